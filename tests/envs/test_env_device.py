"""The envs' `device` keyword (spreadgym.device): a simulated GPU steps as the CPU does, and
a GPU asked for where there is none fails at make, in one line."""

import gymnasium as gym
import pytest

import spreadgym  # noqa: F401  (registers the ids)
from spreadgym import device
from spreadgym.errors import ConfigError


def test_an_env_on_the_simulated_gpu_steps_as_on_the_cpu(cuda_simulator):
    found = cuda_simulator(
        "import json, gymnasium as gym, spreadgym\n"
        "out = []\n"
        "for dev in ('cpu', 'cuda'):\n"
        "    env = gym.make('spreadgym/SpinnerDesign-v0', granules=32, device=dev)\n"
        "    env.reset(seed=3)\n"
        "    out.append(env.step(env.action_space.sample() * 0)[1])\n"
        "print(json.dumps({'rewards': out}))\n")
    assert found["rewards"][0] == found["rewards"][1]


@pytest.mark.skipif(device.cuda_available(), reason="a CUDA GPU is present: the no-GPU error does not apply")
def test_an_env_on_a_missing_gpu_fails_at_make_in_one_line():
    with pytest.raises(ConfigError, match="device: cuda: no CUDA GPU") as error:
        gym.make("spreadgym/SpinnerDesign-v0", device="cuda")
    assert "\n" not in str(error.value)


def test_workers_share_the_simulated_gpu_with_the_cpu_rewards(cuda_simulator, gpu_launch_log):
    """The vector env's worker processes may share a GPU: two workers on the simulated GPU
    step as one process on the CPU (rewards and observations bit for bit), and each worker
    launches its own block's spinner on the GPU (logged in the workers)."""
    env, launches = gpu_launch_log
    found = cuda_simulator(
        "import json, os, numpy as np, gymnasium as gym, spreadgym\n"
        "out = {'parent': os.getpid()}\n"
        "for dev, workers in (('cpu', 1), ('cuda', 2)):\n"
        "    venv = gym.make_vec('spreadgym/SpinnerDesign-v1', num_envs=3, workers=workers, granules=24, device=dev,\n"
        "                        autoreset_mode='same_step')\n"
        "    venv.reset(seed=11)\n"
        "    venv.action_space.seed(5)\n"
        "    obs, reward, *_ = venv.step(venv.action_space.sample())\n"
        "    out[dev] = {'obs': obs.tolist(), 'reward': reward.tolist()}\n"
        "    venv.close()\n"
        "print(json.dumps(out))\n", env=env)
    assert found["cuda"] == found["cpu"]
    assert len(set(found["cpu"]["reward"])) == 3  # three designs, three rewards: not a constant
    launched = launches()
    assert len(launched.get("spinner", set())) == 2 and found["parent"] not in launched["spinner"], launched
