"""The environments under vector envs: gymnasium's async vector env and SB3's SubprocVecEnv."""

import functools

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import SubprocVecEnv

import spreadgym  # noqa: F401  (registers the envs)
from spreadgym.envs.common.config import DESIGN, load_env_config
from spreadgym.physics.selection import MODELS

IDS = ["spreadgym/SpinnerDesign-v0", "spreadgym/SpreaderTuning-v0"]
_DEFAULT = load_env_config(DESIGN).model
SMALL = {"model": _DEFAULT if _DEFAULT in MODELS else "pymunk", "granules": 32}


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_async_vector_rollout(env_id):
    envs = gym.make_vec(env_id, num_envs=2, vectorization_mode="async", **SMALL)
    try:
        obs, infos = envs.reset(seed=[1, 2])
        assert obs.shape == (2,) + envs.single_observation_space.shape and obs.dtype == np.float32
        envs.action_space.seed(0)
        for step in range(3):
            obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
            assert obs.shape[0] == 2 and np.all(np.isfinite(rewards))
            assert terminated.dtype == bool and truncated.dtype == bool
            assert np.all(obs >= -1) and np.all(obs <= 1)
            if step == 0:  # later steps may be autoresets (SpinnerDesign ends every episode)
                assert infos["_metrics"].all() and len(infos["metrics"]["trays"]["mass_kg"]) == 2
    except BaseException:
        envs.close(terminate=True)  # a failed call must not leave close() waiting for it
        raise
    envs.close()


# SubprocVecEnv starts fresh interpreters (forkserver/spawn): the "spreadgym:" form of the
# id imports spreadgym there, which registers both envs (one shows it: each pair of fresh
# workers costs ~25 s here; test_rl_tools runs SpreaderTuning's namespaced id the same way).
def test_sb3_subproc_vector_rollout():
    envs = SubprocVecEnv([functools.partial(gym.make, "spreadgym:SpinnerDesign-v0", **SMALL) for _ in range(2)])
    try:
        envs.seed(7)
        obs = envs.reset()
        assert obs.shape == (2,) + envs.observation_space.shape
        for _ in range(3):
            actions = np.stack([envs.action_space.sample() for _ in range(2)])
            obs, rewards, dones, infos = envs.step(actions)
            assert obs.shape[0] == 2 and np.all(np.isfinite(rewards)) and len(infos) == 2
    finally:
        envs.close()


def test_async_vector_env_is_reproducible():
    def rollout():
        envs = gym.make_vec(IDS[0], num_envs=2, vectorization_mode="async", **SMALL)
        try:
            envs.reset(seed=[3, 4])
            out = envs.step(np.array([[0.5, -0.5], [-0.5, 0.5]], dtype=np.float32))
        except BaseException:
            envs.close(terminate=True)
            raise
        envs.close()
        return out[0], out[1]

    first, second = rollout(), rollout()
    assert np.array_equal(first[0], second[0]) and np.array_equal(first[1], second[1])


def test_native_vector_env_runs_64_designs_as_one_batch_with_the_single_envs_bits():
    """SpinnerDesign's native vector env evaluates a step's designs together (spreadgym.spread.batch):
    rewards and metrics equal the single envs', bit for bit, at 64 sub-envs."""
    n, seed = 64, 5
    venv = gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=n, autoreset_mode="same_step", **SMALL)
    venv.reset(seed=seed)
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (n, venv.single_action_space.shape[0])).astype(np.float32)
    _, rewards, _, _, infos = venv.step(actions)
    for i in range(n):
        env = gym.make("spreadgym/SpinnerDesign-v0", **SMALL)
        env.reset(seed=seed + i)
        _, reward, _, _, info = env.step(actions[i])
        assert rewards[i] == reward
        assert infos["final_info"]["metrics"]["cv_percent_at_target"][i] == info["metrics"]["cv_percent_at_target"]
    venv.close()


def test_native_vector_env_refuses_a_nan_action_as_the_single_env_does():
    venv = gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=2, **SMALL)
    env = gym.make("spreadgym/SpinnerDesign-v0", **SMALL)
    venv.reset(seed=0), env.reset(seed=0)
    bad = np.full(venv.single_action_space.shape, np.nan, dtype=np.float32)
    with pytest.raises(Exception) as single:
        env.step(bad)
    with pytest.raises(Exception) as batch:
        venv.step(np.stack([np.zeros_like(bad), bad]))
    assert type(batch.value) is type(single.value) and str(batch.value) == str(single.value)
    assert "\n" not in str(single.value)
    _, rewards, *_ = venv.step(np.zeros((2,) + bad.shape, dtype=np.float32))  # still steps afterwards
    assert np.all(np.isfinite(rewards))
    venv.close()


def test_step_designs_equals_reset_and_step_one_after_another():
    """The searches' batches (agents.baselines) go through `step_designs`: the same returns as
    each reset and step in turn, and one simulation counted per step."""
    from spreadgym.agents.evaluation import SimulationCounter
    from spreadgym.envs.vector import step_designs

    env = SimulationCounter(gym.make("spreadgym/SpinnerDesign-v0", **SMALL))
    actions = list(np.random.default_rng(1).uniform(-1.0, 1.0, (5, env.action_space.shape[0])))
    resets = [(100 + i, None) for i in range(5)]
    batch = step_designs(env, resets, actions)
    assert env.simulations == 5
    for (seed, options), action, (obs, reward, terminated, truncated, info) in zip(resets, actions, batch):
        env.reset(seed=seed, options=options)
        o, r, te, tr, i = env.step(action)
        np.testing.assert_array_equal(obs, o, strict=True)
        assert reward == r and (terminated, truncated) == (te, tr)
        assert info["metrics"] == i["metrics"]
    assert "run" not in env.unwrapped.task.__dict__  # the task runs its own scenes again


def test_step_designs_with_a_precision_steps_each_job_itself():
    from spreadgym.envs.vector import step_designs

    env = gym.make("spreadgym/SpinnerDesign-v0", precision=5.0, **SMALL)
    action = np.zeros(env.action_space.shape)
    (_, reward, *_), = step_designs(env, [(7, None)], [action])
    env.reset(seed=7)
    assert env.step(action)[1] == reward
