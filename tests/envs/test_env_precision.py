"""The envs' `precision` option: a fixed budget per step by default, runs pooled to a
standard error when asked (single and native vector env alike)."""

import gymnasium as gym
import numpy as np
import pytest

import spreadgym  # noqa: F401  (registers the ids)
from spreadgym.errors import ConfigError

SMALL = {"granules": 512}


def step_once(env, seed: int):
    env.reset(seed=seed)
    action = np.full(env.action_space.shape, 0.2, dtype=np.float32)
    return env.step(action)


def test_default_is_one_run_per_step_and_precision_pools_runs_to_it():
    fixed = step_once(gym.make("spreadgym/SpinnerDesign-v0", **SMALL), 3)[4]["metrics"]
    precise = step_once(gym.make("spreadgym/SpinnerDesign-v0", precision=0.4, **SMALL), 3)[4]["metrics"]
    assert fixed["granules"] == precise["granules"] == 512
    assert precise["cv_standard_error_percent"] <= 0.4 < fixed["cv_standard_error_percent"]


def test_vector_env_with_precision_gives_the_single_envs_rewards():
    kwargs = {"precision": 0.6, **SMALL}
    vec = gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    vec.reset(seed=11)  # sub-env i is seeded 11 + i
    actions = np.array([[0.2, -0.3], [-0.5, 0.4]], dtype=np.float32)[:, :vec.single_action_space.shape[0]]
    _, rewards, *_ = vec.step(actions)
    for i, seed in enumerate((11, 12)):
        env = gym.make("spreadgym/SpinnerDesign-v0", **kwargs)
        env.reset(seed=seed)
        assert env.step(actions[i])[1] == rewards[i]


@pytest.mark.parametrize("bad", [0, -1.0, "0.2", float("nan")])
def test_bad_precision_is_a_config_error_naming_it(bad):
    with pytest.raises(ConfigError, match="precision"):
        gym.make("spreadgym/SpinnerDesign-v0", precision=bad)
