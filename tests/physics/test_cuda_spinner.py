"""The CUDA backend (spreadgym.device, physics.compiled.cuda_spinner) under numba's CUDA
simulator (NUMBA_ENABLE_CUDASIM=1, in a fresh interpreter: the flag is read when numba's
CUDA target loads): the kernel's granule index, design index, copies in and out, against
the CPU kernel on small batches; and the one-line errors where no GPU is found."""

import json
import os
import subprocess
import sys

import pytest

from spreadgym import device
from spreadgym.cli.main import main
from spreadgym.errors import ConfigError

SIMULATED = """
import json, numpy as np
from spreadgym import device, threads
from spreadgym.config.scene import load_scene
from spreadgym.physics.compiled import cuda_spinner
from spreadgym.spread.batch import run_batch

launches = []
launch = cuda_spinner.run_all
cuda_spinner.run_all = lambda *a: (launches.append(a[0].shape[0]), launch(*a))
scenes = [load_scene(name, {"sim.granules": 24, "sim.seed": seed, "sim.replicates": 2})
          for seed, name in enumerate(["paper", "twin-field", "paper-deflectors", "field"])]
threads.set_threads(2)
cpu = run_batch(scenes)
with device.using("cuda"):
    gpu = run_batch(scenes)
rows = []
for a, b in zip(cpu, gpu):
    mass = np.abs(a.trays.mass_kg - b.trays.mass_kg).max() / a.trays.mass_kg.max()
    rows.append({"outcomes": [a.metrics.outcomes, b.metrics.outcomes], "tray_rel": float(mass),
                 "cv": [a.metrics.cv_percent_at_target, b.metrics.cv_percent_at_target],
                 "departures_equal": bool(np.array_equal(a.departure.position_m, b.departure.position_m))})
print(json.dumps({"rows": rows, "launches": launches}))
"""


def simulated(script: str) -> dict:
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    env.pop(device.ENV_VAR, None)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=900, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_cuda_kernel_gives_the_cpu_results_in_one_launch_per_batch():
    """Outcome counts equal, tray masses within 1e-12 relative (the simulator runs the CPU's
    scalar code, so here they are equal to the bit; a real GPU may differ in the last bits
    where it fuses multiply-adds); one launch for the whole batch at two threads."""
    found = simulated(SIMULATED)
    for row in found["rows"]:
        assert row["outcomes"][0] == row["outcomes"][1]
        assert row["tray_rel"] <= 1e-12
        assert row["departures_equal"]
    assert found["launches"] == [24 * 4]  # every scene's granules (twin-field's second disc is its first mirrored)


def test_an_env_on_the_simulated_gpu_steps_as_on_the_cpu():
    found = simulated(
        "import json, gymnasium as gym, spreadgym\n"
        "out = []\n"
        "for dev in ('cpu', 'cuda'):\n"
        "    env = gym.make('spreadgym/SpinnerDesign-v0', granules=32, device=dev)\n"
        "    env.reset(seed=3)\n"
        "    out.append(env.step(env.action_space.sample() * 0)[1])\n"
        "print(json.dumps({'rewards': out}))\n")
    assert found["rewards"][0] == found["rewards"][1]


@pytest.mark.skipif(device.cuda_available(), reason="a CUDA GPU is present: the no-GPU errors do not apply")
def test_cuda_without_a_gpu_is_a_one_line_error(capsys, monkeypatch):
    monkeypatch.delenv(device.ENV_VAR, raising=False)
    assert main(["simulate", "--device", "cuda", "--set", "sim.granules=16"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--device" in err and "no CUDA GPU" in err
    with pytest.raises(ConfigError, match="device: cuda: no CUDA GPU"):
        import gymnasium as gym

        import spreadgym  # noqa: F401

        gym.make("spreadgym/SpinnerDesign-v0", device="cuda")
    monkeypatch.setenv(device.ENV_VAR, "cuda")
    with pytest.raises(ConfigError, match=device.ENV_VAR):
        device.current()


def test_the_device_names_and_their_order(monkeypatch):
    monkeypatch.delenv(device.ENV_VAR, raising=False)
    assert device.current() == "cpu"
    monkeypatch.setenv(device.ENV_VAR, "gpu")
    with pytest.raises(ConfigError, match="unknown device 'gpu'; allowed: cpu, cuda"):
        device.current()
    monkeypatch.setenv(device.ENV_VAR, "cpu")
    device.set_device("cpu")
    try:
        with device.using(None):
            assert device.current() == "cpu"
    finally:
        device.set_device(None)


def test_compare_drives_one_gpu_from_one_process(capsys, monkeypatch):
    """Workers and devices never multiply: with a GPU (faked here), --device cuda with two
    worker processes is refused."""
    monkeypatch.setattr(device, "cuda_available", lambda: True)
    code = main(["compare", "--device", "cuda", "--workers", "2", "--budget", "2", "--methods", "random"])
    assert code == 2 and "--workers 1" in capsys.readouterr().err
