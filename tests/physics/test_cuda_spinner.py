"""The CUDA backend (spreadgym.device, physics.compiled.cuda_spinner; the envs' `device` in
tests/envs/test_env_device.py) under numba's CUDA simulator (the `cuda_simulator` fixture):
the kernel's granule index, design index, copies in and out, against the CPU kernel on
small batches; and the one-line errors where no GPU is found."""

import json

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


def test_the_cuda_kernel_gives_the_cpu_results_in_one_launch_per_batch(cuda_simulator):
    """Outcome counts equal, tray masses within 1e-12 relative (the simulator runs the CPU's
    scalar code, so here they are equal to the bit; a real GPU may differ in the last bits
    where it fuses multiply-adds); one launch for the whole batch at two threads."""
    found = cuda_simulator(SIMULATED)
    for row in found["rows"]:
        assert row["outcomes"][0] == row["outcomes"][1]
        assert row["tray_rel"] <= 1e-12
        assert row["departures_equal"]
    assert found["launches"] == [24 * 4]  # every scene's granules (twin-field's second disc is its first mirrored)


QUEUED = """
import json, threading, numpy as np
from spreadgym.config.materials import load_library
from spreadgym.config.scene import load_scene
from spreadgym.physics.compiled import cuda_spinner, granule_run
from spreadgym.physics.compiled.model import kernel_arrays, kernel_inputs, longest_first
from spreadgym.spread.pipeline import plan_scene

library = load_library()
runs = [run for seed, name in enumerate(["paper", "field"])
        for run in plan_scene(load_scene(name, {"sim.granules": 20, "sim.seed": seed}), "auto", library).spinner_runs()]
arrays, counts = kernel_arrays([kernel_inputs(*run) for run in runs])
n = int(counts.sum())
cpu_out, cpu_outcome = np.zeros((n, granule_run.OUT_SIZE)), np.zeros(n, dtype=np.int8)
granule_run.run_all(*arrays, cpu_out, cpu_outcome, np.empty((0, 1, 3)))
order = longest_first(arrays[0], arrays[2], arrays[5])
granule_of = {float(x): i for i, x in enumerate(arrays[0][:, 0])}  # a granule by its start's x
taken = []  # (thread, granule) in the order the kernel ran them
follow = cuda_spinner.granule_run.follow
def counted(*args):
    me = threading.current_thread()  # the simulator's thread of the kernel: its block and thread index
    taken.append((me.blockIdx.x * cuda_spinner.THREADS_PER_BLOCK + me.threadIdx.x, granule_of[float(args[0])]))
    return follow(*args)
cuda_spinner.granule_run.follow = counted
found = {"granules": n, "distinct_starts": len(granule_of), "longest_first": order.tolist()}
for name, block, kwargs in (("queue, longest first", 4, {"threads": 7}),
                            ("queue, launch order", 4, {"threads": 7, "order": np.arange(n)}),
                            ("queue, one thread", 1, {"threads": 1}),
                            ("one per thread", 4, {"queue": False, "order": np.arange(n)[::-1].copy()})):
    cuda_spinner.THREADS_PER_BLOCK = block
    taken.clear()
    out, outcome = np.full((n, granule_run.OUT_SIZE), np.nan), np.full(n, -1, dtype=np.int8)
    cuda_spinner.run_all(*arrays, out, outcome, **kwargs)
    found[name] = {"bits_equal": bool(np.array_equal(out, cpu_out) and np.array_equal(outcome, cpu_outcome)),
                   "taken": taken.copy()}
print(json.dumps(found))
"""


def test_the_queue_gives_every_granule_its_cpu_bits_in_any_order(cuda_simulator):
    """40 granules on the simulated GPU: the queue's 8 threads (2 blocks of 4, asked for 7)
    take them until none is left, one thread alone takes them all in the queue's order
    (longest first by default), and without the queue thread t takes order[t] alone; every
    granule runs once and the departures and outcomes are the CPU kernel's bits each time."""
    found = cuda_simulator(QUEUED)
    n = found["granules"]
    assert n == 40 == found["distinct_starts"]
    for name in ("queue, longest first", "queue, launch order", "queue, one thread", "one per thread"):
        assert found[name]["bits_equal"], name
        assert sorted(g for _, g in found[name]["taken"]) == list(range(n)), name  # each granule once
    for name in ("queue, longest first", "queue, launch order"):  # which of them run how many: the simulator's
        assert {t for t, _ in found[name]["taken"]} <= set(range(8)), name  # thread switches decide
    assert [g for _, g in found["queue, one thread"]["taken"]] == found["longest_first"]
    assert found["longest_first"] != list(range(n))  # the default order is not launch order here
    assert sorted(found["one per thread"]["taken"]) == [[t, n - 1 - t] for t in range(n)]


@pytest.mark.skipif(device.cuda_available(), reason="a CUDA GPU is present: the no-GPU errors do not apply")
def test_cuda_without_a_gpu_is_a_one_line_error(capsys, monkeypatch):
    monkeypatch.delenv(device.ENV_VAR, raising=False)
    assert main(["simulate", "--device", "cuda", "--set", "sim.granules=16"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--device" in err and "no CUDA GPU" in err
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


COMPARED = """
import json, os, sys
from spreadgym.cli.main import main
for device, workers in (("cpu", "1"), ("cuda", "2")):
    main(["compare", "--device", device, "--workers", workers, "--budget", "2", "--methods", "random", "centre",
          "--granules", "24", "--fertilizers", "pellet", "--swaths", "2.9", "--force",
          "--out", sys.argv[1] + "/" + device])
print(json.dumps({"parent": os.getpid()}))
"""


def test_compare_workers_share_the_simulated_gpu_with_the_cpu_scores(cuda_simulator, gpu_launch_log, tmp_path):
    """--device cuda with two worker processes scores as one process on the CPU (the same
    CV, reward and swath for every method), the searches' spinners launched on the GPU in
    the workers (logged there)."""
    env, launches = gpu_launch_log
    found = cuda_simulator(COMPARED, args=(str(tmp_path),), env=env)
    tables = [json.loads((tmp_path / device / "compare.json").read_text())["table"] for device in ("cpu", "cuda")]
    keys = ("method", "cv_percent", "reward", "effective_swath_m", "simulations")
    cpu, gpu = ([{k: row[k] for k in keys} for row in table] for table in tables)
    assert cpu == gpu and len(cpu) == 2
    launched = launches()
    assert launched.get("spinner") and found["parent"] not in launched["spinner"], launched
