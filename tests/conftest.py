"""Shared fixtures: the material library and small, fast scenes."""

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
    """A command run in a test (`--threads N`) sets the process's thread count: put it back."""
    yield
    from spreadgym.threads import set_threads

    set_threads(None)
