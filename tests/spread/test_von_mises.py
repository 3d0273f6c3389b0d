"""The compiled von Mises pairs (spread.von_mises) against numpy's sampler on the same
generator and against the law's own distribution function."""

import numpy as np
import pytest
from scipy import stats

from spreadgym.physics.compiled import pcg64
from spreadgym.spread import von_mises

# the uniform branch (below 1e-8), the Taylor branch, the rest; the normal branch (above
# 1e6) is numpy's own (`fill_turns`)
KAPPAS = np.array([1e-9, 3e-6, 2e-3, 0.3, 1.0, 4.0, 37.0, 900.0, 5e5])


def wrapped(angle):
    return np.angle(np.exp(1j * angle))


def turns(seed, kappa, mu, copies):
    """Angles (copies, N) from `fill_turns` with one run; row 0 stays NaN."""
    cos, sin = np.full((copies, kappa.size), np.nan), np.full((copies, kappa.size), np.nan)
    von_mises.fill_turns([(seed,)], np.array([0]), np.array([kappa.size]), kappa, np.cos(mu), np.sin(mu), cos, sin)
    return np.arctan2(sin, cos), cos, sin


@pytest.mark.parametrize("copies", [15, 16])
@pytest.mark.parametrize("kappas", [KAPPAS, np.append(KAPPAS, 2e7)], ids=["kernel", "numpy's normal branch"])
def test_the_pairs_are_numpys_draws_about_the_mean(copies, kappas):
    kappa = np.tile(kappas, 40)
    mu = np.random.default_rng(0).uniform(-np.pi, np.pi, kappa.size)
    angle, cos, sin = turns(11, kappa, mu, copies)
    pairs, minus = copies // 2, copies - 1 - copies // 2
    phi = np.random.default_rng((11,)).vonmises(0.0, np.broadcast_to(kappa, (pairs, kappa.size)))
    np.testing.assert_allclose(wrapped(angle[1:pairs + 1] - (mu + phi)), 0.0, atol=1e-12)
    np.testing.assert_allclose(wrapped(angle[pairs + 1:] - (mu - phi[:minus])), 0.0, atol=1e-12)
    np.testing.assert_allclose(cos[1:]**2 + sin[1:]**2, 1.0, rtol=0, atol=1e-15)
    assert np.isnan(cos[0]).all()  # row 0 (the granule itself) is the caller's


def test_the_generator_is_left_where_numpy_leaves_it():
    kappa = np.tile(KAPPAS, 10)
    states = pcg64.seeded([(4,)])
    cos, sin = np.empty((7, kappa.size)), np.empty((7, kappa.size))
    von_mises.antithetic_turns(states, np.array([0]), np.array([kappa.size]), kappa, np.ones(kappa.size),
                               np.zeros(kappa.size), cos, sin)
    numpys = np.random.default_rng((4,))
    numpys.vonmises(0.0, np.broadcast_to(kappa, (3, kappa.size)))
    words = numpys.bit_generator.state["state"]
    mask = (1 << 64) - 1
    assert list(states[0, :4]) == [words["state"] >> 64, words["state"] & mask, words["inc"] >> 64, words["inc"] & mask]


def test_runs_draw_from_their_own_streams():
    kappa = np.full(300, 2.0)
    mu = np.zeros(300)
    cos, sin = np.full((5, 300), np.nan), np.full((5, 300), np.nan)
    von_mises.fill_turns([(1, 0), (1, 1)], np.array([0, 100]), np.array([100, 300]), kappa, np.cos(mu), np.sin(mu),
                         cos, sin)
    for seed, part in (((1, 0), slice(0, 100)), ((1, 1), slice(100, 300))):
        width = part.stop - part.start
        one_cos, one_sin = np.full((5, width), np.nan), np.full((5, width), np.nan)
        von_mises.fill_turns([seed], np.array([0]), np.array([width]), kappa[part], np.ones(width), np.zeros(width),
                             one_cos, one_sin)
        assert np.array_equal(cos[1:, part], one_cos[1:]) and np.array_equal(sin[1:, part], one_sin[1:])


@pytest.mark.parametrize("kappa", [0.5, 4.0, 60.0])
def test_the_angles_follow_the_von_mises_distribution(kappa):
    angle, _, sin = turns(2, np.full(20_000, kappa), np.zeros(20_000), 2)
    result = stats.kstest(angle[1], stats.vonmises(kappa).cdf)
    assert result.pvalue > 1e-3
    assert abs(sin[1].mean()) < 4.0 * sin[1].std() / np.sqrt(sin[1].size)  # symmetric: the sign is drawn


def test_a_concentration_per_column_is_required():
    cos, sin = np.empty((4, 10)), np.empty((4, 10))
    with pytest.raises(ValueError, match="one entry per column"):
        von_mises.antithetic_turns(pcg64.seeded([(1,)]), np.array([0]), np.array([9]), np.ones(9), np.ones(9),
                                   np.zeros(9), cos, sin)
