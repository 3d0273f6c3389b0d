"""A gymnasium vector env seen by stable-baselines3 as one of its `VecEnv`s.

SB3 steps n envs through its own vector classes (`DummyVecEnv`, `SubprocVecEnv`: one
`gym.make` per process) and has no adapter for gymnasium's `VectorEnv`. The SpinnerDesign
tasks have a batched vector env (`gym.make_vec`: every sub-env's tray test in one batch,
in `workers` processes, on the CPU's threads or the GPU: envs/vector.py), so `train` wraps
it in `BatchedVecEnv` to step its n envs as one batch.

The conventions are SubprocVecEnv's, so what SB3 trains on is what it gets there, to the
bit: the env seeded at `reset` with the seeds `seed()` set (seed + i for env i, as
gymnasium's vector envs seed an int), a sub-env that ends an episode reset in the same
step with its last observation in `info["terminal_observation"]` and
`info["TimeLimit.truncated"]` set (truncated and not terminated), the reset's info in
`reset_infos`, rewards as float64 (DummyVecEnv, SB3's class for one env, gives float32).
Each env's info is its own dict: spreadgym's vector env hands them over as they are
(`step_each`, `reset_each`); another gymnasium vector env's are taken back out of its
stacked infos (a key only where its mask says the env gave it; numbers come back as numpy
scalars, and a None among numbers as NaN, as gymnasium stacked them). Episode records
are VecMonitor's when `train` wraps it (float32 returns, where Monitor rounds a Python
sum). The attributes are the vector env's, one for all n envs (the spaces: one env's);
the sub-envs live in the vector env (or its worker processes), so `env_method` and
`set_attr` reach none of them and say so.
"""

from __future__ import annotations

from typing import Any, Optional, Sequence

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvObs, VecEnvStepReturn


class BatchedVecEnv(VecEnv):
    """SB3 `VecEnv` over a gymnasium `VectorEnv` built with `autoreset_mode="same_step"`."""

    def __init__(self, vector_env: VectorEnv):
        if vector_env.metadata.get("autoreset_mode") is not AutoresetMode.SAME_STEP:
            raise ValueError("BatchedVecEnv needs a vector env made with autoreset_mode='same_step' "
                             f"(SB3 resets an ended env in the step that ends it), got "
                             f"{vector_env.metadata.get('autoreset_mode')!r}")
        self.vector_env = vector_env
        self._each = (vector_env.unwrapped is vector_env  # a wrapper's own step would be skipped
                      and hasattr(vector_env, "step_each") and hasattr(vector_env, "reset_each"))
        self._actions: Optional[np.ndarray] = None
        super().__init__(vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space)

    def reset(self) -> VecEnvObs:
        """Reset every env with the seeds and options `seed()` and `set_options()` gave
        (used once, as SB3's vector envs use them)."""
        options = self._options[0]
        if any(o != options for o in self._options):
            raise ValueError("BatchedVecEnv resets every env with the same options; got different ones per env")
        if "reset_mask" in options:
            raise ValueError("BatchedVecEnv resets every env: options['reset_mask'] is not for SB3's reset")
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        self._actions = None
        if self._each:
            observations, self.reset_infos = self.vector_env.reset_each(seed=seeds, options=dict(options) or None)
        else:
            observations, infos = self.vector_env.reset(seed=seeds, options=dict(options) or None)
            self.reset_infos = env_infos(infos, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait called without step_async")
        actions, self._actions = self._actions, None
        if self._each:
            observations, rewards, terminated, truncated, each, finals = self.vector_env.step_each(actions)
        else:
            observations, rewards, terminated, truncated, each, finals = unstacked_step(self.vector_env, actions)
        dones = terminated | truncated
        step_infos = []
        for i, info in enumerate(each):
            if finals[i] is not None:  # the info of an env reset in this step is the reset's
                self.reset_infos[i] = info
                final_obs, info = finals[i]
            info = dict(info)
            info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            if finals[i] is not None:
                info["terminal_observation"] = final_obs
            step_infos.append(info)
        return observations, np.asarray(rewards, dtype=np.float64), dones, step_infos

    def close(self) -> None:
        self.vector_env.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute (for the spaces, one env's), once per env of `indices`
        (the sub-envs share it)."""
        name = f"single_{attr_name}" if attr_name in ("observation_space", "action_space") else attr_name
        return [getattr(self.vector_env, name)] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"BatchedVecEnv cannot set {attr_name!r} on its sub-envs (they live in the batched "
                             "vector env); train with vec_env: subproc to reach each env")

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        raise AttributeError(f"BatchedVecEnv cannot call {method_name!r} on its sub-envs (they live in the batched "
                             "vector env); train with vec_env: subproc to reach each env")

    def env_is_wrapped(self, wrapper_class, indices: VecEnvIndices = None) -> list[bool]:
        """No sub-env is wrapped (a `VecMonitor` over this env keeps the episode records)."""
        return [False] * len(list(self._get_indices(indices)))

    def get_images(self) -> Sequence[Optional[np.ndarray]]:
        frames = self.vector_env.render()
        return [None] * self.num_envs if frames is None else list(frames)


def unstacked_step(vector_env: VectorEnv, actions: np.ndarray) -> tuple:
    """A gymnasium vector env's step (same_step autoreset) as `step_each` gives it:
    (observations, rewards, terminated, truncated, infos, finals), each env's info and
    final (observation, info) taken back out of the stacked infos."""
    observations, rewards, terminated, truncated, infos = vector_env.step(actions)
    num_envs = vector_env.num_envs
    each = env_infos({k: v for k, v in infos.items() if k not in FINAL_KEYS}, num_envs)
    finals: list = [None] * num_envs
    if "final_info" in infos:
        final_infos = env_infos(infos["final_info"], num_envs)
        for i in np.flatnonzero(infos["_final_info"]):
            finals[i] = (infos["final_obs"][i], final_infos[i])
    return observations, rewards, terminated, truncated, each, finals


FINAL_KEYS = ("final_obs", "_final_obs", "final_info", "_final_info")
"""Keys of gymnasium's stacked step infos that carry ended episodes (same_step autoreset)."""


def env_infos(infos: dict, num_envs: int) -> list[dict]:
    """Each env's info dict out of gymnasium's stacked vector infos (`key` with its mask
    `_key`; nested dicts likewise): env i gets the keys its mask sets, in their order."""
    each: list[dict] = [{} for _ in range(num_envs)]
    for key, values in infos.items():
        if key.startswith("_") and key[1:] in infos:
            continue
        mask = infos.get(f"_{key}")
        per_env = env_infos(values, num_envs) if isinstance(values, dict) else values
        for i in range(num_envs):
            if mask is None or mask[i]:
                each[i][key] = per_env[i]
    return each
