"""The compiled spinner built with FMA contraction allowed (what a CUDA build does by default):
the same outcomes as the default build on the reference scenes, and no granule at the loop cap.

Contraction changes the last bits of a path, so positions differ by ~1e-12 m; the outcome
of every granule must not, and the stall guard must not depend on a time step being
exactly zero. The contracted kernels are compiled in a fresh process whose `numba.njit`
adds fastmath={"contract"} (and no disk cache) to every kernel."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spreadgym.config.materials import load_library
from spreadgym.config.scene import scene_with
from spreadgym.physics.compiled import granule_run
from spreadgym.physics.compiled.model import kernel_inputs, run_kernel
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.granules import sample_granules
from spreadgym.spread import discs
from spreadgym.studies.references import reference_family

SEEDS = range(4)

CONTRACTED = """
import sys
import numba
import numpy as np

plain = numba.njit


def contracted(*args, **options):
    options.update(cache=False, fastmath={"contract"})
    return plain(*args, **options)


numba.njit = contracted
sys.path.insert(0, sys.argv[2])
from test_compiled_contracted import outcomes_and_loops  # noqa: E402

np.savez(sys.argv[1], **outcomes_and_loops())
"""


def outcomes_and_loops() -> dict:
    """Per reference scene and seed (first disc; plus paper at 600 rpm): outcome codes, loop passes."""
    library = load_library()
    family = reference_family()
    family["paper-rpm600"] = scene_with(family["paper"], {"spinner.rpm": 600})
    found = {}
    for name, scene in family.items():
        for seed in SEEDS:
            disc = discs.discs(scene_with(scene, {"sim.seed": seed}))[0].scene
            granules = sample_granules(disc, library.fertilizer(disc.fertilizer), disc.sim.replicates, 0)
            out, outcome, _ = run_kernel(kernel_inputs(disc, granules, resolve_contacts(disc, library)))
            found[f"{name}|{seed}|outcome"] = outcome
            found[f"{name}|{seed}|loops"] = out[:, granule_run.LOOPS]
    return found


@pytest.mark.slow
def test_the_contracted_build_gives_the_same_outcomes_and_never_reaches_the_loop_cap(tmp_path):
    path = tmp_path / "contracted.npz"
    here = str(Path(__file__).parent)
    subprocess.run([sys.executable, "-c", CONTRACTED, str(path), here], check=True, timeout=600)
    contracted = np.load(path)
    default = outcomes_and_loops()
    assert set(contracted.files) == set(default)
    for key, value in default.items():
        if key.endswith("|outcome"):
            assert np.array_equal(contracted[key], value), key
        else:
            assert contracted[key].max() < granule_run.MAX_LOOPS, key
            assert value.max() < granule_run.MAX_LOOPS, key
