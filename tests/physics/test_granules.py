"""The granule sampler: the batched scrambled Sobol points are scipy's, bit for bit."""

import warnings

import numpy as np
import pytest
from scipy.stats import qmc

from spreadgym.config.materials import load_library
from spreadgym.config.scene import load_scene, scene_with
from spreadgym.physics import granules


def scipy_uniforms(seed: int, replicate: int, count: int) -> np.ndarray:
    """The reference: one scipy engine per replicate, as the sampler was first written."""
    engine = qmc.Sobol(len(granules.INPUTS), scramble=True, seed=np.random.default_rng([seed, replicate]))
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*balance properties of Sobol' points.*")
        u = engine.random(count)
    return np.clip(u, 1e-12, 1.0 - 1e-12)


@pytest.mark.parametrize("count", [1, 2, 3, 100, 512, 4096])
def test_batched_sobol_points_equal_scipys_engine(count):
    for seed in (0, 7, 2**31 - 2):
        replicates = np.array([0, 1, 5, 255])
        got = granules.replicate_uniforms(seed, replicates, count)
        for row, r in zip(got, replicates):
            assert np.array_equal(row, scipy_uniforms(seed, int(r), count))


def test_sampled_granules_equal_those_of_one_engine_per_replicate():
    library = load_library()
    scene = scene_with(load_scene("paper"), {"sim.granules": 4096, "sim.seed": 3})
    batch = granules.sample_granules(scene, library.fertilizer(scene.fertilizer), replicates=8, first_replicate=2)
    u = np.vstack([scipy_uniforms(3, 2 + k, 512) for k in range(8)])
    assert np.array_equal(batch.phase_rad, 2.0 * np.pi * u[:, 0])
    assert np.array_equal(batch.replicate, np.repeat(np.arange(8), 512))
    again = granules.sample_granules(scene, library.fertilizer(scene.fertilizer), replicates=8, first_replicate=2)
    for name in ("diameter_m", "mass_kg", "release_xy_m", "phase_rad"):
        assert np.array_equal(getattr(batch, name), getattr(again, name))


def test_monte_carlo_draws_are_the_generators_own():
    got = granules.replicate_uniforms(4, np.array([3]), 10, sampler="mc")[0]
    assert np.array_equal(got, np.random.default_rng([4, 3]).random((10, 4)))
