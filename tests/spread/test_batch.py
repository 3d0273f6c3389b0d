"""The batch evaluation: bit for bit the serial runs, at every batch size and thread count,
with the single evaluation's errors; and the thread policy (spreadgym.threads)."""

import json
import math
import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from spreadgym import threads
from spreadgym.config.scene import load_scene, scene_with
from spreadgym.errors import ConfigError, SpreadgymError
from spreadgym.spread.batch import run_batch
from spreadgym.spread.pipeline import run_scene

FIELDS = ("replicate_masses_kg", "landed")


def _same(a, b):
    """Every array and metric of two results equal, bit for bit (wall time aside)."""
    for name in FIELDS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.trays.mass_kg, b.trays.mass_kg)
    assert np.array_equal(a.landing.position_m, b.landing.position_m)
    for name in ("position_m", "velocity_m_s", "spin_rad_s", "time_s", "outcome"):
        assert np.array_equal(getattr(a.departure, name), getattr(b.departure, name)), name
        assert np.array_equal(getattr(a.launch, name), getattr(b.launch, name)), name
    assert np.array_equal(a.sample.x_m, b.sample.x_m) and np.array_equal(a.sample.mass_kg, b.sample.mass_kg)
    ja, jb = a.metrics.to_json(), b.metrics.to_json()
    ja.pop("wall_s"), jb.pop("wall_s")
    assert json.dumps(ja, default=np.ndarray.tolist) == json.dumps(jb, default=np.ndarray.tolist)  # floats exact


def _mixed(granules=512):
    """Scenes sharing bases, with settings, seeds and fertilizers that differ; plates and two discs among them."""
    scenes = []
    for i, name in enumerate(["paper", "field", "twin-field", "paper-deflectors"] * 2):
        overrides = {"sim.granules": granules, "sim.seed": 11 * i + 3, "spinner.rpm": 400 + 60 * i}
        if i >= 4:
            overrides["vanes.pitch_deg"] = -10.0 + 5 * i
        if name == "paper" and i >= 4:
            overrides["fertilizer"] = "pellet"
        scenes.append(load_scene(name, overrides))
    return scenes


@pytest.mark.parametrize("count", [1, 2])
def test_a_batch_equals_its_serial_runs_bit_for_bit(library, monkeypatch, count):
    monkeypatch.setenv(threads.ENV_VAR, str(count))
    scenes = _mixed()
    batch = run_batch(scenes, library=library)
    for scene, result in zip(scenes, batch):
        _same(result, run_scene(scene, library=library))


@pytest.mark.parametrize("size", [1, 2, 63, 64, 1000])
def test_every_batch_size_gives_the_serial_results(library, size):
    base = load_scene("paper", {"sim.granules": 32, "sim.replicates": 2, "sim.angle_copies": 2})
    scenes = [scene_with(base, {"sim.seed": i, "spinner.rpm": 300 + (i % 97) * 8}) for i in range(size)]
    batch = run_batch(scenes, library=library)
    assert len(batch) == size
    for i in sorted({0, size // 2, size - 1}):  # a few; the rest share every code path
        _same(batch[i], run_scene(scenes[i], library=library))
    if size <= 64:
        for scene, result in zip(scenes, batch):
            assert np.array_equal(result.replicate_masses_kg, run_scene(scene, library=library).replicate_masses_kg)


def test_an_empty_batch_and_bad_entries(library):
    assert run_batch([], library=library) == []
    with pytest.raises(ConfigError, match=r"scenes\[1\]"):
        run_batch([load_scene("paper"), {"spinner": {"rpm": 500}}], library=library)


def test_bad_settings_and_models_fail_as_in_a_single_run(library):
    base = load_scene("paper")
    with pytest.raises(SpreadgymError) as single:
        run_scene(scene_with(base, {"spinner.rpm": math.nan}), library=library)
    with pytest.raises(SpreadgymError) as batch:
        run_batch([base, scene_with(base, {"spinner.rpm": math.nan})], library=library)
    assert str(batch.value) == str(single.value) and "\n" not in str(single.value)
    with pytest.raises(SpreadgymError) as single:
        run_scene(base, model="nope", library=library)
    with pytest.raises(SpreadgymError) as batch:
        run_batch([base, base], model="nope", library=library)
    assert str(batch.value) == str(single.value)


def test_the_thread_count_follows_the_flag_then_the_variable_then_the_cores(monkeypatch):
    monkeypatch.delenv(threads.ENV_VAR, raising=False)
    assert threads.thread_count() == len(os.sched_getaffinity(0))
    monkeypatch.setenv(threads.ENV_VAR, "1")
    assert threads.thread_count() == 1
    threads.set_threads(2)
    try:
        assert threads.thread_count() == 2
        with threads.numba_threads() as count:
            assert count == min(2, numba.config.NUMBA_NUM_THREADS) == numba.get_num_threads()
    finally:
        threads.set_threads(None)
    assert threads.thread_count() == 1
    with threads.numba_threads() as count:
        assert count == 1 == numba.get_num_threads()


def test_a_forked_child_runs_after_its_parent_ran_the_parallel_kernel(library):
    scene = load_scene("paper", {"sim.granules": 64})
    parent = run_scene(scene, library=library).replicate_masses_kg
    pid = os.fork()
    if pid == 0:  # the child: exit 0 only if it runs and gets the parent's bits
        code = 1
        try:
            code = 0 if np.array_equal(run_scene(scene, library=library).replicate_masses_kg, parent) else 2
        finally:
            os._exit(code)
    assert os.waitpid(pid, 0)[1] == 0


@pytest.mark.skipif(threads.tbb_library() is None,
                    reason="pip's tbb is not installed (not Linux x86-64): numba takes its workqueue")
def test_where_pip_installed_tbb_the_kernels_run_on_numba_s_tbb_layer():
    """pip's tbb puts its library where the loader does not look; spreadgym.threads loads
    it, so a fresh process's first kernel launch takes oneTBB, not the workqueue."""
    code = ("import numba; from spreadgym.config.scene import load_scene; "
            "from spreadgym.spread.pipeline import run_scene; "
            "run_scene(load_scene('paper', {'sim.granules': 64})); print(numba.threading_layer())")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_THREADING_LAYER", "LD_LIBRARY_PATH")}
    found = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert found.stdout.split()[-1] == "tbb"


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5", " "])
def test_a_bad_thread_count_is_a_one_line_error(monkeypatch, value):
    monkeypatch.setenv(threads.ENV_VAR, value)
    if not value.strip():
        assert threads.thread_count() >= 1  # empty: unset
        return
    with pytest.raises(ConfigError, match=threads.ENV_VAR):
        threads.thread_count()
    with pytest.raises(ConfigError, match="--threads"):
        threads.set_threads(value)


def test_inside_a_ray_task_the_count_is_the_task_cpus(monkeypatch):
    """A Ray worker's numba threads never multiply with its neighbours': the task's CPUs."""
    import sys
    import types

    class Context:
        def __init__(self, cpus):
            self.cpus = cpus

        def get_assigned_resources(self):
            return {"CPU": self.cpus} if self.cpus else {}

    fake = types.SimpleNamespace(is_initialized=lambda: True, get_runtime_context=lambda: Context(3.0))
    monkeypatch.setitem(sys.modules, "ray", fake)
    monkeypatch.delenv(threads.ENV_VAR, raising=False)
    assert threads.thread_count() == 3
    fake.get_runtime_context = lambda: Context(0.5)  # a fractional share still gets one thread
    assert threads.thread_count() == 1
    fake.get_runtime_context = lambda: Context(None)  # the driver: not a task
    assert threads.thread_count() == len(os.sched_getaffinity(0))
    monkeypatch.setenv(threads.ENV_VAR, "2")  # the variable wins over Ray
    fake.get_runtime_context = lambda: Context(3.0)
    assert threads.thread_count() == 2
