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
        granules = sample_granules(scene, library.fertilizer(scene.fertilizer))
        return granules, resolve_contacts(scene, library)

    return _prepare
