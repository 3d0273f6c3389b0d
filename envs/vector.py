"""`spreadgym/SpinnerDesign-v0` as a gymnasium `VectorEnv` (its registered `vector_entry_point`).

`gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=N, **kwargs)` builds this class: one
`Task` (library, base scene, checks) shared by N sub-envs instead of N copies, a batch
of actions in and stacked observations, rewards and infos out.

Same results as the single env: sub-env i is a `SpinnerDesignEnv` sharing the task,
so with `reset(seed=s)` (sub-env i seeded s + i, as gymnasium's vector envs do) every
observation, reward and info equals, bit for bit, that of `gym.make(id).reset(seed=s + i)`
followed by the same actions, with a plain `reset()` after each episode.

Speed: the tray tests of one step run as one batch (spreadgym.spread.batch: every
granule of every sub-env's design in one parallel kernel, the rest of the scenes side by
side on spreadgym.threads' threads), with the same bits as one run each; each sub-env's
`step` then takes its own result. docs/performance.md has the measured rates.

Autoreset: `autoreset_mode="next_step"` (gymnasium's default: the step after an
episode's end resets that sub-env and ignores its action) or `"same_step"` (the
sub-env is reset in the step that ends the episode; its last observation and info are
in `info["final_obs"]` and `info["final_info"]`). SpinnerDesign ends every episode
after one step, so "same_step" wastes no calls on resets.
"""

from __future__ import annotations

import copy
from typing import Any, Optional

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from spreadgym.envs.common.actions import check_action
from spreadgym.envs.spinner_design import SpinnerDesignEnv
from spreadgym.errors import ConfigError

MODES = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP}


class SpinnerDesignVectorEnv(VectorEnv):
    """`num_envs` SpinnerDesign sub-envs sharing one task; keyword arguments as `gym.make`."""

    def __init__(self, num_envs: int = 1, autoreset_mode: str | AutoresetMode = "next_step",
                 render_mode: Optional[str] = None, **kwargs: Any):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ConfigError("num_envs", f"expected an integer >= 1, got {num_envs!r}")
        mode = autoreset_mode.name.lower() if isinstance(autoreset_mode, AutoresetMode) else autoreset_mode
        if mode not in MODES:
            raise ConfigError("autoreset_mode", f"unknown {autoreset_mode!r}; allowed: {sorted(MODES)}")
        if render_mode is not None:
            raise ConfigError("render_mode", "the vector env does not render; render a single env instead")
        first = SpinnerDesignEnv(**kwargs)
        self.envs = [first] + [_sharing_task(first) for _ in range(int(num_envs) - 1)]
        self.num_envs = int(num_envs)
        self.metadata = {"autoreset_mode": MODES[mode]}
        self.render_mode = None
        self.single_action_space = first.action_space
        self.single_observation_space = first.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)

    @property
    def task(self):
        """The task all sub-envs share (its `settings_map` maps actions to settings)."""
        return self.envs[0].task

    def reset(self, *, seed: int | list[int | None] | None = None, options: Optional[dict] = None):
        """Reset every sub-env; an int seed s seeds sub-env i with s + i."""
        super().reset(seed=seed)
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset got {len(seeds)} seeds for num_envs={self.num_envs}")
        observations, infos = [], {}
        for i, (env, env_seed) in enumerate(zip(self.envs, seeds)):
            obs, info = env.reset(seed=env_seed, options=options)
            observations.append(obs)
            infos = self._add_info(infos, info, i)
        self._autoreset[:] = False
        return np.stack(observations), infos

    def step(self, actions):
        actions = np.asarray(actions)
        if actions.shape[:1] != (self.num_envs,):
            raise ValueError(f"actions must have {self.num_envs} rows (one per sub-env), got shape {actions.shape}")
        same_step = self.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
        self._run_designs(actions)
        try:
            observations = []
            rewards = np.zeros(self.num_envs, dtype=np.float64)
            terminated = np.zeros(self.num_envs, dtype=bool)
            truncated = np.zeros(self.num_envs, dtype=bool)
            infos: dict = {}
            for i, env in enumerate(self.envs):
                if self._autoreset[i]:  # next_step mode only
                    obs, info = env.reset()
                else:
                    obs, rewards[i], terminated[i], truncated[i], info = env.step(actions[i])
                    if same_step and (terminated[i] or truncated[i]):
                        infos = self._add_info(infos, {"final_obs": obs, "final_info": info}, i)
                        obs, info = env.reset()
                observations.append(obs)
                infos = self._add_info(infos, info, i)
        finally:
            self.task.__dict__.pop("run", None)  # back to Task.run
        if not same_step:
            self._autoreset = terminated | truncated
        return np.stack(observations), rewards, terminated, truncated, infos

    def _run_designs(self, actions: np.ndarray) -> None:
        """The tray tests of every sub-env that steps now, as one batch: the scene each
        sub-env's `step` will ask for (its action checked as `step` checks it), run
        together; the shared task then hands each sub-env its result in turn."""
        task = self.task
        if task.cfg.precision is not None:  # runs pooled to a precision: each sub-env's own, in its step
            return
        scenes = []
        for i, env in enumerate(self.envs):
            if not self._autoreset[i] and env._context is not None:  # a sub-env that needs a reset fails in step
                settings = task.settings_map.to_settings(check_action(actions[i], task.settings_map.size))
                scenes.append(task.settings_scene(env._scene, settings, env._sim_seed))
        results = task.run_batch(scenes)
        task.run = _Prefetched(scenes, results)  # step() below takes them; then Task.run again

    def close_extras(self, **kwargs: Any):
        for env in getattr(self, "envs", []):  # also for an instance whose __init__ raised
            env.close()


class _Prefetched:
    """A task's `run` for one vector step: the batch's results in order, each for the
    scene it was computed for (checked)."""

    def __init__(self, scenes: list, results: list) -> None:
        self.pending = list(zip(scenes, results))

    def __call__(self, scene, rendering: bool = False):
        expected, result = self.pending.pop(0)
        if rendering or scene != expected:
            raise RuntimeError("the vector env's batch and its sub-envs' steps disagree")
        return result


def step_designs(env, resets: list[tuple[Optional[int], Optional[dict]]], actions: list) -> list[tuple]:
    """`env.reset(seed=seed, options=options)` then `env.step(action)` for each reset and
    action in turn, on one SpinnerDesign env (wrappers included): the same returns, bit
    for bit, with the tray tests run as one batch. Each job is reset twice: once to learn
    the scene its step runs, once to step it. An env that pools runs to a precision or
    renders steps each job itself."""
    base = env.unwrapped
    task = base.task
    if task.cfg.precision is not None or base.render_mode is not None:
        return [(env.reset(seed=seed, options=options), env.step(action))[1]
                for (seed, options), action in zip(resets, actions)]
    scenes = []
    for (seed, options), action in zip(resets, actions):
        env.reset(seed=seed, options=options)
        settings = task.settings_map.to_settings(check_action(action, task.settings_map.size))
        scenes.append(task.settings_scene(base._scene, settings, base._sim_seed))
    results = task.run_batch(scenes)
    task.run = _Prefetched(scenes, results)
    try:
        steps = []
        for (seed, options), action in zip(resets, actions):
            env.reset(seed=seed, options=options)
            steps.append(env.step(action))
        return steps
    finally:
        task.__dict__.pop("run", None)  # back to Task.run


def _sharing_task(env: SpinnerDesignEnv) -> SpinnerDesignEnv:
    """A sub-env with `env`'s (read-only) task and config and a state of its own."""
    other = copy.copy(env)
    other._np_random = None
    other._np_random_seed = None
    other._context = other._scene = other._last = other._viewer = None
    other._context_info = {}
    return other
