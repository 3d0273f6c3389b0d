"""`spreadgym/SpinnerDesign-v1` (and its ladder of rungs): choose the spinner settings for a
job, one step per episode.

`reset` draws a job (the context) with the env's `np_random`; the observation is the
normalised context. The action sets rpm, vane pitch and the angles of adjustable
deflectors (see `spreadgym.envs.common.actions`); `step` runs the whole chain (spinner,
deflectors, flight, tray pattern) once and ends the episode. The reward is in
`spreadgym.envs.common.reward`. docs/environments.md has the layouts and the config keys.

Determinism: reset draws, in this order, the fertilizer, the spinner material, the
target swath (as a number of trays), the forward speed, the wind (x, y) and then the
seed `sim.seed` of the granule sample, all from `np_random`. The same reset seed and
the same actions give the same observations, rewards and infos bit for bit.
A step after the end of an episode re-runs the same job with the same granule
sample (useful for black-box optimisers: common random numbers). On the robust rung,
reset then draws the episode's hidden batch (`Task.sample_batch`).

Version history:
    v1: the benchmark's tasks (docs/benchmark.md), one namespaced id each:
        SpinnerDesign (the first rung), SpinnerDesignPitch (one pitch per vane),
        SpinnerDesignTwin (two discs and the drop point), SpinnerDesignWind (forward speed
        and wind), SpinnerDesignPlates (adjustable deflector plates), SpinnerDesignRobust
        (a hidden batch from the variability model). Continuous target widths with
        held-out bands, a held-out fertilizer, evaluation jobs checked disjoint from the
        training contexts, an observation of the material properties (no one-hot) and of
        the job entries that vary, gymnasium's passive checker on.
    v0: (deprecated, kept working) three fertilizers x nine widths on the tray grid, the
        evaluation jobs among the training contexts, three ids, the checker off. Over
        its life the model behind it changed (analytic, then the compiled full model, the
        bias-corrected CV, the default budget) under the same id.
"""

from __future__ import annotations

import copy
from typing import Optional

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from spreadgym.config.scene import Scene
from spreadgym.envs.common import reward as rewards
from spreadgym.envs.common.actions import Settings, check_action
from spreadgym.envs.common.base_env import SpreadgymEnv
from spreadgym.envs.common.config import DESIGN
from spreadgym.envs.common.render import draw_frame, frame_lines
from spreadgym.envs.common.task import SEED_BOUND, Batch, check_reset_options, info_metrics


class SpinnerDesignEnv(SpreadgymEnv):
    """Choose rpm, vane pitch and deflector angles for a sampled job; one step per episode
    (the module docstring has the version history)."""

    config_name = DESIGN

    def __init__(self, render_mode: Optional[str] = None, **kwargs):
        super().__init__(render_mode, **kwargs)
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(self.task.context_size,), dtype=np.float32)
        self.reward_bounds = rewards.design_reward_bounds(self.config.reward)
        self._scene: Optional[Scene] = None
        self._sim_seed = 0
        self._batch: Optional[Batch] = None  # the hidden batch of the robust variant

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        self._context = self._last = None  # a reset that fails leaves an env that needs one
        context = self.task.sample_context(self.np_random)
        self._sim_seed = int(self.np_random.integers(SEED_BOUND))
        if options is not None:
            check_reset_options(options)
            if "context" in options:
                context = self.task.replace_context(context, options["context"])
        self._batch = self.task.sample_batch(context, self.np_random)
        self._context = context
        self._scene = self.task.context_scene(context)
        self._context_info = self.task.context_info(context)
        self._last = None
        if self.render_mode == "human":
            self.render()
        return self.task.encode_context(context, self._scene), {"context": copy.deepcopy(self._context_info)}

    def design_scene(self, action) -> tuple[Scene, Settings]:
        """The scene `step(action)` runs (the action checked as `step` checks it) and its settings."""
        unit = check_action(action, self.task.settings_map.size)
        settings = self.task.settings_map.to_settings(unit)
        return self.task.settings_scene(self._scene, settings, self._sim_seed, self._batch), settings

    def step(self, action):
        if self._context is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        scene, settings = self.design_scene(action)
        result = self.task.run(scene, rendering=self.render_mode is not None, batch=self._batch)
        score = rewards.score(result.metrics, self.config.reward)
        reward = rewards.design_reward(score)
        self._last = (scene, result, settings, score, reward)
        info = {
            "metrics": info_metrics(result.metrics),
            "settings": settings.as_dict(),
            "context": copy.deepcopy(self._context_info),
            "reward_terms": score.as_dict(),
            "sim_seed": self._sim_seed,
        }
        if self._batch is not None:
            info["batch"] = self._batch.as_dict()
        if self.render_mode == "human":
            self.render()
        return self.task.encode_context(self._context, self._scene), reward, True, False, info

    def _frame(self) -> np.ndarray:
        r = self.config.render
        if self._last is None:
            scene = self._scene if self._scene is not None else self.task.base_scene
            lines = frame_lines(self._context, None, None, None, ["no step yet"])
            return draw_frame(scene, None, r.width_px, r.height_px, r.trajectories, lines)
        scene, result, settings, score, reward = self._last
        lines = frame_lines(self._context, settings, score, reward)
        return draw_frame(scene, result, r.width_px, r.height_px, r.trajectories, lines)
