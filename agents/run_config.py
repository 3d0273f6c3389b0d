"""The run config of `spreadgym train`: one YAML per algorithm, validated by a pydantic model.

Config: `configs/agents/ppo.yaml`, `configs/agents/sac.yaml`, flat like
rl-baselines3-zoo's: the run keys below plus the algorithm's own keyword arguments
(`learning_rate`, `n_steps`, `batch_size`, ...). A key that is neither a run key nor a
keyword of the algorithm is an error naming it.

Run keys:
    algo             ppo | sac (optional; must match --algo)
    env              env id (spreadgym:SpinnerDesign-v0 or spreadgym:SpreaderTuning-v0)
    env_kwargs       gym.make keyword arguments (checked by the env: unknown keys fail)
    n_envs           parallel envs
    vec_env          auto | batched | subproc: how the n_envs step (agents/training_env.py);
                     auto: the batched vector env where it batches (the SpinnerDesign tasks,
                     env_kwargs it takes, n_envs above spreadgym's threads, or workers set),
                     else SubprocVecEnv (n_envs > 1) or DummyVecEnv; what SB3 trains on is
                     the same whichever steps them
    workers          processes of the batched vector env (null: one per thread, at most n_envs)
    n_timesteps      total env steps of the run
    normalize        false | true | {norm_obs, norm_reward, clip_obs, clip_reward, gamma, epsilon}
    seed             seed of the model and the envs
    checkpoint_freq  env steps between checkpoints
    max_minutes      wall-clock limit of one invocation (null: none)
    policy           MlpPolicy
    policy_kwargs    e.g. {net_arch: [64, 64], activation_fn: tanh, log_std_init: -1.0}

Learning rates (and PPO's clip_range) may be a number or `lin_<value>` (linear decay
to 0, as in the zoo). The algorithm's keywords are read off its constructor, so
building the schema imports stable-baselines3.
"""

from __future__ import annotations

import difflib
import functools
import inspect
import re
from pathlib import Path
from typing import Any, Literal, Optional

from pydantic import Field, create_model, field_validator, model_validator

from spreadgym import threads
from spreadgym.agents.evaluation import canonical_env_id, is_tuning
from spreadgym.config.base import Integer, Real, StrictModel, validate
from spreadgym.config.resources import config_dir, read_yaml
from spreadgym.errors import ConfigError, SpreadgymError

ALGOS = ("ppo", "sac")
DEFAULT_ENV = "spreadgym:SpinnerDesign-v0"
WRITTEN_KEYS = ("trained",)  # written into DIR/config.yaml by train, ignored when read back
RESERVED = {"policy", "env", "tensorboard_log", "verbose", "seed", "device", "_init_setup_model", "policy_kwargs"}
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu", "gelu", "silu")
SCHEDULE_KEYS = ("learning_rate", "clip_range", "clip_range_vf")


MAX_LAYERS, MAX_UNITS = 16, 4096  # far above any policy a design task needs; beyond, memory runs out first


def check_net_arch(net_arch: Any) -> None:
    """`policy_kwargs.net_arch`: a list of layer widths (whole numbers in [1, MAX_UNITS], at
    most MAX_LAYERS), or a mapping of SB3's networks (pi, vf, qf) to such lists; else a
    ValueError naming it and the allowed range."""
    def layers(key: str, widths: Any) -> None:
        if not isinstance(widths, list) or len(widths) > MAX_LAYERS or not all(
                isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= MAX_UNITS for w in widths):
            raise ValueError(f"{key}: expected a list of at most {MAX_LAYERS} layer widths, whole numbers in "
                             f"[1, {MAX_UNITS}], got {widths!r}")

    if isinstance(net_arch, dict):
        for name, widths in net_arch.items():
            if name not in ("pi", "vf", "qf"):
                raise ValueError(f"net_arch.{name}: unknown network; known: pi, vf, qf")
            layers(f"net_arch.{name}", widths)
    else:
        layers("net_arch", net_arch)


def batched_refusal(env_kwargs: dict[str, Any]) -> Optional[str]:
    """Why the SpinnerDesign vector env cannot take these env_kwargs, or None if it can:
    gym.make's own keys (max_episode_steps, disable_env_checker) wrap a single env and are
    no keywords of a vector env, and it renders rgb_array frames only. SubprocVecEnv runs
    such a config (one gym.make per env)."""
    import gymnasium

    from spreadgym.envs.vector import SpinnerDesignVectorEnv

    make_keys = [name for name, parameter in inspect.signature(gymnasium.make).parameters.items()
                 if parameter.default is not inspect.Parameter.empty]
    for key in make_keys:
        if key in env_kwargs:
            return f"env_kwargs.{key} is a key of gym.make, which the vector env does not take"
    render_mode = env_kwargs.get("render_mode")
    if render_mode is not None and render_mode not in SpinnerDesignVectorEnv.metadata["render_modes"]:
        return f"env_kwargs.render_mode {render_mode!r}: the vector env renders only rgb_array"
    return None


def algo_class(algo: str):
    if algo not in ALGOS:
        raise SpreadgymError(f"unknown algorithm {algo!r}; known: {', '.join(ALGOS)}")
    from stable_baselines3 import PPO, SAC  # heavy (torch): only when an algorithm is needed

    return {"ppo": PPO, "sac": SAC}[algo]


def hyperparameter_names(algo: str) -> list[str]:
    params = inspect.signature(algo_class(algo).__init__).parameters
    return sorted(k for k in params if k != "self" and k not in RESERVED)


class Normalize(StrictModel):
    """VecNormalize keyword arguments; the ones left out keep stable-baselines3's defaults."""

    norm_obs: Optional[bool] = None
    norm_reward: Optional[bool] = None
    clip_obs: Optional[Real] = Field(default=None, gt=0.0)
    clip_reward: Optional[Real] = Field(default=None, gt=0.0)
    gamma: Optional[Real] = Field(default=None, ge=0.0, le=1.0)
    epsilon: Optional[Real] = Field(default=None, gt=0.0)


class RunConfig(StrictModel):
    """The run keys; `run_config_schema(algo)` adds the algorithm's keywords as fields."""

    algo: Literal["ppo", "sac"]
    env: str = DEFAULT_ENV
    env_kwargs: dict[str, Any] = Field(default_factory=dict)
    n_envs: Integer = Field(default=1, ge=1)
    vec_env: Literal["auto", "batched", "subproc"] = "auto"
    workers: Optional[Integer] = Field(default=None, ge=1)
    n_timesteps: Integer = Field(default=10_000, ge=1)
    normalize: Optional[Normalize] = None  # YAML: false (None), true ({}), or the keyword arguments
    seed: Integer = Field(default=0, ge=0)
    checkpoint_freq: Integer = Field(default=1000, ge=1)
    max_minutes: Optional[Real] = Field(default=None, gt=0.0)
    policy: str = "MlpPolicy"
    policy_kwargs: dict[str, Any] = Field(default_factory=dict)

    @field_validator("env_kwargs", "policy_kwargs", "seed", "env", "policy", "vec_env", mode="before")
    @classmethod
    def _null_is_default(cls, value, info):
        """YAML's `key:` (null) means the default."""
        if value is not None:
            return value
        return {"env_kwargs": {}, "policy_kwargs": {}, "seed": 0, "env": DEFAULT_ENV,
                "policy": "MlpPolicy", "vec_env": "auto"}[info.field_name]

    @field_validator("normalize", mode="before")
    @classmethod
    def _normalize_flag(cls, value):
        """`false` (or null): no VecNormalize; `true`: VecNormalize with its defaults."""
        if value is None or value is False:
            return None
        return {} if value is True else value

    @field_validator("env")
    @classmethod
    def _env(cls, value: str) -> str:
        return canonical_env_id(value)

    @field_validator("policy_kwargs")
    @classmethod
    def _policy_kwargs(cls, value: dict) -> dict:
        act = value.get("activation_fn")
        if act is not None and act not in ACTIVATIONS:
            raise ValueError(f"activation_fn: unknown {act!r}; known: {', '.join(ACTIVATIONS)}")
        if "net_arch" in value:
            check_net_arch(value["net_arch"])
        return value

    @model_validator(mode="after")
    def _vec_env(self) -> "RunConfig":
        if self.vec_env == "batched" and is_tuning(self.env):
            raise ValueError(f"vec_env: batched needs an env with a batched vector env (the SpinnerDesign tasks); "
                             f"{self.env} has none: use auto or subproc")
        refusal = batched_refusal(self.env_kwargs)
        if self.vec_env == "batched" and refusal:
            raise ValueError(f"vec_env: batched cannot run this config ({refusal}): use auto or subproc")
        if self.workers is not None and self.vec_env_kind != "batched":
            why = ("vec_env: subproc" if self.vec_env == "subproc" else refusal if refusal and not is_tuning(self.env)
                   else f"{self.env} has no batched vector env")
            raise ValueError(f"workers: only the batched vector env has workers ({why})")
        if self.workers is not None and self.workers > self.n_envs:
            raise ValueError(f"workers: at most n_envs ({self.n_envs}), got {self.workers}")
        return self

    @property
    def vec_env_kind(self) -> str:
        """What steps the run's envs: "batched" (spreadgym's vector env in SB3's clothes),
        "subproc" (SB3's SubprocVecEnv) or "dummy" (SB3's DummyVecEnv, one env in this
        process). `auto` takes the batched env where it batches: the env has one, it can run
        the env_kwargs (`batched_refusal`), and there are more envs than threads spreadgym
        may use (its workers, one per thread, then hold more than one env on the whole), or
        `workers` is set. On two cores it led SubprocVecEnv by 20-22 % at four envs a worker,
        and at one env a worker (a vector env of one, nothing to batch) tied it in the medians
        and trailed it by 5-10 % in the best blocks (docs/agents.md). What SB3 trains on is
        the same either way."""
        if self.vec_env == "auto":
            batches = (not is_tuning(self.env) and batched_refusal(self.env_kwargs) is None
                       and (self.workers is not None or self.n_envs > threads.thread_count()))
            return "batched" if batches else "subproc" if self.n_envs > 1 else "dummy"
        if self.vec_env == "batched":
            return "batched"
        return "subproc" if self.n_envs > 1 else "dummy"

    @model_validator(mode="after")
    def _schedules(self) -> "RunConfig":
        for key, value in self.hyperparams.items():
            if key in SCHEDULE_KEYS:
                schedule(value, key)  # raises on a bad value
        return self

    @property
    def hyperparams(self) -> dict[str, Any]:
        """The algorithm's keywords the config sets (the others keep stable-baselines3's defaults)."""
        return {name: getattr(self, name) for name in type(self).model_fields
                if name not in RunConfig.model_fields and name in self.model_fields_set}

    @property
    def normalize_kwargs(self) -> Optional[dict]:
        """None (no VecNormalize) or VecNormalize keyword arguments."""
        return None if self.normalize is None else self.normalize.model_dump(exclude_none=True)

    def as_yaml(self) -> dict:
        """The flat YAML form (what DIR/config.yaml holds); validating it gives this config back."""
        out = {key: getattr(self, key) for key in RunConfig.model_fields}
        kwargs = self.normalize_kwargs
        out["normalize"] = False if kwargs is None else (kwargs or True)
        out.update(self.hyperparams)
        return out

    def replace(self, **changes: Any) -> "RunConfig":
        """A validated copy with some keys changed."""
        return validate(type(self), {**self.as_yaml(), **changes}, "config")


@functools.cache
def run_config_schema(algo: str) -> type[RunConfig]:
    """RunConfig with one optional field per keyword argument of the algorithm's constructor."""
    fields = {name: (Any, None) for name in hyperparameter_names(algo)}
    return create_model(f"{algo.upper()}RunConfig", __base__=RunConfig, **fields)


def default_config_path(algo: str) -> Path:
    return config_dir() / "agents" / f"{algo}.yaml"


def read_config(path: Path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise ConfigError("--config", f"no such file {str(path)!r}")
    raw = read_yaml(path)
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(str(path), f"expected a mapping of keys, got {type(raw).__name__}")
    return raw


def validate_config(algo: str, raw: dict, where: str) -> RunConfig:
    """The validated run config of `algo` from a flat mapping (the YAML's `trained` record ignored)."""
    schema = run_config_schema(algo)
    raw = {key: value for key, value in raw.items() if key not in WRITTEN_KEYS}
    known = sorted(schema.model_fields)
    for key in raw:
        if key not in schema.model_fields:
            close = difflib.get_close_matches(str(key), known, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise ConfigError(str(key), f"unknown key in {where}{hint}; known keys: {', '.join(known)}")
    if raw.get("algo") not in (None, algo):
        raise ConfigError("algo", f"{where} is a config for {raw['algo']!r}, not for {algo!r}")
    return validate(schema, {**raw, "algo": algo}, where)


def schedule(value: Any, key: str):
    """A number, or 'lin_<number>': linear from <number> to 0 over the run."""
    if isinstance(value, str):
        match = re.fullmatch(r"lin_([0-9.eE+-]+)", value.strip())
        if not match:
            raise ValueError(f"{key}: expected a number or lin_<number>, got {value!r}")
        start = float(match.group(1))
        return lambda progress_remaining: progress_remaining * start
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{key}: expected a number or lin_<number>, got {value!r}")
    return float(value)


def model_kwargs(cfg: RunConfig) -> dict:
    """Keyword arguments of the SB3 constructor from a validated config."""
    import torch  # heavy: only when a model is built

    kwargs = dict(cfg.hyperparams)
    for key in SCHEDULE_KEYS:
        if key in kwargs:
            kwargs[key] = schedule(kwargs[key], key)
    policy_kwargs = dict(cfg.policy_kwargs)
    if "activation_fn" in policy_kwargs:
        policy_kwargs["activation_fn"] = {
            "tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU, "leaky_relu": torch.nn.LeakyReLU,
            "gelu": torch.nn.GELU, "silu": torch.nn.SiLU,
        }[policy_kwargs["activation_fn"]]
    if policy_kwargs:
        kwargs["policy_kwargs"] = policy_kwargs
    return kwargs
