"""A gymnasium vector env seen by stable-baselines3 as one of its `VecEnv`s.

SB3 steps n envs through its own vector classes (`DummyVecEnv`, `SubprocVecEnv`: one
`gym.make` per process) and has no adapter for gymnasium's `VectorEnv`. The SpinnerDesign
tasks have a batched vector env (`gym.make_vec`: every sub-env's tray test in one batch,
in `workers` processes, on the CPU's threads or the GPU: envs/vector.py), so `train` wraps
it in `BatchedVecEnv` to step its n envs as one batch.

The conventions are SubprocVecEnv's, so a training run sees what it would see there:
the env seeded at `reset` with the seeds `seed()` set (seed + i for env i, as gymnasium's
vector envs seed an int), a sub-env that ends an episode reset in the same step with its
last observation in `info["terminal_observation"]` and `info["TimeLimit.truncated"]` set
(truncated and not terminated), the reset's info in `reset_infos`, rewards as float64.
Each env's info is a dict of its own, taken back out of gymnasium's stacked infos (a
key only where gymnasium's mask says the env gave it). The attributes are the vector
env's (one for all n envs); the sub-envs themselves live in the vector env (or its worker
processes), so `env_method` and `set_attr` reach none of them and say so.
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
        self._actions: Optional[np.ndarray] = None
        super().__init__(vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space)

    def reset(self) -> VecEnvObs:
        """Reset every env with the seeds and options `seed()` and `set_options()` gave
        (used once, as SB3's vector envs use them)."""
        options = self._options[0]
        if any(o != options for o in self._options):
            raise ValueError("BatchedVecEnv resets every env with the same options; got different ones per env")
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
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
        observations, rewards, terminated, truncated, infos = self.vector_env.step(actions)
        dones = terminated | truncated
        each = env_infos(infos, self.num_envs)
        finals = env_infos(infos["final_info"], self.num_envs) if dones.any() else []
        step_infos = []
        for i, info in enumerate(each):
            if dones[i]:  # gymnasium's info of a reset env is the reset's; the step's is final_info
                self.reset_infos[i] = info
                info = finals[i]
            info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            if dones[i]:
                info["terminal_observation"] = infos["final_obs"][i]
            step_infos.append(info)
        return observations, np.asarray(rewards, dtype=np.float64), dones, step_infos

    def close(self) -> None:
        self.vector_env.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute, once per env of `indices` (the sub-envs share it)."""
        return [getattr(self.vector_env, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"BatchedVecEnv cannot set {attr_name!r} on its sub-envs (they live in the batched "
                             "vector env); train with vec_env: subproc to reach each env")

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        raise AttributeError(f"BatchedVecEnv cannot call {method_name!r} on its sub-envs (they live in the batched "
                             "vector env); train with vec_env: subproc to reach each env")

    def env_is_wrapped(self, wrapper_class, indices: VecEnvIndices = None) -> list[bool]:
        """No sub-env is wrapped (a `VecMonitor` over this env keeps the episode records)."""
        return [False] * len(self._indices(indices))

    def get_images(self) -> Sequence[Optional[np.ndarray]]:
        frames = self.vector_env.render()
        return [None] * self.num_envs if frames is None else list(frames)

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)


def env_infos(infos: dict, num_envs: int) -> list[dict]:
    """Each env's info dict out of gymnasium's stacked vector infos (`key` with its mask
    `_key`; nested dicts likewise): env i gets the keys its mask sets, in their order."""
    each: list[dict] = [{} for _ in range(num_envs)]
    for key, values in infos.items():
        if key.startswith("_") and key[1:] in infos:
            continue
        mask = infos.get(f"_{key}")
        if isinstance(values, dict):
            nested = env_infos(values, num_envs)
            for i in range(num_envs):
                if mask is None or mask[i]:
                    each[i][key] = nested[i]
            continue
        for i in range(num_envs):
            if mask is None or mask[i]:
                each[i][key] = values[i]
    return each
