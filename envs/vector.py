"""The SpinnerDesign tasks as a gymnasium `VectorEnv` (their registered `vector_entry_point`).

`gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=N, **kwargs)` builds this class (any
rung of the ladder, and the deprecated v0): one `Task` (library, base scene, checks) shared
by N sub-envs instead of N copies, a batch of actions in and stacked observations, rewards
and infos out.

Same results as the single env: sub-env i is a `SpinnerDesignEnv` sharing the task,
so with `reset(seed=s)` (sub-env i seeded s + i, as gymnasium's vector envs do; a list
of N seeds seeds each its own) every observation, reward and info equals, bit for bit,
that of `gym.make(id).reset(seed=s + i)` followed by the same actions, with a plain
`reset()` after each episode.

Speed: the tray tests of one step run as one batch (spreadgym.spread.batch: every
granule of every sub-env's design in one parallel kernel, the rest of the scenes side by
side on spreadgym.threads' threads), with the same bits as one run each; each sub-env's
`step` then takes its own result. Two cases step each sub-env itself: runs pooled to a
`precision` and a render mode (the frames need the disc paths). The robust variant's
hidden batches run together, in one library holding every episode's fertilizer copy.
docs/benchmark.md has every rung's rates.

`workers=P` (default 1) runs the sub-envs in P worker processes, contiguous blocks of
near-equal size, each block a vector env of its own with its share of the threads
(envs/shards.py): the Python around each batch, one thread's work in one process, then
runs P at a time. Same bits as one process; P at most the threads spreadgym may use. On a
GPU (`device="cuda"`) each worker launches its own batches on the same GPU, so the Python
around the launches, which bounds one process there, runs P at a time too. Two workers of
one thread gave 1.08-1.10x one process of two threads on two cores (docs/performance.md).

Size: any `num_envs`. A step runs its designs in batches of at most MAX_GRANULE_COPIES
landing points (sim.granules x sim.angle_copies x discs per design: `spreadgym simulate`'s
budget for one run), each batch when the first of its sub-envs steps (`_Prefetched`), so a
step never holds more than one batch's results beyond what the sub-envs keep (each its
last result, for `render`, until its next reset).

Autoreset (`autoreset_mode`): "next_step" (gymnasium's default: the step after an
episode's end resets that sub-env and ignores its action), "same_step" (the sub-env is
reset in the step that ends the episode; its last observation and info are in
`info["final_obs"]` and `info["final_info"]`; SpinnerDesign ends every episode after one
step, so this wastes no calls on resets) or "disabled" (nothing resets by itself: reset
the ended sub-envs with `reset(options={"reset_mask": mask})`, which resets those and
keeps the others' observations; stepping an ended sub-env is an error).
"""

from __future__ import annotations

import copy
from typing import Any, Optional

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from spreadgym import device, threads
from spreadgym.config.scene import MAX_GRANULE_COPIES, granule_copies
from spreadgym.envs.common.actions import check_action
from spreadgym.envs.common.task import batches_library, check_reset_options
from spreadgym.envs.shards import Shards
from spreadgym.envs.spinner_design import SpinnerDesignEnv
from spreadgym.errors import ConfigError

MAX_NUM_ENVS = 65536
"""Sub-envs one vector env may hold (each a shallow copy of the first, with its own state)."""

MODES = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP,
         "disabled": AutoresetMode.DISABLED}


class SpinnerDesignVectorEnv(VectorEnv):
    """`num_envs` SpinnerDesign sub-envs sharing one task (in `workers` processes); other
    keyword arguments as `gym.make`."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": SpinnerDesignEnv.metadata["render_fps"],
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, autoreset_mode: str | AutoresetMode = "next_step",
                 render_mode: Optional[str] = None, workers: int = 1, **kwargs: Any):
        if (isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer))
                or not 1 <= num_envs <= MAX_NUM_ENVS):
            raise ConfigError("num_envs", f"expected an integer from 1 to {MAX_NUM_ENVS}, got {num_envs!r}")
        mode = autoreset_mode.name.lower() if isinstance(autoreset_mode, AutoresetMode) else autoreset_mode
        if mode not in MODES:
            raise ConfigError("autoreset_mode", f"unknown {autoreset_mode!r}; allowed: {sorted(MODES)}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ConfigError("render_mode", f"unknown {render_mode!r}; the vector env renders rgb_array "
                                             "(a tuple of frames, one per sub-env)")
        first = SpinnerDesignEnv(render_mode=render_mode, **kwargs)
        self.num_envs = int(num_envs)
        self._first = first
        self._shards: Optional[Shards] = None
        workers = _checked_workers(workers, self.num_envs)
        if workers == 1:
            self.envs = [first] + [_sharing_task(first) for _ in range(self.num_envs - 1)]
        else:
            self.envs = []  # they live in the workers
            self._shards = Shards(SpinnerDesignVectorEnv, self.num_envs, workers, _device_of(first),
                                  {"autoreset_mode": mode, "render_mode": render_mode, **kwargs})
        self.metadata = {**self.metadata, "autoreset_mode": MODES[mode]}
        self.render_mode = render_mode
        self.single_action_space = first.action_space
        self.single_observation_space = first.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)  # next_step: reset in the coming step
        self._ended = np.zeros(self.num_envs, dtype=bool)  # disabled: ended and not reset since
        self._observations = np.zeros(self.observation_space.shape, dtype=self.observation_space.dtype)

    @property
    def task(self):
        """The task all sub-envs share (its `settings_map` maps actions to settings; with
        workers, each worker holds its own copy)."""
        return self._first.task

    def reset(self, *, seed: int | list[int | None] | None = None, options: Optional[dict] = None):
        """Reset the sub-envs: every one, or those of `options["reset_mask"]` (a bool array of
        num_envs entries; the others keep their observations). An int seed s seeds sub-env i
        with s + i; a list gives each sub-env its own (None: unseeded)."""
        observations, each = self.reset_each(seed=seed, options=options)
        infos: dict = {}
        for i, info in enumerate(each):
            if info is not None:
                infos = self._add_info(infos, info, i)
        return observations, infos

    def reset_each(self, *, seed: int | list[int | None] | None = None,
                   options: Optional[dict] = None) -> tuple[np.ndarray, list[Optional[dict]]]:
        """`reset` with each sub-env's info as its own dict (None for one the mask left
        alone) instead of gymnasium's stacked infos, which turn Python numbers into numpy
        scalars and a None among numbers into NaN (spreadgym.agents.batched_vec_env)."""
        self._check_open()
        seeds = self._seeds(seed)
        if options is not None and not isinstance(options, dict):
            raise ConfigError("options", f"expected a mapping, got {type(options).__name__}")
        options = dict(options) if options else {}
        mask = self._reset_mask(options.pop("reset_mask")) if "reset_mask" in options else None
        if options:
            check_reset_options(options)  # here, so that a bad option resets nothing (in one process or in workers)
            if "context" in options:
                self.task.check_context(options["context"])
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))  # the vector env's own np_random, as gymnasium's
        each: list[Optional[dict]] = [None] * self.num_envs
        for i, observation, info in self._reset_records(seeds, options, mask):
            self._observations[i] = observation
            each[i] = info
        reset = np.ones(self.num_envs, dtype=bool) if mask is None else mask
        self._autoreset[reset] = False
        self._ended[reset] = False
        return self._observations.copy(), each

    def _reset_records(self, seeds: list, options: dict, mask: Optional[np.ndarray]) -> list[tuple]:
        """(i, observation, info) of each sub-env reset (all, or those of `mask`), in order."""
        if self._shards is not None:
            return self._from_workers("_reset_records", lambda a, b: None if mask is not None and not mask[a:b].any()
                                      else (seeds[a:b], options, None if mask is None else mask[a:b]))
        return [(i, *env.reset(seed=env_seed, options=options or None))
                for i, (env, env_seed) in enumerate(zip(self.envs, seeds)) if mask is None or mask[i]]

    def _from_workers(self, name: str, args_of) -> list[tuple]:
        """The records of method `name` on every worker (`args_of(first, stop)`: its
        arguments for the block [first, stop), or None to leave it out), indices global."""
        answers = self._shards.call(name, [args_of(a, b) for a, b in self._shards.blocks])
        return [(a + i, *rest) for (a, _), records in zip(self._shards.blocks, answers) for i, *rest in records or []]

    def _seeds(self, seed) -> list[Optional[int]]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(self.num_envs)]
        if not isinstance(seed, (list, tuple, np.ndarray)):
            raise ValueError(f"seed must be an int, a list of num_envs={self.num_envs} ints or None, got {seed!r}")
        seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(f"reset got {len(seeds)} seeds for num_envs={self.num_envs}")
        for i, s in enumerate(seeds):  # as a single env's reset takes them: a 1.5 or a "1" is no seed
            if s is not None and (isinstance(s, (bool, np.bool_)) or not isinstance(s, (int, np.integer)) or s < 0):
                raise ValueError(f"seed[{i}] must be a non-negative int or None, got {s!r}")
        return [None if s is None else int(s) for s in seeds]

    def _reset_mask(self, mask) -> np.ndarray:
        """`options["reset_mask"]` checked as gymnasium's vector envs check it."""
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (self.num_envs,):
            raise ValueError(f"options['reset_mask'] must be a numpy bool array of shape ({self.num_envs},), "
                             f"got {mask!r}")
        if not mask.any():
            raise ValueError("options['reset_mask'] resets nothing: it needs at least one True entry")
        return mask

    def step(self, actions):
        observations, rewards, terminated, truncated, each, finals = self.step_each(actions)
        infos: dict = {}
        for i, (info, final) in enumerate(zip(each, finals)):
            if final is not None:
                infos = self._add_info(infos, {"final_obs": final[0], "final_info": final[1]}, i)
            infos = self._add_info(infos, info, i)
        return observations, rewards, terminated, truncated, infos

    def step_each(self, actions) -> tuple:
        """`step` with each sub-env's info as its own dict instead of gymnasium's stacked
        infos (see `reset_each`): (observations, rewards, terminated, truncated, infos,
        finals), finals[i] the (observation, info) that ended sub-env i's episode in
        same_step mode (its infos[i] is then the reset's), else None."""
        self._check_open()
        actions = np.asarray(actions)
        if actions.shape[:1] != (self.num_envs,):
            raise ValueError(f"actions must have {self.num_envs} rows (one per sub-env), got shape {actions.shape}")
        mode = self.metadata["autoreset_mode"]
        if mode is AutoresetMode.DISABLED and self._ended.any():
            raise ValueError(f"sub-envs {np.flatnonzero(self._ended).tolist()} ended their episodes; autoreset is "
                             "disabled: reset them first with reset(options={'reset_mask': mask})")
        for i in np.flatnonzero(~self._autoreset):  # here, so that a bad action steps nothing (nor do workers)
            check_action(actions[i], self.task.settings_map.size)
        rewards = np.zeros(self.num_envs, dtype=np.float64)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        each: list = [None] * self.num_envs
        finals: list = [None] * self.num_envs
        for i, obs, reward, ended, cut, info, final in self._step_records(actions, self._autoreset):
            rewards[i], terminated[i], truncated[i] = reward, ended, cut
            self._observations[i] = obs
            each[i], finals[i] = info, final
        if mode is AutoresetMode.NEXT_STEP:
            self._autoreset = terminated | truncated
        elif mode is AutoresetMode.DISABLED:
            self._ended = terminated | truncated
        return self._observations.copy(), rewards, terminated, truncated, each, finals

    def _step_records(self, actions: np.ndarray, autoreset: np.ndarray) -> list[tuple]:
        """(i, observation, reward, terminated, truncated, info, final) of every sub-env:
        stepped, or reset where `autoreset` says (next_step mode); `final` is the (observation,
        info) that ended an episode in same_step mode, which then resets the sub-env, else None."""
        if self._shards is not None:
            return self._from_workers("_step_records", lambda a, b: (actions[a:b], autoreset[a:b]))
        same_step = self.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
        self._run_designs(actions, autoreset)
        records = []
        try:
            for i, env in enumerate(self.envs):
                if autoreset[i]:  # next_step mode only
                    obs, info = env.reset()
                    records.append((i, obs, 0.0, False, False, info, None))
                    continue
                obs, reward, ended, cut, info = env.step(actions[i])
                final = None
                if same_step and (ended or cut):
                    final = (obs, info)
                    obs, info = env.reset()
                records.append((i, obs, reward, ended, cut, info, final))
        finally:
            self.task.__dict__.pop("run", None)  # back to Task.run
        return records

    def render(self) -> Optional[tuple]:
        """One frame per sub-env (render_mode="rgb_array"), as gymnasium's sync vector env gives them."""
        if self.render_mode is None:
            return None
        if self._shards is not None:
            return tuple(frame for frames in self._shards.call("render", [()] * len(self._shards.blocks))
                         for frame in frames)
        return tuple(env.render() for env in self.envs)

    def _run_designs(self, actions: np.ndarray, autoreset: np.ndarray) -> None:
        """The tray tests of every sub-env that steps now, in batches: the scene each
        sub-env's `step` will ask for (its action checked as `step` checks it); the shared
        task then hands each sub-env its result in turn, running each batch when its first
        sub-env asks (`_Prefetched`)."""
        task = self.task
        stepping = [i for i, env in enumerate(self.envs)
                    if not autoreset[i] and env._context is not None]  # one that needs a reset fails in step
        library = batches_library(task.library, [self.envs[i]._batch for i in stepping])
        if not batched(self.envs[0]) or library is None:
            return
        scenes = [self.envs[i].design_scene(actions[i])[0] for i in stepping]
        task.run = _Prefetched(scenes, lambda part: task.run_batch(part, library))  # step() takes them; then Task.run

    def _check_open(self) -> None:
        if self.closed:
            raise gym.error.ClosedEnvironmentError("the vector env is closed: make a new one")

    def close_extras(self, **kwargs: Any):
        if getattr(self, "_shards", None) is not None:  # getattr: also for an instance whose __init__ raised
            self._shards.close()
        first = getattr(self, "_first", None)
        for env in getattr(self, "envs", None) or ([first] if first is not None else []):
            env.close()


class _Prefetched:
    """A task's `run` for one vector step: the results of `scenes` in order, each for the
    scene it was computed for (checked), computed by `run_batch` in parts of at most
    MAX_GRANULE_COPIES landing points, each when the first of its scenes is asked for.
    (Computing the next part on a helper thread while the sub-envs of the part before
    step was measured: a tie on two and on sixteen cores, docs/performance.md.)"""

    def __init__(self, scenes: list, run_batch) -> None:
        self.scenes, self.run_batch = list(scenes), run_batch
        self.results: list = []

    def __call__(self, scene, rendering: bool = False, batch=None):
        if not self.results:
            self.results = list(self.run_batch(self.scenes[:_part_size(self.scenes)]))
        expected, result = self.scenes.pop(0), self.results.pop(0)
        if rendering or scene != expected:  # a hidden batch is in the scene (its fertilizer copy, its contacts)
            raise RuntimeError("the vector env's batch and its sub-envs' steps disagree")
        return result


def _part_size(scenes: list) -> int:
    """How many of `scenes`, from the first, one batch runs: the scenes shared out evenly
    over the fewest batches of at most MAX_GRANULE_COPIES landing points each (and at least
    one scene per batch)."""
    copies = [granule_copies(scene) for scene in scenes]
    parts = -(-sum(copies) // MAX_GRANULE_COPIES)
    size = -(-len(scenes) // max(parts, 1))
    while size > 1 and sum(copies[:size]) > MAX_GRANULE_COPIES:
        size -= 1
    return size


def step_designs(env, resets: list[tuple[int, Optional[dict]]], actions: list) -> list[tuple]:
    """`env.reset(seed=seed, options=options)` then `env.step(action)` for each reset and
    action in turn, on one SpinnerDesign env (wrappers included): the same returns, bit
    for bit, with the tray tests run as one batch. Each job is reset twice: once to learn
    the scene its step runs, once to step it. An env that pools runs to a precision or
    renders steps each job itself (`batched`); hidden batches (the robust variant) run
    together in one library holding each episode's fertilizer copy. Every seed must be
    given: an unseeded reset, done twice, would draw two different jobs."""
    unseeded = [i for i, (seed, _) in enumerate(resets) if seed is None]
    if unseeded:
        raise ValueError(f"step_designs needs a seed for every job (each is reset twice); "
                         f"jobs {unseeded[:5]} have none")
    base = env.unwrapped
    task = base.task
    if not batched(base):
        return _one_by_one(env, resets, actions)
    scenes, batches = [], []
    for (seed, options), action in zip(resets, actions):
        env.reset(seed=seed, options=options)
        scenes.append(base.design_scene(action)[0])
        batches.append(base._batch)
    library = batches_library(task.library, batches)
    if library is None:
        return _one_by_one(env, resets, actions)
    task.run = _Prefetched(scenes, lambda part: task.run_batch(part, library))
    try:
        steps = []
        for (seed, options), action in zip(resets, actions):
            env.reset(seed=seed, options=options)
            steps.append(env.step(action))
        return steps
    finally:
        task.__dict__.pop("run", None)  # back to Task.run


def _one_by_one(env, resets, actions) -> list[tuple]:
    return [(env.reset(seed=seed, options=options), env.step(action))[1]
            for (seed, options), action in zip(resets, actions)]


def batched(env: SpinnerDesignEnv) -> bool:
    """Whether `env`'s steps can run as one batch: not pooled to a precision, not rendering
    (the frames need disc paths). Hidden batches run together in one library holding each
    episode's fertilizer copy (`batches_library`)."""
    cfg = env.task.cfg
    return cfg.precision is None and env.render_mode is None


def _checked_workers(workers, num_envs: int) -> int:
    """`workers` as a count of processes: 1 to min(num_envs, the threads spreadgym may use)
    (on a GPU too: the workers share it, each with its share of the threads)."""
    count = threads.thread_count()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or not 1 <= workers <= num_envs:
        raise ConfigError("workers", f"expected a whole number of processes from 1 to num_envs={num_envs}, "
                                     f"got {workers!r}")
    if workers > count:
        raise ConfigError("workers", f"{workers} processes for the {count} threads spreadgym may use here "
                                     f"(SPREADGYM_THREADS, the cores); allowed: 1 to {count}")
    return int(workers)


def _device_of(env: SpinnerDesignEnv) -> str:
    """Where `env`'s spinner runs: its `device` keyword, else this process's choice (a
    spawned worker would read only SPREADGYM_DEVICE)."""
    return env.task.cfg.device or device.current()


def _sharing_task(env: SpinnerDesignEnv) -> SpinnerDesignEnv:
    """A sub-env with `env`'s (read-only) task and config and a state of its own."""
    other = copy.copy(env)
    other._np_random = None
    other._np_random_seed = None
    other._context = other._scene = other._last = other._viewer = other._batch = None
    other._context_info = {}
    return other
