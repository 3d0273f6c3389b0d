"""The training run's vector env: its worker processes, and what they say when they fail.

The run's `vec_env` decides what steps its envs (`RunConfig.vec_env_kind`): the SpinnerDesign
tasks' batched vector env as an SB3 VecEnv (`batched_env`; its workers' errors reach the
trainer as they are), or SubprocVecEnv workers (one `gym.make` per process): a worker that
raises records its exception's one-line message in a folder the trainer gives it and
ends quietly, so the trainer can end the command with that message
(`worker_failure`) instead of a bare EOFError from the broken pipe.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from functools import partial
from pathlib import Path
from typing import Optional

import gymnasium as gym

from spreadgym import threads
from spreadgym.agents.run_config import RunConfig
from spreadgym.errors import SpreadgymError


def worker_env(env_id: str, error_dir: Optional[str] = None, **env_kwargs):
    """Make one env; in a worker process, leave Ctrl-C and SIGTERM to the trainer, and write
    any exception's one-line message to `error_dir` before the worker dies, so the trainer
    can say it (`worker_failure`)."""
    if multiprocessing.parent_process() is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        env = gym.make(env_id, **env_kwargs)
    except Exception as exc:
        _record_failure(error_dir, exc)
        raise
    return env if error_dir is None else _FailureRecorder(env, error_dir)


class _FailureRecorder(gym.Wrapper):
    """Records the message of an exception raised by reset or step (worker processes)."""

    def __init__(self, env, error_dir: str):
        super().__init__(env)
        self._error_dir = error_dir

    def reset(self, **kwargs):
        try:
            return self.env.reset(**kwargs)
        except Exception as exc:
            _record_failure(self._error_dir, exc)
            raise

    def step(self, action):
        try:
            return self.env.step(action)
        except Exception as exc:
            _record_failure(self._error_dir, exc)
            raise


def _record_failure(error_dir: Optional[str], exc: BaseException) -> None:
    """Write the exception's kind and one-line message for the trainer; in a worker
    process of bad input, end the process quietly (the trainer says the message once,
    without the worker's traceback)."""
    if error_dir is None:
        return
    kind = "input" if isinstance(exc, (SpreadgymError, ValueError)) else type(exc).__name__
    message = " ".join(str(exc).split()) or type(exc).__name__
    try:
        Path(error_dir, f"{os.getpid()}.txt").write_text(f"{kind}\t{message}", encoding="utf-8")
    except OSError:  # the trainer has already stopped on another worker's failure
        pass
    if kind == "input" and multiprocessing.parent_process() is not None:
        os._exit(2)


def worker_failure(error_dir: str) -> BaseException:
    """What to raise when a worker process has gone: its recorded message as a
    SpreadgymError (exit 2) for bad input, else a RuntimeError naming the exception (a bug)."""
    records = sorted(Path(error_dir).glob("*.txt"))
    if not records:
        return RuntimeError("a training env worker process died without a message (killed or out of memory?)")
    kind, message = records[0].read_text(encoding="utf-8").split("\t", 1)
    if kind == "input":
        return SpreadgymError(f"a training env worker stopped: {message}")
    return RuntimeError(f"a training env worker failed with {kind}: {message}")


def check_env_kwargs(env_id: str, env_kwargs: dict):
    """Build the env once in this process, so a bad kwarg fails here, naming the key."""
    env = gym.make(env_id, **env_kwargs)
    spaces = (env.observation_space, env.action_space)
    env.close()
    return spaces


WORKER_GONE = (EOFError, BrokenPipeError, ConnectionResetError)  # what SubprocVecEnv raises when a worker died


def make_training_env(cfg: RunConfig, error_dir: Optional[str] = None):
    """The vector env of the run (`cfg.vec_env_kind`): spreadgym's batched vector env as an
    SB3 VecEnv (`batched_env`), or SubprocVecEnv for n_envs > 1 (workers record their
    failures in `error_dir`; spreadgym's threads shared out among them by `threads_shared`,
    so that processes and threads do not multiply: one thread each where n_envs exceeds
    the threads), else DummyVecEnv."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if cfg.vec_env_kind == "batched":
        return batched_env(cfg)
    n = cfg.n_envs
    vec_cls = partial(threads_shared, SubprocVecEnv) if n > 1 else DummyVecEnv
    try:
        return make_vec_env(partial(worker_env, cfg.env, error_dir if n > 1 else None), n_envs=n, seed=cfg.seed,
                            env_kwargs=cfg.env_kwargs, vec_env_cls=vec_cls)
    except WORKER_GONE:
        if error_dir is None:
            raise
        raise worker_failure(error_dir) from None


def threads_shared(vec_cls, env_fns: list, **kwargs):
    """`vec_cls(env_fns)` with worker i building its env on `threads.shares(len(env_fns))[i]`
    threads: spreadgym's threads shared out among the workers, all of them used."""
    shares = threads.shares(len(env_fns))
    return vec_cls([partial(_on_threads, make, share) for make, share in zip(env_fns, shares)], **kwargs)


def _on_threads(make, count: int):
    """make() in a process that uses `count` of spreadgym's threads."""
    threads.set_threads(count)
    return make()


def batched_env(cfg: RunConfig):
    """The SpinnerDesign vector env of `cfg.n_envs` sub-envs (`gym.make_vec`, same-step
    autoreset) in `cfg.workers` processes (None: one per thread spreadgym may use, at most
    n_envs), as an SB3 VecEnv seeded with `cfg.seed` (env i: seed + i, as make_vec_env
    seeds SubprocVecEnv's) and its episodes recorded by VecMonitor (as Monitor records
    them in each SubprocVecEnv worker)."""
    from stable_baselines3.common.vec_env import VecMonitor

    from spreadgym.agents.batched_vec_env import BatchedVecEnv

    workers = cfg.workers if cfg.workers is not None else min(cfg.n_envs, threads.thread_count())
    vector = gym.make_vec(cfg.env, num_envs=cfg.n_envs, autoreset_mode="same_step", workers=workers,
                          **cfg.env_kwargs)
    env = BatchedVecEnv(vector)
    env.seed(cfg.seed)
    return VecMonitor(env)


# -- checkpoints ----------------------------------------------------------------------------
