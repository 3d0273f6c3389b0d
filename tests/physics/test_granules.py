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
    batch = granules.sample_granules(scene, library.fertilizer_of(scene), replicates=8, first_replicate=2)
    u = np.vstack([scipy_uniforms(3, 2 + k, 512) for k in range(8)])
    assert np.array_equal(batch.phase_rad, 2.0 * np.pi * u[:, 0])
    assert np.array_equal(batch.replicate, np.repeat(np.arange(8), 512))
    again = granules.sample_granules(scene, library.fertilizer_of(scene), replicates=8, first_replicate=2)
    for name in ("diameter_m", "mass_kg", "release_xy_m", "phase_rad"):
        assert np.array_equal(getattr(batch, name), getattr(again, name))


def test_monte_carlo_draws_are_the_generators_own():
    got = granules.replicate_uniforms(4, np.array([3]), 10, sampler="mc")[0]
    assert np.array_equal(got, np.random.default_rng([4, 3]).random((10, 4)))


def unscrambled_points(numbers: np.ndarray, count: int) -> np.ndarray:
    """(count, dims) unscrambled Sobol points from direction numbers, in Gray-code order."""
    point = np.zeros(numbers.shape[0], dtype=np.uint64)
    points = [point.copy()]
    for i in range(1, count):
        point ^= numbers[:, (i & -i).bit_length() - 1]
        points.append(point.copy())
    return np.asarray(points) / 2.0**granules.SOBOL_BITS


@pytest.mark.parametrize("dims", [1, 2, 4, 8])
def test_direction_number_table_gives_scipys_unscrambled_points(dims):
    """The first 2^13 points exercise direction numbers 0-12; the engine's own."""
    engine = qmc.Sobol(dims, scramble=False, bits=granules.SOBOL_BITS)
    assert np.array_equal(unscrambled_points(granules._direction_numbers(dims), 2**13), engine.random(2**13))


@pytest.mark.parametrize("j", [13, 17, 21, 23])
def test_high_direction_numbers_equal_scipys_engine(j):
    """Point 2^(j+1) - 1 of the unscrambled sequence is direction number j alone."""
    engine = qmc.Sobol(8, scramble=False, bits=granules.SOBOL_BITS)
    engine.fast_forward(2 ** (j + 1) - 1)
    expected = np.rint(engine.random(1)[0] * 2.0**granules.SOBOL_BITS).astype(np.uint64)
    assert np.array_equal(granules._direction_numbers(8)[:, j], expected)


def test_direction_number_table_holds_scipys_data():
    """All 30 numbers of every tabled dimension, against scipy's own polynomials and initial
    integers run through scipy's initialisation (its private helpers: the one check of
    numbers 24-29 that costs no seconds of fast-forwarding)."""
    from scipy.stats import _sobol

    dims = len(granules.SOBOL_POLYNOMIALS)
    poly = _sobol.get_poly_vinit("poly", np.uint64)
    vinit = _sobol.get_poly_vinit("vinit", np.uint64)
    assert tuple(int(p) for p in poly[:dims]) == granules.SOBOL_POLYNOMIALS
    for d, initial in enumerate(granules.SOBOL_INITIAL[1:], start=1):
        assert tuple(int(m) for m in vinit[d][:len(initial)]) == initial
        assert not vinit[d][len(initial):].any()
    sv = np.zeros((dims, granules.SOBOL_BITS), dtype=np.uint64)
    _sobol._initialize_v(sv, dim=dims, bits=granules.SOBOL_BITS)
    assert np.array_equal(granules._direction_numbers(dims), sv)


def test_direction_numbers_beyond_the_table_are_refused():
    with pytest.raises(ValueError, match="Sobol dimensions"):
        granules._direction_numbers(len(granules.SOBOL_POLYNOMIALS) + 1)
