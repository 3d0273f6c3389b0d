"""The corrected CV: unbiased on patterns with a known exact CV, honest standard errors."""

import numpy as np
import pytest
from scipy import stats

from spreadgym.spread import estimate, pattern

TRAY_M = 0.5
HALF_WIDTH_M = 15.0
GRANULES = 4000  # at 1000 the gaussian's noise outweighs its 6 % CV and no estimator is unbiased


def exact_trays(cdf) -> np.ndarray:
    """Expected tray masses (probabilities) of a landing distribution with CDF `cdf`."""
    m = int(round(HALF_WIDTH_M / TRAY_M))
    edges = (np.arange(-m, m + 2) - 0.5) * TRAY_M
    return np.diff(cdf(edges))


PATTERNS = {
    # name: (sampler(rng, n) -> x, cdf, bout width, driving)
    "gaussian": (lambda rng, n: rng.normal(0.0, 2.0, n), stats.norm(0, 2.0).cdf, 5.0, "racetrack"),
    "triangle": (lambda rng, n: rng.triangular(-4.0, 0.0, 4.0, n), stats.triang(0.5, -4.0, 8.0).cdf, 5.0,
                 "racetrack"),
    "skewed": (lambda rng, n: rng.gamma(3.0, 1.0, n) - 3.0, stats.gamma(3.0, loc=-3.0).cdf, 4.0,
               "back-and-forth"),
}


def exact_cv(name: str) -> float:
    _, cdf, width, driving = PATTERNS[name]
    probs = exact_trays(cdf)
    n = round(width / TRAY_M)
    bout = pattern._fold_matrix(probs.size, n, driving) @ probs  # numpy, not the kernels
    return float(100.0 * bout.std(ddof=bout.size // n) / bout.mean())  # a period of 2n: its trays weigh 1/2


def draw(name: str, seed: int, granules: int, replicates: int) -> estimate.CvEstimate:
    sample, _, width, driving = PATTERNS[name]
    rng = np.random.default_rng(seed)
    x = np.clip(sample(rng, granules), -HALF_WIDTH_M, HALF_WIDTH_M)
    replicate = np.arange(granules) % replicates
    _, masses = estimate.replicate_tray_masses(x, 1.0, replicate, replicates, TRAY_M, HALF_WIDTH_M)
    return estimate.estimate_cv(masses, TRAY_M, width, driving)


@pytest.mark.parametrize("name", sorted(PATTERNS))
def test_corrected_cv_is_unbiased_where_the_plain_cv_is_not(name):
    exact = exact_cv(name)
    runs = [draw(name, seed, GRANULES, 8) for seed in range(400)]
    corrected = np.array([r.cv_percent for r in runs])
    raw = np.array([r.raw_percent for r in runs])
    se_of_mean = corrected.std(ddof=1) / np.sqrt(corrected.size)
    assert abs(corrected.mean() - exact) < 3 * se_of_mean, (corrected.mean(), exact, se_of_mean)
    # the plain CV of as many granules is biased upwards, far beyond its own standard error
    assert raw.mean() - exact > 3 * raw.std(ddof=1) / np.sqrt(raw.size)


@pytest.mark.parametrize("name", sorted(PATTERNS))
def test_stated_standard_error_covers_the_exact_cv(name):
    exact = exact_cv(name)
    runs = [draw(name, 10_000 + seed, GRANULES, 8) for seed in range(400)]
    covered = np.mean([r.interval_percent[0] <= exact <= r.interval_percent[1] for r in runs])
    assert 0.90 <= covered <= 0.99, covered
    stated = np.sqrt(np.mean([r.standard_error_percent**2 for r in runs]))
    observed = np.std([r.cv_percent for r in runs], ddof=1)
    assert stated == pytest.approx(observed, rel=0.25)


def test_one_replicate_gives_the_plain_cv_and_no_standard_error():
    result = draw("gaussian", 0, 500, 1)
    assert result.cv_percent == pytest.approx(result.raw_percent, rel=1e-12)
    assert result.standard_error_percent is None and result.interval_percent is None


def test_pooled_trays_equal_the_sum_of_the_replicates():
    rng = np.random.default_rng(1)
    x = rng.normal(0, 2, 3000)
    mass = rng.uniform(1e-5, 3e-5, 3000)
    replicate = rng.integers(0, 5, 3000)
    trays, per_replicate = estimate.replicate_tray_masses(x, mass, replicate, 5, TRAY_M)
    np.testing.assert_allclose(per_replicate.sum(axis=0), trays.mass_kg, rtol=1e-12, atol=1e-18)
    assert np.array_equal(trays.mass_kg, pattern.collect(x, mass, TRAY_M).mass_kg)


def test_empty_pattern_has_no_cv():
    result = estimate.estimate_cv(np.zeros((4, 21)), TRAY_M, 3.0, "racetrack")
    assert result == estimate.CvEstimate(None, None, None, None)


def per_width_curve(masses, driving, widths):
    """The reference: `estimate_cv` at each width in turn."""
    found = [estimate.estimate_cv(masses, TRAY_M, w, driving) for w in widths]
    return (np.array([np.nan if e.cv_percent is None else e.cv_percent for e in found]),
            np.array([np.nan if e.standard_error_percent is None else e.standard_error_percent for e in found]))


@pytest.mark.parametrize("driving", pattern.DRIVING)
@pytest.mark.parametrize("replicates", [1, 2, 3, 8])
def test_cv_curve_in_one_pass_equals_estimate_cv_width_by_width(driving, replicates):
    rng = np.random.default_rng(replicates)
    widths = np.arange(1, 32) * TRAY_M
    cases = [rng.random((replicates, 31)) * (rng.random((replicates, 31)) > 0.3),  # gaps
             np.zeros((replicates, 31))]  # nothing landed
    alone = np.zeros((replicates, 31))
    alone[0, 10:14] = 1.0  # one replicate holds all the mass: no correction, no error
    cases.append(alone)
    for masses in cases:
        for got, want in zip(estimate.cv_curve(masses, TRAY_M, driving, widths),
                             per_width_curve(masses, driving, widths)):
            np.testing.assert_array_equal(got, want)  # the same kernel on one width or many: the same bits


@pytest.mark.parametrize("driving", pattern.DRIVING)
def test_compiled_bout_cvs_match_numpy_jackknife(driving):
    """The compiled kernel against the estimator written out in numpy: the fold as a
    matrix product, the CV with numpy's std, the jackknife over replicates."""
    rng = np.random.default_rng(7)
    masses = rng.random((6, 41)) * (rng.random((6, 41)) > 0.2)
    widths = np.arange(1, 42) * TRAY_M
    cvs, ses = estimate.cv_curve(masses, TRAY_M, driving, widths)
    for w, cv, se in zip(widths, cvs, ses):
        n = round(w / TRAY_M)
        fold = pattern._fold_matrix(41, n, driving)
        bouts = masses @ fold.T

        def plain(b, n=n):  # ddof 1 over the bout; 2 over a period of 2n (its trays weigh 1/2)
            return 100.0 * b.std(ddof=b.size // n) / b.mean() if n > 1 else 0.0

        raw = plain(bouts.sum(axis=0))
        loo = np.array([plain(np.delete(bouts, i, axis=0).sum(axis=0)) for i in range(6)])
        np.testing.assert_allclose(cv, max(0.0, 6 * raw - 5 * loo.mean()), rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(se, np.sqrt(5 / 6 * np.sum((loo - loo.mean()) ** 2)), rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("driving", pattern.DRIVING)
def test_many_replicates_curve_shared_out_over_threads_keeps_its_bits(driving):
    """A pooled reference's curve (hundreds of replicates) is split by widths over the
    threads; every width alone gives the same bits whatever the thread count, and the
    leave-one-out sums (a running sum plus the rest) agree with numpy's jackknife."""
    from spreadgym import threads

    rng = np.random.default_rng(11)
    masses = rng.random((300, 33)) * (rng.random((300, 33)) > 0.1)
    widths = np.arange(1, 34) * TRAY_M
    threads.set_threads(1)
    try:
        alone = estimate.cv_curve(masses, TRAY_M, driving, widths)
        assert estimate.SPLIT_WORK < 300**2 * np.arange(1, 34).sum()  # the split path is the one taken
        for count in (2, 3, 7):
            threads.set_threads(count)
            for got, want in zip(estimate.cv_curve(masses, TRAY_M, driving, widths), alone):
                np.testing.assert_array_equal(got, want)
    finally:
        threads.set_threads(None)
    for w, cv, se in list(zip(widths, *alone))[::8]:
        n = round(w / TRAY_M)
        bouts = masses @ pattern._fold_matrix(33, n, driving).T
        ddof = bouts.shape[1] // n  # 1 over a bout, 2 over a period of 2n (its trays weigh 1/2)
        loo = bouts.sum(axis=0) - bouts
        plain = 100.0 * loo.std(axis=1, ddof=ddof) / loo.mean(axis=1) if n > 1 else np.zeros(300)
        raw = 100.0 * bouts.sum(axis=0).std(ddof=ddof) / bouts.sum(axis=0).mean() if n > 1 else 0.0
        np.testing.assert_allclose(cv, max(0.0, 300 * raw - 299 * plain.mean()), rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(se, np.sqrt(299 / 300 * np.sum((plain - plain.mean()) ** 2)), rtol=1e-7)
