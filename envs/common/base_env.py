"""The part of both environments that is not the task: construction from the config,
render modes (an RGB frame, or a window for "human") and close."""

from __future__ import annotations

from typing import Any, Optional

import gymnasium as gym
import numpy as np

from spreadgym.config.base import brief
from spreadgym.envs.common.config import load_env_config
from spreadgym.envs.common.render import HumanViewer
from spreadgym.envs.common.task import Context, Task
from spreadgym.errors import ConfigError


class SpreadgymEnv(gym.Env):
    """Base of the spreadgym envs: `config_name` names the YAML in configs/envs/, `_frame`
    draws the current picture."""

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 4}
    config_name: str

    def __init__(self, render_mode: Optional[str] = None, **kwargs: Any):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError("render_mode", f"unknown {brief(render_mode)}; allowed: {self.metadata['render_modes']}")
        self.render_mode = render_mode
        self.config = load_env_config(self.config_name, kwargs)
        self.task = Task(self.config)
        self.action_space = self.task.settings_map.space
        self._context: Optional[Context] = None
        self._context_info: dict = {}
        self._last = None  # (scene, result, settings, score, reward) of the latest tray test
        self._viewer: Optional[HumanViewer] = None

    def _frame(self) -> np.ndarray:
        raise NotImplementedError

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "render() was called without a render mode; "
                'make the env with render_mode="rgb_array" or "human"'
            )
            return None
        frame = self._frame()
        if self.render_mode == "rgb_array":
            return frame
        if self._viewer is None:
            self._viewer = HumanViewer(self.metadata["render_fps"])
        self._viewer.show(frame)
        return None

    def close(self):
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
