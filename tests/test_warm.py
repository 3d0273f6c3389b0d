"""`python -m spreadgym.warm` (run by make after installing) leaves nothing for a user's
first simulation or env step to compile: in fresh processes, numba saves no kernel."""

import os
import subprocess
import sys

import pytest

STEPS = {
    "env step": "import gymnasium as gym, spreadgym\n"
                "for scene in ('paper', 'paper-deflectors', 'twin-field'):\n"
                "    env = gym.make('spreadgym/SpinnerDesign-v0', scene=scene, granules=256)\n"
                "    env.reset(seed=0); env.step(env.action_space.sample())\n",
    "vector env": "import gymnasium as gym, spreadgym\n"
                  "envs = gym.make_vec('spreadgym/SpinnerDesign-v0', num_envs=3,\n"
                  "                    vectorization_mode='vector_entry_point', granules=256)\n"
                  "envs.reset(seed=0); envs.step(envs.action_space.sample())\n",
    "simulate and reference": "from spreadgym.cli.main import main\n"
                              "main(['simulate', '--scene', 'paper', '--set', 'sim.granules=256', '--json'])\n"
                              "main(['reference', '--scene', 'paper', '--replicates', '4', '--granules', '128'])\n",
}


def compiled_in(script: str) -> list[str]:
    """The kernels numba compiled (and saved) while `script` ran in a fresh interpreter."""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=900,
                          env={**os.environ, "NUMBA_DEBUG_CACHE": "1"})
    assert done.returncode == 0, done.stderr[-2000:]
    return [line for line in (done.stdout + done.stderr).splitlines() if line.startswith("[cache] data saved")]


@pytest.fixture(scope="module")
def warmed():
    done = subprocess.run([sys.executable, "-m", "spreadgym.warm"], capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.mark.parametrize("what", list(STEPS))
def test_after_the_warm_up_a_first_step_compiles_nothing(warmed, what):
    assert compiled_in(STEPS[what]) == []
