"""The compiled von Mises pairs (spread.von_mises) against numpy's sampler on the same
generator and against the law's own distribution function."""

import numpy as np
import pytest
from scipy import stats

from spreadgym.spread import von_mises

# both limit branches (uniform below 1e-8, normal above 1e6), the Taylor branch, the rest
KAPPAS = np.array([1e-9, 3e-6, 2e-3, 0.3, 1.0, 4.0, 37.0, 900.0, 2e7])


def wrapped(angle):
    return np.angle(np.exp(1j * angle))


def turns(rng, kappa, mu, copies, columns=None, width=None):
    """Angles (copies, width) from antithetic_turns; row 0 and unlisted columns stay NaN."""
    columns = np.arange(kappa.size) if columns is None else columns
    width = kappa.size if width is None else width
    cos, sin = np.full((copies, width), np.nan), np.full((copies, width), np.nan)
    von_mises.antithetic_turns(rng, kappa, np.cos(mu), np.sin(mu), columns, cos, sin)
    return np.arctan2(sin, cos), cos, sin


@pytest.mark.parametrize("copies", [15, 16])
def test_the_pairs_are_numpys_draws_about_the_mean(copies):
    kappa = np.tile(KAPPAS, 40)
    mu = np.random.default_rng(0).uniform(-np.pi, np.pi, kappa.size)
    angle, cos, sin = turns(np.random.default_rng(11), kappa, mu, copies)
    pairs, minus = copies // 2, copies - 1 - copies // 2
    phi = np.random.default_rng(11).vonmises(0.0, np.broadcast_to(kappa, (pairs, kappa.size)))
    np.testing.assert_allclose(wrapped(angle[1:pairs + 1] - (mu + phi)), 0.0, atol=1e-12)
    np.testing.assert_allclose(wrapped(angle[pairs + 1:] - (mu - phi[:minus])), 0.0, atol=1e-12)
    np.testing.assert_allclose(cos[1:]**2 + sin[1:]**2, 1.0, rtol=0, atol=1e-15)
    assert np.isnan(cos[0]).all()  # row 0 (the granule itself) is the caller's


def test_only_the_listed_columns_are_written():
    angle, _, _ = turns(np.random.default_rng(3), np.array([2.0, 5.0]), np.zeros(2), 5,
                        columns=np.array([3, 1]), width=4)
    assert np.isnan(angle[:, [0, 2]]).all() and np.isfinite(angle[1:, [1, 3]]).all()


def test_the_generator_is_left_where_numpy_leaves_it():
    ours, numpys = np.random.default_rng(4), np.random.default_rng(4)
    kappa = np.tile(KAPPAS, 10)
    turns(ours, kappa, np.zeros(kappa.size), 7)
    numpys.vonmises(0.0, np.broadcast_to(kappa, (3, kappa.size)))
    assert ours.random() == numpys.random()


@pytest.mark.parametrize("kappa", [0.5, 4.0, 60.0])
def test_the_angles_follow_the_von_mises_distribution(kappa):
    angle, _, sin = turns(np.random.default_rng(2), np.full(20_000, kappa), np.zeros(20_000), 2)
    result = stats.kstest(angle[1], stats.vonmises(kappa).cdf)
    assert result.pvalue > 1e-3
    assert abs(sin[1].mean()) < 4.0 * sin[1].std() / np.sqrt(sin[1].size)  # symmetric: the sign is drawn
