"""Training with stable-baselines3 (PPO or SAC) on the spreadgym envs, with resume.

Config: see `spreadgym.agents.run_config` (one YAML per algorithm, run keys plus the
algorithm's keyword arguments).

Output folder DIR:
    DIR/config.yaml               the config the run used (+ a `trained:` record)
    DIR/model.zip                 the final policy
    DIR/vecnormalize.pkl          normalisation statistics (if `normalize`)
    DIR/checkpoints/rl_model_<N>_steps.zip (+ _replay_buffer_ / _vecnormalize_ .pkl)
    DIR/tb/                       TensorBoard logs

Resume: when DIR/checkpoints holds a checkpoint, `train` loads the newest complete
one (model, SAC replay buffer, VecNormalize statistics) and continues until the
total `n_timesteps` (the --timesteps given now, else the saved config's), with the
saved config. Ctrl-C (or SIGTERM) stops at the next env step and saves a checkpoint.
"""

from __future__ import annotations

import os
import pickle
import re
import signal
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import gymnasium as gym
import numpy as np
import yaml
from tqdm import tqdm

from spreadgym import threads
from spreadgym.agents.run_config import (
    ALGOS,
    RunConfig,
    algo_class,
    default_config_path,
    model_kwargs,
    read_config,
    run_config_schema,
    validate_config,
)
from spreadgym.agents.training_env import WORKER_GONE, check_env_kwargs, make_training_env, worker_failure
from spreadgym.config.base import first_line
from spreadgym.config.overrides import apply_overrides
from spreadgym.errors import ConfigError, SpreadgymError

# stable-baselines3 and torch are imported inside the functions that need them: torch
# must be imported after OMP_NUM_THREADS is set, and a module importing this one (the
# demo, the commands) should not pay for torch unless it trains or loads a policy.

CHECKPOINT_PREFIX = "rl_model"
CHECKPOINT_RE = re.compile(rf"^{CHECKPOINT_PREFIX}_(\d+)_steps\.zip$")


@dataclass
class Checkpoint:
    steps: int
    model: Path
    replay_buffer: Path
    vecnormalize: Path


def checkpoint_files(ckpt_dir: Path, steps: int) -> Checkpoint:
    return Checkpoint(
        steps,
        ckpt_dir / f"{CHECKPOINT_PREFIX}_{steps}_steps.zip",
        ckpt_dir / f"{CHECKPOINT_PREFIX}_replay_buffer_{steps}_steps.pkl",
        ckpt_dir / f"{CHECKPOINT_PREFIX}_vecnormalize_{steps}_steps.pkl",
    )


def list_checkpoints(ckpt_dir: Path) -> list[Checkpoint]:
    """Checkpoints in DIR/checkpoints, newest (most steps) first."""
    if not ckpt_dir.is_dir():
        return []
    steps = [int(m.group(1)) for p in ckpt_dir.iterdir() if (m := CHECKPOINT_RE.match(p.name))]
    return [checkpoint_files(ckpt_dir, s) for s in sorted(steps, reverse=True)]


def save_checkpoint(model, ckpt_dir: Path) -> Checkpoint:
    """Replay buffer and VecNormalize first, the model last: a zip implies its companions."""
    ckpt_dir.mkdir(parents=True, exist_ok=True)
    ck = checkpoint_files(ckpt_dir, int(model.num_timesteps))
    if getattr(model, "replay_buffer", None) is not None:
        model.save_replay_buffer(ck.replay_buffer)
    if model.get_vec_normalize_env() is not None:
        model.get_vec_normalize_env().save(str(ck.vecnormalize))
    model.save(ck.model)
    return ck


# -- callbacks ------------------------------------------------------------------------------

def _callbacks(total: int, started_steps: int, stop_flags: dict, max_minutes: Optional[float]):
    from stable_baselines3.common.callbacks import BaseCallback

    class Progress(BaseCallback):
        """tqdm bar over env steps (SB3's own bar needs rich); a log line every minute
        when stderr is not a terminal; stops on a signal or the wall-clock limit."""

        def _on_training_start(self) -> None:
            self.started = time.monotonic()
            self.last_line = self.started
            self.bar = tqdm(total=total, initial=min(self.model.num_timesteps, total), unit="step",
                            desc=f"train {type(self.model).__name__}", file=sys.stderr, disable=None,
                            dynamic_ncols=True, smoothing=0.05)

        def _mean_reward(self) -> Optional[float]:
            buf = self.model.ep_info_buffer
            return sum(e["r"] for e in buf) / len(buf) if buf else None

        def _on_step(self) -> bool:
            done = min(self.model.num_timesteps, total)
            self.bar.update(done - self.bar.n)
            reward = self._mean_reward()
            now = time.monotonic()
            if reward is not None and self.n_calls % 10 == 0:
                self.bar.set_postfix(reward=f"{reward:.3f}", refresh=False)
            if self.bar.disable and now - self.last_line > 60:
                self.last_line = now
                mean = "-" if reward is None else f"{reward:.3f}"
                print(f"train: {self.model.num_timesteps}/{total} steps, mean episode reward {mean}, "
                      f"{(now - self.started) / 60:.1f} min", file=sys.stderr, flush=True)
            if stop_flags.get("signal"):
                return False
            if max_minutes is not None and now - self.started > 60.0 * max_minutes:
                stop_flags["time"] = True
                return False
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return Progress()


# -- train ----------------------------------------------------------------------------------

@dataclass
class TrainResult:
    out_dir: Path
    num_timesteps: int
    resumed_from: Optional[int]
    stopped: str  # "done", "time limit", "interrupted", "already done"
    wall_s: float


def load_run_config(out_dir: Path, algo: str) -> RunConfig:
    path = out_dir / "config.yaml"
    if not path.is_file():
        raise SpreadgymError(f"{out_dir}/checkpoints holds checkpoints but {path} is missing: cannot resume "
                             "(use a fresh --out folder)")
    raw = read_config(path)
    saved = raw.get("algo")
    if saved is not None and saved != algo:
        raise SpreadgymError(f"{out_dir} holds a {saved} run; resume it with --algo {saved} or use a fresh --out")
    return validate_config(algo, raw, str(path))


def train(algo: str, out_dir: Path, config_path: Optional[Path] = None, overrides: Optional[dict] = None,
          env_id: Optional[str] = None, timesteps: Optional[int] = None, seed: Optional[int] = None,
          max_minutes: Optional[float] = None, log=print) -> TrainResult:
    started = time.monotonic()
    algo = algo.lower()
    cls = algo_class(algo)
    out_dir = Path(out_dir)
    ckpt_dir = out_dir / "checkpoints"
    checkpoints = list_checkpoints(ckpt_dir)

    fewer_workers = None  # a resumed run's workers where this machine has fewer threads
    if checkpoints:
        cfg = load_run_config(out_dir, algo)
        ignored = [name for name, v in (("--config", config_path), ("--set", overrides), ("--env", env_id),
                                        ("--seed", seed)) if v]
        if ignored:
            log(f"resuming: {', '.join(ignored)} ignored, the run keeps {out_dir / 'config.yaml'}")
        if cfg.workers is not None and cfg.workers > threads.thread_count():  # resumed on a smaller machine
            fewer_workers = threads.thread_count()
            log(f"resuming: workers {cfg.workers} is more than the {fewer_workers} threads spreadgym may "
                f"use here; using {fewer_workers} (what is trained on does not depend on it)")
    else:
        path = Path(config_path) if config_path else default_config_path(algo)
        raw = read_config(path)
        if overrides:
            raw = apply_overrides(raw, overrides, run_config_schema(algo))
        if env_id:
            raw["env"] = env_id
        if seed is not None:
            raw["seed"] = int(seed)
        cfg = validate_config(algo, raw, str(config_path or f"configs/agents/{algo}.yaml"))
    if timesteps is not None:
        if isinstance(timesteps, bool) or not isinstance(timesteps, int) or timesteps < 1:
            raise ConfigError("--timesteps", f"expected a positive whole number, got {timesteps!r}")
        cfg = cfg.replace(n_timesteps=timesteps)
    if max_minutes is not None:
        if not max_minutes > 0:
            raise SpreadgymError(f"--max-minutes must be positive, got {max_minutes}")
        cfg = cfg.replace(max_minutes=float(max_minutes))

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)
    spaces = check_env_kwargs(cfg.env, cfg.env_kwargs)  # bad env kwargs fail here, naming the key
    kwargs = model_kwargs(cfg)
    try:  # the constructor checks the hyperparameter values before any worker starts
        cls(cfg.policy, _spaces_env(*spaces), device="cpu", **kwargs)
    except (TypeError, ValueError, AssertionError, RuntimeError) as exc:  # RuntimeError: torch's own refusals
        raise SpreadgymError(f"{algo} hyperparameters: {first_line(exc)}") from None

    out_dir.mkdir(parents=True, exist_ok=True)
    total = cfg.n_timesteps
    resumed_from = None
    model = None
    stepped_by = {"batched": "spreadgym's batched vector env", "subproc": "SubprocVecEnv, a process each",
                  "dummy": "DummyVecEnv, in this process"}[cfg.vec_env_kind]
    log(f"envs: {cfg.n_envs} in {stepped_by} (vec_env {cfg.vec_env})")  # auto's choice depends on the threads
    with tempfile.TemporaryDirectory(prefix="spreadgym-workers-") as error_dir:
        venv = make_training_env(cfg if fewer_workers is None else cfg.replace(workers=fewer_workers),
                                 error_dir)  # config.yaml keeps the run's own count
        try:
            if checkpoints:
                model, venv, resumed_from = _resume(cls, cfg, checkpoints, venv, out_dir, log)
            else:
                if cfg.normalize_kwargs is not None:
                    from stable_baselines3.common.vec_env import VecNormalize

                    venv = VecNormalize(venv, **cfg.normalize_kwargs)
                model = cls(cfg.policy, venv, device="cpu", seed=cfg.seed, tensorboard_log=str(out_dir / "tb"),
                            verbose=0, **kwargs)
            _write_config(out_dir, cfg, model.num_timesteps, resumed_from, "running", time.monotonic() - started)
            if model.num_timesteps >= total:
                log(f"{out_dir} already holds {model.num_timesteps} >= {total} steps; nothing to train")
                stopped = "already done"
            else:
                stopped = _learn(model, cfg, total, ckpt_dir, log)
            final = save_checkpoint(model, ckpt_dir)
            model.save(out_dir / "model.zip")
            if model.get_vec_normalize_env() is not None:
                model.get_vec_normalize_env().save(str(out_dir / "vecnormalize.pkl"))
            wall = time.monotonic() - started
            _write_config(out_dir, cfg, model.num_timesteps, resumed_from, stopped, wall)
            log(f"checkpoint {final.model}")
        except WORKER_GONE:
            if cfg.vec_env_kind != "subproc":  # only SubprocVecEnv's workers record their failures
                raise
            raise worker_failure(error_dir) from None
        finally:
            try:
                venv.close()
            except WORKER_GONE:  # a worker already gone: the error above says why
                pass
    if stopped == "interrupted":
        log(f"interrupted at {model.num_timesteps} steps; checkpoint saved; run the same command to resume")
        raise KeyboardInterrupt
    return TrainResult(out_dir, int(model.num_timesteps), resumed_from, stopped, wall)


def _spaces_env(obs_space, act_space):
    """A stand-in env with the real spaces (for the constructor check: no simulation)."""
    class Spaces(gym.Env):
        observation_space = obs_space
        action_space = act_space

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            return obs_space.sample(), {}

        def step(self, action):
            return obs_space.sample(), 0.0, True, False, {}

    return Spaces()


def resume_seed(seed: int, steps: int) -> int:
    """The seed of a run's part resumed at `steps`: from the run's seed and the step count,
    so no part repeats another's contexts and granule samples."""
    return int(np.random.SeedSequence([int(seed), int(steps)]).generate_state(1)[0] % 2**31)


def _resume(cls, cfg, checkpoints, venv, out_dir, log):
    """Load the newest complete checkpoint (falling back to older ones if a file is broken)."""
    from stable_baselines3.common.vec_env import VecNormalize

    errors = []
    for ck in checkpoints:
        if cfg.normalize_kwargs is not None and not ck.vecnormalize.is_file():
            errors.append(f"{ck.model.name}: no {ck.vecnormalize.name}")
            continue
        try:
            env = VecNormalize.load(str(ck.vecnormalize), venv) if cfg.normalize_kwargs is not None else venv
            model = cls.load(ck.model, env=env, device="cpu", tensorboard_log=str(out_dir / "tb"))
            if hasattr(model, "replay_buffer"):
                if ck.replay_buffer.is_file():
                    model.load_replay_buffer(ck.replay_buffer)
                else:
                    log(f"resuming without a replay buffer: {ck.replay_buffer.name} is missing")
        except Exception as exc:  # a checkpoint cut short by a kill: try the previous one
            errors.append(f"{ck.model.name}: {type(exc).__name__}: {exc}")
            continue
        for err in errors:
            log(f"skipped checkpoint {err}")
        log(f"resuming from {ck.model} ({model.num_timesteps} steps)")
        # a seed of its own for the part after the checkpoint: SB3's load seeds torch and the envs
        # with the run's seed again, which replays the contexts, samples and draws of step 0;
        # from the same checkpoint a resumed run gives the same bits
        seed = resume_seed(cfg.seed, int(model.num_timesteps))
        model.set_random_seed(seed)
        env.seed(seed)
        return model, env, int(model.num_timesteps)
    raise SpreadgymError(f"{out_dir}/checkpoints: no usable checkpoint ({'; '.join(errors)})")


def _learn(model, cfg, total, ckpt_dir, log) -> str:
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    flags: dict = {}
    periodic = CheckpointCallback(save_freq=max(cfg.checkpoint_freq // cfg.n_envs, 1),
                                  save_path=str(ckpt_dir), name_prefix=CHECKPOINT_PREFIX,
                                  save_replay_buffer=True, save_vecnormalize=True)
    progress = _callbacks(total, model.num_timesteps, flags, cfg.max_minutes)

    def on_signal(signum, frame):
        if flags.get("signal"):  # second Ctrl-C: stop now
            raise KeyboardInterrupt
        flags["signal"] = signum
        print("\nstopping after this step to save a checkpoint (Ctrl-C again to abort)", file=sys.stderr)

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        model.learn(total_timesteps=total - model.num_timesteps, callback=CallbackList([periodic, progress]),
                    reset_num_timesteps=False, tb_log_name=cfg.algo, progress_bar=False)
    except Exception as error:  # noqa: BLE001 (re-raised unless a stop signal came first)
        if not flags.get("signal"):
            raise
        # SIGTERM to the whole process group (`timeout`, a service manager) also stops the
        # batched env's workers, which leave only Ctrl-C to the trainer: the step in flight
        # is lost, as a stop between steps loses the rollout's unlearned steps; the model is whole
        log(f"the envs stopped with the signal ({type(error).__name__}: {' '.join(str(error).split())}); "
            "saving the model as it was")
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if flags.get("signal"):
        return "interrupted"
    if flags.get("time"):
        log(f"stopped at the time limit of {cfg.max_minutes:g} min ({model.num_timesteps} steps)")
        return "time limit"
    return "done"


def _write_config(out_dir: Path, cfg: RunConfig, steps: int, resumed_from, stopped: str, wall_s: float) -> None:
    record = cfg.as_yaml()
    record["trained"] = {"num_timesteps": int(steps), "resumed_from": resumed_from, "stopped": stopped,
                         "wall_s_last_invocation": round(float(wall_s), 1)}
    text = ("# written by `spreadgym train`: the config of this run (a valid --config file;\n"
            "# the `trained` record is ignored when read back)\n") + yaml.safe_dump(record, sort_keys=False)
    tmp = out_dir / "config.yaml.tmp"
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(out_dir / "config.yaml")


# -- loading a saved policy -----------------------------------------------------------------

@dataclass
class SavedPolicy:
    path: Path
    algo: str
    config: RunConfig  # validated config of the run
    model: Any
    obs_rms: Any  # VecNormalize (for its observation statistics) or None

    @property
    def env_id(self) -> str:
        return self.config.env

    @property
    def env_kwargs(self) -> dict:
        return dict(self.config.env_kwargs)

    def act(self, obs):
        obs = np.asarray(obs, dtype=np.float32)
        if self.obs_rms is not None:
            obs = self.obs_rms.normalize_obs(obs)
        action, _ = self.model.predict(obs, deterministic=True)
        return action


def check_sb3_zip(file: Path, given, flag: str = "--model") -> None:
    """A SpreadgymError naming `flag` and `given` unless `file` is a zip holding a saved
    stable-baselines3 policy (data and policy.pth)."""
    if not zipfile.is_zipfile(file):
        raise SpreadgymError(f"{flag} {given}: not a saved stable-baselines3 policy (not a zip file)")
    with zipfile.ZipFile(file) as zf:
        if "data" not in zf.namelist() or "policy.pth" not in zf.namelist():
            raise SpreadgymError(f"{flag} {given}: not a saved stable-baselines3 policy (no data/policy.pth)")


def saved_policy_file(path, flag: str = "--model") -> tuple[Path, Path]:
    """(model zip, run folder) of a policy saved by `train` (DIR/model.zip, DIR or a
    checkpoint zip), checked without loading it: the file, its contents and the run's
    config.yaml. Anything else is a SpreadgymError naming `flag` and the path."""
    given = Path(path)
    path = given / "model.zip" if given.is_dir() else given
    if not path.is_file():
        raise SpreadgymError(f"{flag} {given}: no such file (expected DIR/model.zip written by spreadgym train)")
    check_sb3_zip(path, given, flag)
    match = CHECKPOINT_RE.match(path.name)
    run_dir = path.parent.parent if match and path.parent.name == "checkpoints" else path.parent
    if not (run_dir / "config.yaml").is_file():
        raise SpreadgymError(f"{flag} {given}: {run_dir / 'config.yaml'} is missing (the run's config, written by "
                             "train)")
    return path, run_dir


def load_policy(path, flag: str = "--model") -> SavedPolicy:
    """A policy saved by `train` (`saved_policy_file`), with the run's config.yaml and
    VecNormalize statistics. Anything else is a SpreadgymError naming `flag` and the path."""
    given = Path(path)
    path, run_dir = saved_policy_file(given, flag)
    match = CHECKPOINT_RE.match(path.name)
    config_path = run_dir / "config.yaml"
    raw = read_config(config_path)
    algo = str(raw.get("algo", "")).lower()
    if algo not in ALGOS:
        raise SpreadgymError(f"{flag} {given}: {config_path} names no known algo ({raw.get('algo')!r})")
    cfg = validate_config(algo, raw, str(config_path))
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)
    try:
        model = algo_class(algo).load(path, device="cpu")
    except Exception as exc:
        raise SpreadgymError(f"{flag} {given}: could not load a {algo} policy ({type(exc).__name__}: {exc})") from None
    obs_rms = None
    if cfg.normalize_kwargs is not None:
        stats = (checkpoint_files(path.parent, int(match.group(1))).vecnormalize if match
                 else run_dir / "vecnormalize.pkl")
        if not stats.is_file():
            raise SpreadgymError(f"{flag} {given}: the run normalised observations but {stats} is missing")
        with open(stats, "rb") as handle:
            obs_rms = pickle.load(handle)
        obs_rms.training = False
        obs_rms.norm_reward = False
    return SavedPolicy(path, algo, cfg, model, obs_rms)
