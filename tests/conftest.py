"""Shared fixtures: the material library, small fast scenes, numba's CUDA simulator."""

import json
import os
import subprocess
import sys

import pytest

from spreadgym.config.materials import load_library
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.granules import sample_granules


@pytest.fixture(scope="session")
def library():
    return load_library()


@pytest.fixture
def prepare(library):
    """(granules, contacts) for a scene, sampled with the scene's seed."""

    def _prepare(scene):
        granules = sample_granules(scene, library.fertilizer_of(scene))
        return granules, resolve_contacts(scene, library)

    return _prepare


@pytest.fixture(autouse=True)
def _default_thread_count():
    """A command run in a test (`--threads N`) sets the process's thread count (and device): put them back."""
    yield
    from spreadgym.device import set_device
    from spreadgym.threads import set_threads

    set_threads(None)
    set_device(None)


@pytest.fixture
def cuda_simulator():
    """Run a script in a fresh interpreter under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1,
    read when numba's CUDA target loads) and return the JSON it prints last."""

    def _run(script: str) -> dict:
        env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
        env.pop("SPREADGYM_DEVICE", None)
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=900, env=env)
        assert done.returncode == 0, done.stderr[-3000:]
        return json.loads(done.stdout.strip().splitlines()[-1])

    return _run
