"""spreadgym.heap: glibc's malloc thresholds raised once per process, and left alone where
the user set malloc. Each allocator check runs in a fresh interpreter (a clean heap)."""

import os
import subprocess
import sys

import pytest

from spreadgym import heap

pytestmark = pytest.mark.skipif(not heap.is_glibc(), reason="the thresholds are glibc's")

# A pattern the default thresholds serve with fresh pages every time: an 8 MiB array (mmapped; its
# free raises glibc's thresholds to about 8 and 16 MiB), then 20 MiB in 4 MiB arrays from the heap,
# whose free leaves more than 16 MiB at the heap's top, so glibc returns it to the kernel.
CYCLES = """
import resource, sys
import numpy as np
from spreadgym import heap
print(heap.tune() if sys.argv[1] == "tune" else None)
faults = []
for _ in range(8):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    big = np.ones(2**20)
    del big
    parts = [np.ones(2**19) for _ in range(5)]
    del parts
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(sum(faults[1:]))
"""


def _run(mode: str, **env: str) -> tuple[str, int]:
    clean = {k: v for k, v in os.environ.items() if k not in heap.USER_SETTINGS and k != "GLIBC_TUNABLES"}
    out = subprocess.run([sys.executable, "-c", CYCLES, mode], capture_output=True, text=True, check=True,
                         env={**clean, **env}).stdout.split()
    return out[0], int(out[1])


def test_tuned_heap_keeps_freed_arrays_where_the_default_faults_them_in_again():
    tuned, tuned_faults = _run("tune")
    default, default_faults = _run("leave")
    assert (tuned, default) == ("True", "None")
    assert default_faults > 7 * 1500  # ~2000 pages (8 MiB) faulted in again per cycle
    assert tuned_faults < 100


@pytest.mark.parametrize("name, value", [("MALLOC_MMAP_THRESHOLD_", "131072"), ("MALLOC_TRIM_THRESHOLD_", "0"),
                                         ("MALLOC_TOP_PAD_", "0"),
                                         ("GLIBC_TUNABLES", "glibc.malloc.mmap_threshold=131072")])
def test_a_user_who_set_malloc_keeps_their_settings(name, value):
    tuned, faults = _run("tune", **{name: value})
    assert tuned == "False"


def test_tune_decides_once_and_is_cheap_after(monkeypatch):
    first = heap.tune()
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "131072")  # too late: the process already decided
    assert heap.tune() is first


@pytest.mark.parametrize("call", ["run_scene(scene, ci=False)", "run_batch([scene], ci=False)"])
def test_a_simulation_tunes_the_heap(call):
    code = ("from spreadgym import heap\nfrom spreadgym.config.scene import load_scene, scene_with\n"
            "from spreadgym.spread.batch import run_batch\nfrom spreadgym.spread.pipeline import run_scene\n"
            "scene = scene_with(load_scene('paper'), {'sim.granules': 64, 'sim.replicates': 4})\n"
            f"before = heap._tuned\n{call}\nprint(before, heap._tuned)")
    clean = {k: v for k, v in os.environ.items() if k not in heap.USER_SETTINGS and k != "GLIBC_TUNABLES"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=clean)
    assert out.stdout.split() == ["None", "True"]


@pytest.mark.parametrize("answer", [None, ValueError("unknown name"), AttributeError("no confstr")])
def test_other_c_libraries_are_left_alone(monkeypatch, answer):
    def confstr(name):
        if isinstance(answer, Exception):
            raise answer
        return answer
    monkeypatch.setattr(heap.os, "confstr", confstr)
    assert not heap.is_glibc() and not heap._ours_to_set()
