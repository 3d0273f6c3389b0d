"""Tray collection, overlap and CV against hand computations and analytic patterns."""

import math

import numpy as np
import pytest

from spreadgym.errors import ConfigError
from spreadgym.spread import pattern
from spreadgym.spread.pattern import (
    DRIVING,
    Trays,
    bout_pattern,
    collect,
    cv_curve,
    cv_percent,
    effective_swath_m,
)

W_TRAY = 0.5


def _grid(half_count, w=W_TRAY):
    return np.arange(-half_count, half_count + 1) * w


def triangle_trays(base_m=48.0, peak_x_m=0.0, w=W_TRAY, half_count=None):
    """Tray masses of a triangle density (area 1) with support [-base/2, base/2]
    (peak moved to peak_x_m for skewed cases), integrated exactly over each tray."""
    a, b, c = -base_m / 2, base_m / 2, peak_x_m
    height = 2.0 / (b - a)

    def cdf(x):
        x = min(max(x, a), b)
        if x <= c:
            return height * (x - a) ** 2 / (2 * (c - a)) if c > a else 0.0
        left = height * (c - a) / 2
        return left + height * (b - c) / 2 - height * (b - x) ** 2 / (2 * (b - c))

    m = half_count if half_count is not None else int(math.ceil(b / w)) + 2
    centers = _grid(m, w)
    mass = np.array([cdf(x + w / 2) - cdf(x - w / 2) for x in centers])
    return Trays(centers, mass, w)


def gaussian_trays(sigma_m, w=W_TRAY, mean_m=0.0, half_width_m=None):
    half = half_width_m if half_width_m is not None else 6 * sigma_m + abs(mean_m)
    m = int(math.ceil(half / w))
    centers = _grid(m, w)
    cdf = lambda x: 0.5 * (1 + math.erf((x - mean_m) / (sigma_m * math.sqrt(2))))  # noqa: E731
    mass = np.array([cdf(x + w / 2) - cdf(x - w / 2) for x in centers])
    return Trays(centers, mass, w)


def brute_force_bout(trays, n, driving):
    """Lay the passes on a long tray grid one by one and read the strip of n trays
    centred on pass 0 (centres in [-W/2, W/2)), or for back-and-forth with n even the
    whole period of 2n trays from there."""
    m = trays.count // 2
    passes = m // n + 3
    offset = (passes + 1) * n + m
    field = np.zeros(2 * offset + 1)
    for j in range(-passes, passes + 1):
        mirrored = driving == "back-and-forth" and j % 2 != 0
        for i, p in zip(range(-m, m + 1), trays.mass_kg):
            field[offset + j * n + (-i if mirrored else i)] += p
    k = np.arange(2 * n if driving == "back-and-forth" and n % 2 == 0 else n) - n // 2
    return field[offset + k]


def sample_cv(values, n=None):
    """CV (%) of a bout of n trays given as its n values or as a period of 2n, each of
    whose trays then weighs 1/2 (n trays' worth: ddof 1 over n)."""
    values = np.asarray(values, dtype=float)
    n = values.size if n is None else n
    if n == 1:
        return 0.0  # one tray: nothing to vary
    weight = n / values.size
    mean = values.sum() / values.size
    sd = math.sqrt(weight * ((values - mean) ** 2).sum() / (n - 1))
    return 100.0 * sd / mean


# ---- collect -------------------------------------------------------------------


def test_collect_by_hand():
    x = [-0.26, -0.25, -0.24, 0.0, 0.249, 0.25, 0.74, 0.75]
    mass = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0]
    trays = collect(x, mass, 0.5)
    # tray i covers [0.5 i - 0.25, 0.5 i + 0.25): -0.26 -> -1; -0.25..0.249 -> 0;
    # 0.25, 0.74 -> 1; 0.75 -> 2; so m = 2 and five trays
    np.testing.assert_array_equal(trays.center_m, [-1.0, -0.5, 0.0, 0.5, 1.0])
    np.testing.assert_array_equal(trays.mass_kg, [0.0, 1.0, 2 + 4 + 8 + 16, 32 + 64, 128])
    assert trays.width_m == 0.5
    assert trays.pattern_width_m == 2.0  # trays -1..2 loaded
    assert trays.reach_trays == 2


def test_collect_min_half_width_and_empty():
    trays = collect([0.1], [1.0], 0.5, min_half_width_m=24.0)
    assert trays.count % 2 == 1
    assert trays.center_m[-1] + 0.25 >= 24.0 and trays.center_m[0] - 0.25 <= -24.0
    assert trays.center_m[-1] == 24.0  # 48 trays each side, exactly enough
    empty = collect([], [], 0.5)
    assert empty.count == 1 and empty.total_kg == 0.0


def test_collect_conserves_mass():
    rng = np.random.default_rng(4)
    x = rng.normal(2.0, 7.0, 50_000)
    mass = rng.uniform(1e-5, 3e-5, x.size)
    trays = collect(x, mass, 0.5)
    assert trays.count % 2 == 1
    assert trays.center_m[trays.count // 2] == 0.0
    assert math.isclose(trays.mass_kg.sum(), mass.sum(), rel_tol=1e-12)
    # every granule inside the row
    assert x.min() >= trays.center_m[0] - 0.25 and x.max() < trays.center_m[-1] + 0.25


# ---- worked cases ----------------------------------------------------------------

TRIANGLE_TABLE = [(12.0, 0.0), (16.0, 6.5), (24.0, 0.0), (28.0, 5.4), (32.0, 14.4), (36.0, 25.2)]


@pytest.mark.parametrize("driving", DRIVING)
@pytest.mark.parametrize("width, expected", TRIANGLE_TABLE)
def test_triangle_worked_case(driving, width, expected):
    trays = triangle_trays(48.0)
    assert math.isclose(trays.total_kg, 1.0, rel_tol=1e-12)
    cv = cv_percent(trays, width, driving)
    assert abs(cv - expected) < 0.05, cv
    # independent overlap and CV give the same number
    n = int(width / W_TRAY)
    assert cv == pytest.approx(sample_cv(brute_force_bout(trays, n, driving), n), abs=1e-9)


@pytest.mark.parametrize("peak_x_m", [10.0, -10.0])
@pytest.mark.parametrize("width, racetrack, back_and_forth", [(10.0, 11.8, 19.7), (15.0, 23.4, 49.8)])
def test_skewed_triangle_worked_case(peak_x_m, width, racetrack, back_and_forth):
    """docs/flight-and-pattern.md's skewed rows, whichever way the triangle leans (the
    even strip gave 21.2 % at 10 m leaning right and 18.0 % leaning left)."""
    trays = triangle_trays(30.0, peak_x_m=peak_x_m)
    assert abs(cv_percent(trays, width, "racetrack") - racetrack) < 0.05
    assert abs(cv_percent(trays, width, "back-and-forth") - back_and_forth) < 0.05


@pytest.mark.parametrize("driving", DRIVING)
@pytest.mark.parametrize("width, expected", [(20.0, 6.1), (24.0, 15.9)])
def test_gaussian_worked_case(driving, width, expected):
    trays = gaussian_trays(8.0)
    assert abs(cv_percent(trays, width, driving) - expected) < 0.05


# ---- overlap -------------------------------------------------------------------


@pytest.mark.parametrize("driving", DRIVING)
@pytest.mark.parametrize("n", [1, 2, 3, 7, 8, 24, 25, 60, 97, 140])
def test_bout_pattern_matches_brute_force_on_skewed_pattern(driving, n):
    trays = triangle_trays(30.0, peak_x_m=9.0, half_count=40)
    got = bout_pattern(trays, n * W_TRAY, driving)
    assert got.shape == ((2 * n,) if driving == "back-and-forth" and n % 2 == 0 else (n,))
    np.testing.assert_allclose(got, brute_force_bout(trays, n, driving), rtol=1e-12, atol=1e-15)
    assert got.mean() * n == pytest.approx(trays.total_kg, rel=1e-12)  # a bout holds one pass's mass
    assert cv_percent(trays, n * W_TRAY, driving) == pytest.approx(sample_cv(got, n), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("n", [2, 3, 4, 6, 7, 8, 12, 28, 60])
def test_back_and_forth_cv_does_not_depend_on_which_way_the_pattern_leans(n):
    """A pattern and its mirror image make mirrored fields, so one CV (the strip of an
    even count held one kind of bout's midline tray and not the other's: the two
    differed by up to 3 pp on the field scene); the estimate's kernel agrees."""
    trays = triangle_trays(30.0, peak_x_m=9.0, half_count=40)
    mirrored = Trays(trays.center_m, trays.mass_kg[::-1].copy(), trays.width_m)
    cv = cv_percent(trays, n * W_TRAY, "back-and-forth")
    assert cv_percent(mirrored, n * W_TRAY, "back-and-forth") == pytest.approx(cv, rel=1e-12)
    masses = np.stack([trays.mass_kg, 0.5 * trays.mass_kg, mirrored.mass_kg])
    flipped = masses[:, ::-1].copy()
    from spreadgym.spread import estimate

    for got, want in zip(estimate.cv_curve(masses, W_TRAY, "back-and-forth", [n * W_TRAY]),
                         estimate.cv_curve(flipped, W_TRAY, "back-and-forth", [n * W_TRAY])):
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-9)


def test_back_and_forth_with_mass_in_one_tray_off_the_axis_has_a_cv():
    """Mass in one tray lands in some bout whichever way: the strip of an even count
    missed it and gave NaN (as if nothing had landed) where its mirror image gave 141 %."""
    trays = Trays(_grid(2), np.array([0.0, 0.0, 0.0, 1.0, 0.0]), W_TRAY)
    mirrored = Trays(_grid(2), np.array([0.0, 1.0, 0.0, 0.0, 0.0]), W_TRAY)
    cv = cv_percent(trays, 2 * W_TRAY, "back-and-forth")
    assert math.isfinite(cv) and cv == pytest.approx(cv_percent(mirrored, 2 * W_TRAY, "back-and-forth"))
    # the period (0.5 m trays at -0.5, 0, 0.5, 1.0 m) holds the tray's mass at 0.5 m only: 1 of 4
    assert cv == pytest.approx(sample_cv([0.0, 0.0, 1.0, 0.0], 2))


def test_racetrack_bout_holds_one_pass():
    trays = triangle_trays(30.0, peak_x_m=9.0)
    for n in (5, 12, 40):
        assert bout_pattern(trays, n * W_TRAY, "racetrack").sum() == pytest.approx(trays.total_kg)


def test_symmetric_pattern_same_for_both_driving_patterns():
    trays = gaussian_trays(6.0)
    for n in range(1, 80):
        racetrack, back_and_forth = (bout_pattern(trays, n * W_TRAY, d) for d in DRIVING)
        # a back-and-forth period (n even) is two bouts
        np.testing.assert_allclose(np.tile(racetrack, back_and_forth.size // n), back_and_forth)
        assert cv_percent(trays, n * W_TRAY, "racetrack") == pytest.approx(
            cv_percent(trays, n * W_TRAY, "back-and-forth"), rel=1e-9, abs=1e-12)


def test_skewed_pattern_differs_between_driving_patterns():
    skewed = triangle_trays(30.0, peak_x_m=10.0)  # peak well right of the axis
    half_gauss = Trays(_grid(60), np.where(_grid(60) >= 0, np.exp(-0.5 * (_grid(60) / 8.0) ** 2), 0.0), W_TRAY)
    for trays in (skewed, half_gauss):
        for width in (10.0, 15.0, 18.0, 20.5):
            a = cv_percent(trays, width, "racetrack")
            b = cv_percent(trays, width, "back-and-forth")
            assert abs(a - b) > 0.5, (width, a, b)


def test_back_and_forth_odd_bout_represents_the_whole_period():
    """Back-and-forth repeats every 2W; with n odd the strip centred on a pass
    holds each value of the period once (the period holds it twice)."""
    trays = triangle_trays(30.0, peak_x_m=9.0, half_count=40)
    for n in (3, 15, 31, 45):
        strip = bout_pattern(trays, n * W_TRAY, "back-and-forth")
        # lay the field with passes every n trays and read one 2n-tray period
        m = trays.count // 2
        passes = m // n + 4
        offset = (passes + 2) * n + m
        field = np.zeros(2 * offset + 1)
        for j in range(-passes, passes + 1):
            for i, p in zip(range(-m, m + 1), trays.mass_kg):
                field[offset + j * n + (-i if j % 2 else i)] += p
        period = field[offset - n: offset + n]
        np.testing.assert_allclose(np.sort(np.repeat(strip, 2)), np.sort(period), rtol=1e-12, atol=1e-15)


# ---- CV curve and effective swath -----------------------------------------------


def test_cv_curve_default_widths():
    trays = triangle_trays(48.0)
    widths, cvs = cv_curve(trays, "racetrack")
    assert widths[0] == W_TRAY
    np.testing.assert_allclose(np.diff(widths), W_TRAY)
    # loaded trays reach +-24 m: up to 97 trays
    assert widths[-1] == pytest.approx((2 * 48 + 1) * W_TRAY)
    assert cvs[0] == 0.0  # one tray per bout
    assert np.all(np.isfinite(cvs))


def test_cv_curve_of_a_tray_width_with_more_decimals_than_its_rounding():
    """A continuous-swath job's trays are W / k wide (envs, `swath_draw: continuous`); the curve's
    widths are rounded to the nanometre, and must still count as whole numbers of trays. The
    curve equals the one computed at the same widths unrounded; an off-grid width is still refused."""
    w = 2.888263574960896 / 6  # 0.48137726249...
    trays = triangle_trays(12.0, w=w)
    widths, cvs = cv_curve(trays, "back-and-forth")
    exact = [cv_percent(trays, k * w, "back-and-forth") for k in range(1, widths.size + 1)]
    np.testing.assert_allclose(cvs, exact, rtol=0, atol=0)
    assert cv_percent(trays, 6 * w, "back-and-forth") == cvs[5]
    with pytest.raises(ConfigError, match="not a positive multiple"):
        cv_percent(trays, 6 * w + 1e-6, "back-and-forth")


@pytest.mark.parametrize("driving", DRIVING)
def test_effective_swath_triangle(driving):
    trays = triangle_trays(48.0)
    widths = np.arange(1, 200) * W_TRAY
    cvs = np.array([sample_cv(brute_force_bout(trays, int(round(w / W_TRAY)), driving)) if w > W_TRAY else 0.0
                    for w in widths])
    for threshold in (15.0, 5.0, 25.0):
        expected = widths[cvs <= threshold].max()
        got = effective_swath_m(trays, driving, threshold)
        assert got == pytest.approx(expected)
    # 15 %: 32 m passes (14.4 %), 36 m fails (25.2 %)
    assert 32.0 <= effective_swath_m(trays, driving, 15.0) < 36.0


def test_effective_swath_takes_largest_width_of_non_monotone_curve():
    trays = triangle_trays(48.0)
    # CV 0 at 12 m, 6.5 % at 16 m, 0 at 24 m, 5.4 % at 28 m: at 5 % the curve fails
    # between 12 and 24 m and passes again at 24 m
    assert cv_percent(trays, 16.0, "racetrack") > 5.0
    assert effective_swath_m(trays, "racetrack", 5.0) >= 24.0


def test_effective_swath_none_and_empty():
    empty = Trays(_grid(3), np.zeros(7), W_TRAY)
    assert math.isnan(cv_percent(empty, 1.0, "racetrack"))
    assert effective_swath_m(empty, "racetrack", 15.0) == 0.0
    # a lone heap one tray wide: nothing but a one-tray bout reaches a tiny threshold (one
    # tray's CV is 0 whatever the pattern; the reports call a swath under two trays none)
    heap = Trays(_grid(10), np.where(np.arange(21) == 14, 1.0, 0.0), W_TRAY)
    assert effective_swath_m(heap, "racetrack", 1.0, widths_m=[1.0, 2.0, 5.0]) == 0.0
    assert effective_swath_m(heap, "racetrack", 1.0) == W_TRAY


# ---- errors ---------------------------------------------------------------------


def test_errors_name_their_keys():
    trays = triangle_trays(48.0)
    with pytest.raises(ConfigError) as e:
        cv_percent(trays, 12.3, "racetrack")
    assert e.value.key == "pattern.target_swath_m"
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigError) as e:
            bout_pattern(trays, bad, "racetrack")
        assert e.value.key == "pattern.target_swath_m"
    with pytest.raises(ConfigError) as e:
        cv_percent(trays, 12.0, "spiral")
    assert e.value.key == "pattern.driving" and "racetrack, back-and-forth" in str(e.value)
    for bad in (0.0, -0.5):
        with pytest.raises(ConfigError) as e:
            collect([0.0], [1.0], bad)
        assert e.value.key == "pattern.tray_width_m"
    with pytest.raises(ConfigError):
        Trays(_grid(2)[:-1], np.ones(4), W_TRAY)  # even count
    with pytest.raises(ConfigError) as e:
        effective_swath_m(trays, "racetrack", 0.0)
    assert e.value.key == "pattern.cv_threshold_percent"


@pytest.mark.parametrize("driving", ["racetrack", "back-and-forth"])
@pytest.mark.parametrize("tray_count", [1, 7, 31, 61])
def test_fold_pairs_lay_every_bout_width_side_by_side(driving, tray_count):
    """Each tray alone, laid pass by pass (brute force): its column in every bout.

    61 trays (30 m) already has every case of the index arithmetic (bouts wider than
    the pattern, odd and even pass counts); the brute force grows as trays^3, so the
    twin-field's 171 trays would cost 40 s for nothing new."""
    counts = np.arange(1, tray_count + 3)
    tray, column = pattern.fold_pairs(tray_count, counts, driving)
    stacked = np.zeros((pattern.bout_columns(counts, driving == "racetrack").sum(), tray_count))
    np.add.at(stacked, (column, tray), 1.0)
    centres = _grid(tray_count // 2)
    expected = np.vstack([
        np.column_stack([brute_force_bout(Trays(centres, np.eye(tray_count)[i], W_TRAY), int(n), driving)
                         for i in range(tray_count)])
        for n in counts])
    assert np.array_equal(stacked, expected)
