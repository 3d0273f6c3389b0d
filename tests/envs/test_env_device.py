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


def test_workers_with_a_gpu_are_refused_in_one_line(cuda_simulator):
    """One process drives the GPU: the vector env's worker processes are for the CPU."""
    found = cuda_simulator(
        "import json, gymnasium as gym, spreadgym\n"
        "from spreadgym.errors import ConfigError\n"
        "try:\n"
        "    gym.make_vec('spreadgym/SpinnerDesign-v1', num_envs=2, workers=2, granules=32, device='cuda')\n"
        "    print(json.dumps({'error': None}))\n"
        "except ConfigError as error:\n"
        "    print(json.dumps({'error': str(error)}))\n")
    assert found["error"] == "workers: one process drives the GPU: use workers=1 with device='cuda'"
