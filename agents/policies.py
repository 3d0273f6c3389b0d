"""What `spreadgym evaluate` and `compare` can score (`load_any_policy`):

* a run of `spreadgym train`: DIR, DIR/model.zip or a checkpoint (its config.yaml gives the
  env id and kwargs, its vecnormalize.pkl the observation statistics);
* an rl_zoo3 model: `logs/ALGO/ENV_N/ENV.zip` (or `best_model.zip` there), whose
  `ENV/args.yml` gives the env id and kwargs and `ENV/vecnormalize.pkl` the statistics;
* a plain stable-baselines3 model file (`model.save(...)`): the algorithm is read from the
  file, the env is `--env` (default: the first rung, spreadgym/SpinnerDesign-v1);
* a Python callable `module:function` (or `path/to/file.py:function`), called as
  `function(obs) -> action` on one observation at a time; the env is `--env`.

Every policy is run deterministically (SB3's `predict(deterministic=True)`). Anything that
is none of these is a SpreadgymError naming what was given.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import pickle
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import yaml

from spreadgym.config.base import first_line
from spreadgym.errors import SpreadgymError

DEFAULT_ENV = "spreadgym/SpinnerDesign-v1"
CALLABLE = re.compile(r"^(?P<module>[\w.]+|.+\.py):(?P<name>[A-Za-z_]\w*)$")
SB3_ALGOS = {"ppo": ("stable_baselines3", "PPO"), "a2c": ("stable_baselines3", "A2C"),
             "sac": ("stable_baselines3", "SAC"), "td3": ("stable_baselines3", "TD3"),
             "ddpg": ("stable_baselines3", "DDPG"), "tqc": ("sb3_contrib", "TQC")}
"""Algorithms with a continuous action (the envs' Box): name -> (package, class)."""


@dataclass
class Policy:
    """A decision rule and the env it was made for (None: the caller's `--env`)."""

    name: str  # short label: the algorithm ("ppo"), or the function's name
    source: str  # what was given
    act: Callable[[np.ndarray], np.ndarray]
    env_id: Optional[str] = None
    env_kwargs: dict = field(default_factory=dict)
    kind: str = "train"  # train | zoo | sb3 | callable


def load_any_policy(given, env_id: Optional[str] = None) -> Policy:
    """The policy `given` names (module docstring); `env_id` is the env for the kinds that carry none."""
    text = str(given)
    path = Path(text)
    match = CALLABLE.match(text)
    if match and not path.exists():
        return _callable_policy(match["module"], match["name"], text, env_id)
    if path.is_dir() and not (path / "model.zip").is_file():
        raise SpreadgymError(f"--model {given}: a folder without model.zip (give the model file)")
    file = path / "model.zip" if path.is_dir() else path
    if not file.is_file():
        raise SpreadgymError(f"--model {given}: no such file, and not a callable module:function")
    from spreadgym.agents.training import CHECKPOINT_RE, check_sb3_zip, load_policy

    check_sb3_zip(file, given)

    in_checkpoints = CHECKPOINT_RE.match(file.name) and file.parent.name == "checkpoints"
    run_dir = file.parent.parent if in_checkpoints else file.parent
    if (run_dir / "config.yaml").is_file():
        saved = load_policy(file)
        if env_id is not None and _same_task(env_id) != _same_task(saved.env_id):
            raise SpreadgymError(f"--env {env_id}: {given} was trained on {saved.env_id}")
        return Policy(saved.algo, text, saved.act, saved.env_id, saved.env_kwargs, "train")
    zoo = _zoo_params(file)
    if zoo is not None:
        return _zoo_policy(file, zoo, text)
    algo, model = _load_sb3(file, given)
    return Policy(algo, text, _predictor(model, None), env_id or DEFAULT_ENV, {}, "sb3")


def model_files(given) -> list[str]:
    """The files a `--model` value names (for an output folder that must not write over its
    inputs): the model file or run folder's model.zip, or a callable's .py file; a leading
    `LABEL=` (compare) is left out."""
    text = str(given)
    labelled = re.match(r"^([\w.-]+)=(.+)$", text)
    text = labelled.group(2) if labelled and not Path(text).exists() else text
    match = CALLABLE.match(text)
    if match and not Path(text).exists():
        return [match["module"]] if match["module"].endswith(".py") else []
    path = Path(text)
    return [str(path / "model.zip" if path.is_dir() else path)]


def _same_task(env_id: str) -> str:
    from spreadgym.agents.evaluation import canonical_env_id

    return canonical_env_id(env_id)


def _callable_policy(module: str, name: str, text: str, env_id: Optional[str]) -> Policy:
    try:
        if module.endswith(".py"):
            spec = importlib.util.spec_from_file_location(Path(module).stem, module)
            if spec is None or not Path(module).is_file():
                raise FileNotFoundError(module)
            loaded = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(loaded)
        else:
            loaded = importlib.import_module(module)
    except Exception as exc:  # a missing module, or one whose own code fails (SyntaxError, a raise at import)
        raise SpreadgymError(f"--model {text}: cannot import {module} ({type(exc).__name__}: "
                             f"{first_line(exc)})") from None
    function = getattr(loaded, name, None)
    if not callable(function):
        raise SpreadgymError(f"--model {text}: {module} has no callable {name}")

    def act(obs):
        return np.asarray(function(obs), dtype=np.float32)

    return Policy(text, text, act, env_id or DEFAULT_ENV, {}, "callable")


def _algo_of(data: dict) -> Optional[str]:
    """The algorithm of a saved SB3 model's `data`: its policy class's module names it (SAC,
    TD3, TQC); the on-policy ones share ActorCriticPolicy, and PPO alone saves a clip range."""
    module = str((data.get("policy_class") or {}).get("__module__", ""))
    for name in ("sac", "td3", "tqc"):
        if module.endswith(f".{name}.policies"):
            return name
    if module == "stable_baselines3.common.policies":
        return "ppo" if "clip_range" in data else "a2c"
    return None


def _load_sb3(file: Path, given, algo: Optional[str] = None):
    """(algo name, model) of an SB3 zip: `algo` where known (zoo's args.yml), else read from the file."""
    with zipfile.ZipFile(file) as zf:
        try:
            data = json.loads(zf.read("data"))
        except ValueError:
            raise SpreadgymError(f"--model {given}: its data entry is not JSON") from None
    algo = algo or _algo_of(data)
    if algo not in SB3_ALGOS:
        module = (data.get("policy_class") or {}).get("__module__")
        raise SpreadgymError(f"--model {given}: not a model of {', '.join(SB3_ALGOS)} (policy class from {module!r})")
    package, cls = SB3_ALGOS[algo]
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        algo_class = getattr(importlib.import_module(package), cls)
    except ImportError:
        raise SpreadgymError(f"--model {given}: a {cls} model needs {package} (pip install {package})") from None
    import torch

    torch.set_num_threads(1)
    try:
        return cls.lower(), algo_class.load(file, device="cpu")
    except Exception as exc:
        raise SpreadgymError(f"--model {given}: could not load a {cls} model ({type(exc).__name__}: "
                             f"{first_line(exc)})") from None


def _predictor(model, obs_rms) -> Callable[[np.ndarray], np.ndarray]:
    def act(obs):
        obs = np.asarray(obs, dtype=np.float32)
        if obs_rms is not None:
            obs = obs_rms.normalize_obs(obs)
        return model.predict(obs, deterministic=True)[0]

    return act


# -- rl_zoo3 ----------------------------------------------------------------------------------

class _ZooLoader(yaml.SafeLoader):
    """Safe YAML plus the one python tag rl_zoo3's args.yml and config.yml use (OrderedDict)."""


def _ordered_dict(loader: yaml.SafeLoader, node: yaml.Node) -> dict:
    pairs = loader.construct_sequence(node, deep=True)
    return dict(pairs[0]) if pairs else {}


_ZooLoader.add_constructor("tag:yaml.org,2002:python/object/apply:collections.OrderedDict", _ordered_dict)


def _zoo_params(file: Path) -> Optional[Path]:
    """The folder holding a zoo model's args.yml (`ENV_N/ENV/`), or None when it is not a zoo model."""
    found = sorted(p.parent for p in file.parent.glob("*/args.yml"))
    return found[0] if len(found) == 1 else None


def _read_zoo_yaml(path: Path) -> dict:
    try:
        with open(path, encoding="utf-8") as handle:
            raw = yaml.load(handle, Loader=_ZooLoader)  # noqa: S506 (SafeLoader plus OrderedDict)
    except yaml.YAMLError as exc:
        raise SpreadgymError(f"{path}: not readable as rl_zoo3's YAML ({exc.__class__.__name__})") from None
    return raw if isinstance(raw, dict) else {}


def _zoo_policy(file: Path, params: Path, text: str) -> Policy:
    args = _read_zoo_yaml(params / "args.yml")
    env_id = args.get("env")
    if not isinstance(env_id, str):
        raise SpreadgymError(f"--model {text}: {params / 'args.yml'} names no env")
    env_kwargs = args.get("env_kwargs") or {}
    algo, model = _load_sb3(file, text, str(args.get("algo", "")).lower() or None)
    obs_rms = None
    stats = params / "vecnormalize.pkl"
    if stats.is_file():
        with open(stats, "rb") as handle:
            obs_rms = pickle.load(handle)  # noqa: S301 (the user's own training output, as zoo's enjoy reads it)
        obs_rms.training = False
        obs_rms.norm_reward = False
    return Policy(algo, text, _predictor(model, obs_rms), env_id, dict(env_kwargs), "zoo")


def describe(policy: Policy) -> str:
    return {"train": "spreadgym train run", "zoo": "rl_zoo3 model", "sb3": "stable-baselines3 model",
            "callable": "callable"}[policy.kind]
