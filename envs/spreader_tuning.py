"""`spreadgym/SpreaderTuning-v1` (and SpreaderTuningHard-v1): calibrate a spreader the way a
tray test does, over several steps.

`reset` draws a job (as in SpinnerDesign), sets the initial settings (config
`initial_settings`) and runs a first tray test. Each `step` changes the settings by
`max_change * action` in normalised units (the full range of a setting is 2) and runs
another tray test with a fresh granule sample, so the measured pattern is noisy like a
real one. The episode is `terminated` when the measured CV at the target swath is at
or below `goal_cv_percent`, `truncated` after `max_steps` steps.

Observation (float32, every entry in [-1, 1]), in this order:
    context                  as SpinnerDesign (C entries)
    settings                 current settings, normalised to [-1, 1] (A entries, action order)
    cv                       min(CV, cv_worst) / cv_worst, measured at the target (1 if nothing landed)
    swath                    min(W_eff / W_target, 2) / 2
    landed                   landed mass / released mass
    steps_left               (max_steps - steps taken) / max_steps
    single pass              `single_pass_bins` bins over +-`single_pass_half_width_m`: the
                             tray masses re-binned (mass beyond the window goes to the edge
                             bins), divided by the largest bin (0 if nothing landed)
    bout                     `bout_bins` bins over one bout at the target swath: the
                             overlapped tray masses re-binned, divided by their mean and by
                             2, clipped to [0, 1] (0.5 = the mean)

Start rule (`start: unsolved`, v1): random initial settings are redrawn while the first
tray test already meets the goal, at most `start_draws` times; every draw is a tray test
(`info["tray_tests"]`), and `info["start_solved"]` says whether all of them met it.

Version history:
    v1: the jobs of SpinnerDesign-v1 (held-out widths and fertilizer for evaluation), the
        unsolved start rule (v0 started solved in about half its episodes), the harder
        SpreaderTuningHard-v1 (goal 10 % in 30 tray tests), the passive checker on, the
        TimeLimit checked against `max_steps`.
    v0: (deprecated, kept working) starts drawn without a rule, three ids, the checker off.
"""

from __future__ import annotations

import copy
from typing import Optional

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from spreadgym.config.scene import Scene
from spreadgym.envs.common import reward as rewards
from spreadgym.envs.common.actions import check_action
from spreadgym.envs.common.base_env import SpreadgymEnv
from spreadgym.envs.common.config import TUNING
from spreadgym.envs.common.render import draw_frame, frame_lines
from spreadgym.envs.common.task import SEED_BOUND, Batch, check_reset_options, info_metrics
from spreadgym.spread import pattern

SUMMARY_NAMES = ["cv", "swath", "landed", "steps_left"]


def rebin(edges: np.ndarray, mass: np.ndarray, new_edges: np.ndarray) -> np.ndarray:
    """Mass per new bin, spreading each old bin's mass uniformly over it.

    The first and last new bins also collect whatever lies beyond them, so the total
    is kept."""
    cumulative = np.concatenate([[0.0], np.cumsum(mass)])
    at = np.interp(new_edges, edges, cumulative)
    at[0], at[-1] = 0.0, cumulative[-1]
    return np.maximum(np.diff(at), 0.0)


def single_pass_features(trays: pattern.Trays, half_width_m: float, bins: int) -> np.ndarray:
    """Single-pass tray masses on a fixed grid, divided by the largest bin."""
    w = trays.width_m
    edges = np.append(trays.center_m - 0.5 * w, trays.center_m[-1] + 0.5 * w)
    masses = rebin(edges, trays.mass_kg, np.linspace(-half_width_m, half_width_m, bins + 1))
    top = masses.max() if masses.size else 0.0
    return masses / top if top > 0 else np.zeros(bins)


def bout_features(trays: pattern.Trays, bout_width_m: float, driving: str, bins: int) -> np.ndarray:
    """Overlapped pattern over one bout on `bins` bins, / mean / 2, clipped to [0, 1]
    (over one period of the field where `pattern.bout_pattern` gives the period)."""
    if trays.total_kg <= 0:
        return np.zeros(bins)
    bout = pattern.bout_pattern(trays, bout_width_m, driving)
    n, w = pattern.bout_tray_count(bout_width_m, trays.width_m), trays.width_m
    start = (-(n // 2) - 0.5) * w
    edges = start + w * np.arange(bout.size + 1)
    masses = rebin(edges, bout, np.linspace(edges[0], edges[-1], bins + 1))
    mean = masses.mean()
    return np.clip(masses / mean / 2.0, 0.0, 1.0) if mean > 0 else np.zeros(bins)


class SpreaderTuningEnv(SpreadgymEnv):
    """Adjust rpm, vane pitch and deflector angles step by step until the tray test passes."""

    config_name = TUNING

    def __init__(self, render_mode: Optional[str] = None, **kwargs):
        super().__init__(render_mode, **kwargs)
        smap = self.task.settings_map
        obs_cfg = self.config.observation
        self.observation_names = (
            list(self.task.context_names)
            + [f"setting:{n}" for n in smap.names]
            + SUMMARY_NAMES
            + [f"single_pass[{i}]" for i in range(obs_cfg.single_pass_bins)]
            + [f"bout[{i}]" for i in range(obs_cfg.bout_bins)]
        )
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(len(self.observation_names),), dtype=np.float32)
        self.reward_bounds = rewards.tuning_reward_bounds(self.config.reward)
        self._ended = False
        self._scene: Optional[Scene] = None
        self._context_obs = np.zeros(self.task.context_size, dtype=np.float32)
        self._unit = np.zeros(smap.size)
        self._steps = 0
        self._batch: Optional[Batch] = None  # the hidden batch of a robust variant

    # -- gymnasium API -----------------------------------------------------------------
    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        self._context = self._last = None  # a reset that fails leaves an env that needs one
        context = self.task.sample_context(self.np_random)
        if options is not None:
            check_reset_options(options)
            if "context" in options:
                context = self.task.replace_context(context, options["context"])
        self._context = context
        self._ended = False
        self._scene = self.task.context_scene(context)
        self._context_info = self.task.context_info(context)
        self._context_obs = self.task.encode_context(context, self._scene)
        self._batch = self.task.sample_batch(context, self.np_random)
        self._steps = 0
        tray_tests = 0
        while True:  # the start rule: with `start: unsolved`, redraw a start that already meets the goal
            self._unit = self._initial_unit()
            result, settings, score = self._tray_test()
            tray_tests += 1
            redraw = self.config.start == "unsolved" and self._reached_goal(result)
            if not redraw or tray_tests >= self.config.start_draws:
                break
        self._last = (result.scene, result, settings, score, None)
        info = self._info(result, settings, score)
        info["tray_tests"] = tray_tests
        info["start_solved"] = self._reached_goal(result)
        if self.render_mode == "human":
            self.render()
        return self._observation(result, score), info

    def step(self, action):
        if self._context is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if self._ended:
            raise gym.error.ResetNeeded("the episode has ended (terminated or truncated); call reset()")
        smap = self.task.settings_map
        a = check_action(action, smap.size)
        self._unit = np.clip(self._unit + self.config.max_change * a, -1.0, 1.0)
        self._steps += 1
        result, settings, score = self._tray_test()
        terminated = self._reached_goal(result)
        truncated = bool(not terminated and self._steps >= self.config.max_steps)
        self._ended = terminated or truncated
        reward = rewards.tuning_reward(score, self.config.reward, terminated)
        self._last = (result.scene, result, settings, score, reward)
        info = self._info(result, settings, score)
        if self.render_mode == "human":
            self.render()
        return self._observation(result, score), reward, terminated, truncated, info

    # -- internals -----------------------------------------------------------------------
    def _frame(self) -> np.ndarray:
        r = self.config.render
        if self._last is None:
            return draw_frame(self.task.base_scene, None, r.width_px, r.height_px, r.trajectories,
                              ["call reset() first"])
        scene, result, settings, score, reward = self._last
        extra = [f"step {self._steps}/{self.config.max_steps}, goal CV <= {self.config.goal_cv_percent:g} %"]
        lines = frame_lines(self._context, settings, score, reward if reward is not None else float("nan"), extra)
        return draw_frame(scene, result, r.width_px, r.height_px, r.trajectories, lines)

    def _initial_unit(self) -> np.ndarray:
        """The normalised settings of the first tray test (config `initial_settings`)."""
        smap = self.task.settings_map
        mode = self.config.initial_settings
        if mode == "random":
            return self.np_random.uniform(-1.0, 1.0, size=smap.size)
        if mode == "middle":
            return np.zeros(smap.size)
        return smap.to_unit(smap.from_scene(self._scene))

    def _reached_goal(self, result) -> bool:
        cv = result.metrics.cv_percent_at_target
        return bool(cv is not None and cv <= self.config.goal_cv_percent)

    def _tray_test(self):
        settings = self.task.settings_map.to_settings(self._unit)
        seed = int(self.np_random.integers(SEED_BOUND))
        result = self.task.run(self.task.settings_scene(self._scene, settings, seed, self._batch),
                               rendering=self.render_mode is not None, batch=self._batch)
        return result, settings, rewards.score(result.metrics, self.config.reward)

    def _observation(self, result, score: rewards.Score) -> np.ndarray:
        obs_cfg = self.config.observation
        scene = result.scene
        summary = [
            score.cv_term,
            min(score.effective_swath_m / score.target_swath_m, 2.0) / 2.0,
            score.landed_fraction,
            (self.config.max_steps - self._steps) / self.config.max_steps,
        ]
        parts = [
            self._context_obs,
            self._unit,
            np.clip(summary, 0.0, 1.0),
            single_pass_features(result.trays, obs_cfg.single_pass_half_width_m, obs_cfg.single_pass_bins),
            bout_features(result.trays, scene.pattern.target_swath_m, scene.pattern.driving, obs_cfg.bout_bins),
        ]
        obs = np.concatenate([np.asarray(p, dtype=np.float64) for p in parts])
        return np.clip(obs, -1.0, 1.0).astype(np.float32)

    def _info(self, result, settings, score: rewards.Score) -> dict:
        return {
            "metrics": info_metrics(result.metrics),
            "settings": settings.as_dict(),
            "context": copy.deepcopy(self._context_info),
            "reward_terms": score.as_dict(),
            "sim_seed": int(result.scene.sim.seed),
            "steps": self._steps,
        }
