"""Spread pattern scoring as a tray test does it (EN 13739-2, ISO 5690, ASABE S341).

A row of trays across the track catches one pass. The single-pass transverse
distribution is then overlapped with the neighbouring passes at bout width W and
the coefficient of variation (CV) of the overlapped distribution is computed over
the trays of one bout.

Conventions (x across the track, to the right of the machine; SI units):

* Trays: an odd number T = 2m + 1 of trays of width w, tray i (i = -m..m) centred
  at c_i = i w and covering [c_i - w/2, c_i + w/2); the middle tray is on the
  machine axis.
* Passes are at x = j W (j integer), W = n w with n a positive integer, so every
  pass lands on the tray grid and overlapping is exact index arithmetic.
* Racetrack (progressive): every pass drives the same way; the field is
  sum_j p(x - jW), periodic in W.
* Back-and-forth (alternating): every other pass (odd j) drives the other way, so
  its pattern is mirrored about its own axis, p(-(x - jW)). The field repeats every
  2W and each bout between two passes is mirror-symmetric about its midline; the
  bout between the right-hand sides of two passes differs from the bout between
  their left-hand sides when the pattern is skewed.
* One bout is the strip of n trays centred on a pass: the trays with centres in
  [-W/2, W/2). For racetrack any n consecutive trays give the same values. For
  back-and-forth this strip holds half of each kind of bout, so with n odd its
  values are exactly those of the whole 2W period (each counted once instead of
  twice). With n even a strip would hold the tray on one kind of bout's midline and
  not the one on the other's, so its CV would change when the pattern is mirrored
  (by over 3 pp on the field scene); the bout is then the whole period of 2n
  trays, in which every value of the field appears twice but the two midline trays
  once (`bout_columns`). A symmetric pattern gives the same field, hence the same
  numbers, for both driving patterns.
* CV = 100 s / mean, s the sample standard deviation (ddof = 1) over the n trays of
  one bout: for a period of 2n trays, its sum of squares over 2 (n - 1), i.e. the
  trays weighted 1/2, n trays' worth (`row_cv`); with n odd this is the strip's CV.
  With n = 1 the bout is one tray and the CV is 0 (nothing can vary at the tray
  resolution); with no mass at all the CV is NaN.
* Effective (working) width: the largest tested W whose CV is at or below the
  threshold. The CV curve need not be monotone (a triangle's curve dips back to 0
  at half and at its full base); the standards' working width is the largest W
  that satisfies the criterion, so narrower widths that fail in between are not a
  reason to stop early.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Optional, Sequence

import numpy as np

from spreadgym.errors import ConfigError
from spreadgym.physics.compiled.options import KERNEL
from spreadgym.spread import binning

DRIVING = ("racetrack", "back-and-forth")
_GRID_TOL = 1e-9
MAX_TRAYS = 4001  # a row of trays; 200 m at 0.05 m trays: beyond any spreader, and bounded memory


@dataclass(frozen=True)
class Trays:
    """One pass caught by a row of trays."""

    center_m: np.ndarray  # (T,) tray centres across the track (x), i * width, T odd
    mass_kg: np.ndarray  # (T,) mass collected per tray (single pass)
    width_m: float

    def __post_init__(self) -> None:
        width = _check_tray_width(self.width_m)
        center = np.asarray(self.center_m, dtype=float)
        mass = np.asarray(self.mass_kg, dtype=float)
        if center.ndim != 1 or mass.shape != center.shape:
            raise ConfigError(
                "trays", f"center_m and mass_kg must be 1-D of equal length, got {center.shape}, {mass.shape}"
            )
        if center.size % 2 != 1:
            raise ConfigError("trays", f"need an odd number of trays centred on the axis, got {center.size}")
        m = center.size // 2
        grid = np.arange(-m, m + 1) * width
        if not np.max(np.abs(center - grid)) <= _GRID_TOL * max(width, 1.0) * (m + 1):  # NaN fails too
            raise ConfigError("trays", "tray centres must be i * width_m for i = -m..m")
        if not np.all(np.isfinite(mass)) or np.any(mass < 0):
            raise ConfigError("trays", "tray masses must be finite and >= 0")
        object.__setattr__(self, "center_m", center)
        object.__setattr__(self, "mass_kg", mass)
        object.__setattr__(self, "width_m", width)

    @property
    def count(self) -> int:
        return int(self.center_m.size)

    @property
    def total_kg(self) -> float:
        return float(self.mass_kg.sum())

    @property
    def pattern_width_m(self) -> float:
        """Width from the left edge of the outermost loaded tray on the left to the
        right edge of the outermost loaded tray on the right (0 if empty)."""
        loaded = np.flatnonzero(self.mass_kg > 0)
        if loaded.size == 0:
            return 0.0
        return float((loaded[-1] - loaded[0] + 1) * self.width_m)

    @property
    def reach_trays(self) -> int:
        """max |i| over loaded trays (0 if empty)."""
        loaded = np.flatnonzero(self.mass_kg > 0)
        if loaded.size == 0:
            return 0
        return int(np.max(np.abs(loaded - self.count // 2)))


def _check_tray_width(tray_width_m) -> float:
    w = float(tray_width_m)
    if not (np.isfinite(w) and w > 0):
        raise ConfigError("pattern.tray_width_m", f"must be a positive number of metres, got {tray_width_m!r}")
    return w


def _check_driving(driving: str) -> str:
    if driving not in DRIVING:
        raise ConfigError(
            "pattern.driving", f"unknown driving pattern {driving!r}; allowed: {', '.join(DRIVING)}"
        )
    return driving


def bout_tray_count(bout_width_m: float, tray_width_m: float) -> int:
    """n = W / w, which must be a positive integer (to rounding): `bout_tray_counts` of one width."""
    return int(bout_tray_counts([bout_width_m], tray_width_m)[0])


def collect(x_m, mass_kg, tray_width_m: float, min_half_width_m: float = 0.0) -> Trays:
    """Catch granules landing at x_m (across the track) with masses mass_kg.

    The row has an odd number of trays centred on the axis and is wide enough to
    hold every granule and to reach at least min_half_width_m on each side."""
    return collect_indexed(x_m, mass_kg, tray_width_m, min_half_width_m)[0]


def collect_indexed(x_m, mass_kg, tray_width_m: float, min_half_width_m: float = 0.0) -> tuple[Trays, np.ndarray]:
    """`collect`, and the index of each granule's tray (0 .. count - 1, from the row's left end)."""
    x = np.asarray(x_m, dtype=float).reshape(-1)
    trays, _, index = collect_replicates(x, mass_kg, np.zeros(x.size, dtype=np.int64), 1, tray_width_m,
                                         min_half_width_m)
    return trays, index


def collect_replicates(x_m, mass_kg, replicate, replicates: int, tray_width_m: float,
                       min_half_width_m: float = 0.0) -> tuple[Trays, np.ndarray, np.ndarray]:
    """`collect` of granules in `replicates` independent replicates (`replicate` (N,),
    0..replicates-1 each): the pooled `Trays`, the (replicates, T) tray masses of each
    replicate on the same row, and each granule's tray (0 .. T - 1). One compiled pass
    (spreadgym.spread.binning); the sums are bincount's."""
    w = _check_tray_width(tray_width_m)
    x = np.asarray(x_m, dtype=float).reshape(-1)
    mass = np.asarray(mass_kg, dtype=float)
    if mass.shape != x.shape:  # one mass for all
        mass = np.broadcast_to(mass, x.shape)
    status, m, pooled, per_replicate, index = binning.bin_landings(
        x, mass, np.asarray(replicate, dtype=np.int64).reshape(-1), int(replicates), w,
        min_half_trays(min_half_width_m, w), MAX_TRAYS)
    if status == binning.BAD_POSITION:
        raise ConfigError("x_m", "landing positions must be finite")
    if status == binning.BAD_MASS:
        raise ConfigError("mass_kg", "granule masses must be finite and >= 0")
    if status == binning.BAD_REPLICATE:
        raise ConfigError("replicate", f"replicate indices must be in 0..{int(replicates) - 1}")
    if status == binning.TOO_WIDE:
        reach = float(np.max(np.abs(x))) / w + 0.5
        count = 2 * int(max(reach, m)) + 1
        raise ConfigError("pattern.tray_width_m", f"the pattern spans {count * w:.0f} m, {count} trays of {w:g} m; "
                                                  f"allowed up to {MAX_TRAYS} trays (use wider trays)")
    return tray_row(pooled, m, w), per_replicate, index


def min_half_trays(min_half_width_m: float, tray_width_m: float) -> int:
    """The fewest trays either side of the centre tray that reach `min_half_width_m` (m)."""
    half = float(min_half_width_m)
    if not (np.isfinite(half) and half >= 0):
        raise ConfigError("min_half_width_m", f"must be >= 0, got {min_half_width_m!r}")
    return max(0, int(np.ceil(half / tray_width_m - 0.5 - _GRID_TOL)))


def tray_row(mass_kg: np.ndarray, half_trays: int, tray_width_m: float) -> Trays:
    """The row of 2 m + 1 trays of width w centred on the axis (m = `half_trays`) holding `mass_kg`."""
    return Trays(center_m=np.arange(-half_trays, half_trays + 1) * tray_width_m, mass_kg=mass_kg,
                 width_m=tray_width_m)


def bout_tray_counts(widths_m, tray_width_m: float) -> np.ndarray:
    """n = W / w of every bout width W in `widths_m` (int64 array); each must be a positive
    integer to rounding, else a one-line error names the first that is not."""
    w = _check_tray_width(tray_width_m)
    widths = np.asarray(widths_m, dtype=float).reshape(-1)
    with np.errstate(invalid="ignore", over="ignore"):
        ratio = widths / w
        n = np.where(np.isfinite(ratio), np.rint(ratio), 0.0)
        # in metres: the CV curve's widths are rounded to the nanometre (`default_widths_m`), which
        # for a tray width with more decimals moves the ratio by more than _GRID_TOL
        bad = (n < 1) | ~(np.abs(widths - n * w) <= _GRID_TOL * np.maximum(1.0, widths))
    if bad.any():
        raise ConfigError("pattern.target_swath_m", f"bout width {float(widths[np.argmax(bad)])!r} m is not a "
                                                    f"positive multiple of the tray width {w} m")
    return n.astype(np.int64)


@lru_cache(maxsize=256)
def fold_pairs_cached(tray_count: int, counts: tuple, driving: str) -> tuple[np.ndarray, np.ndarray]:
    """`fold_pairs` for a tuple of counts, computed once per (T, counts, driving): the
    runs of a batch share their rows and widths. The arrays are read-only."""
    tray, column = fold_pairs(tray_count, np.asarray(counts, dtype=np.int64), driving)
    tray, column = np.ascontiguousarray(tray, dtype=np.int64), np.ascontiguousarray(column, dtype=np.int64)
    tray.flags.writeable = column.flags.writeable = False
    return tray, column


def fold_pairs(tray_count: int, counts: np.ndarray, driving: str) -> tuple[np.ndarray, np.ndarray]:
    """How a row of T trays (centred on the axis) overlaps into bouts of counts[j] trays,
    the bouts side by side (bout j starts at column sum(columns[:j]), `bout_columns`):
    every (tray index 0..T-1, column) where tray i adds its mass to the bout.

    Bout tray q sits at grid index k_q = q - n // 2 (centres in [-W/2, W/2), or up to
    3W/2 for a back-and-forth period).
    Racetrack: tray i reaches k when k = i (mod n), so q = (i + n // 2) mod n.
    Back-and-forth: unmirrored passes (even j) put tray i at k = i + j n, i.e.
    k = i (mod 2n); mirrored passes (odd j) put it at k = j n - i, i.e.
    k = n - i (mod 2n); so q = (i + n // 2) mod 2n and q = (n - i + n // 2) mod 2n,
    each where q < n, or with n even where q < 2n (the bout is the period:
    `bout_columns`, so bout j starts at the sum of the earlier bouts' columns). The
    pairs come bout by bout, each tray in turn (back-and-forth: the unmirrored passes'
    trays, then the mirrored passes'): `bout_cvs` adds them in this order."""
    return fold_pair_arrays(int(tray_count), np.asarray(counts, dtype=np.int64), driving == "racetrack")


@KERNEL
def bout_columns(counts, racetrack):
    """The trays that stand for a bout of counts[j] trays in the fold (int64 array):
    counts[j], or for back-and-forth with counts[j] even the whole period of 2 counts[j]
    trays. An even strip centred on a pass holds one kind of bout's midline tray and not
    the other's, so its CV would depend on which way the pattern is skewed; the period
    holds every value of the field twice but its two midlines once, and `row_cv` weighs
    them so (with n odd the strip already holds every value once)."""
    columns = counts.copy()
    if not racetrack:
        for j in range(counts.size):
            if counts[j] % 2 == 0:
                columns[j] = 2 * counts[j]
    return columns


@KERNEL
def fold_pair_arrays(tray_count, counts, racetrack):
    """`fold_pairs` in compiled code, for kernels that fold rows themselves
    (spreadgym.spread.finish_kernel); `racetrack` False: back-and-forth."""
    m = tray_count // 2
    columns = bout_columns(counts, racetrack)
    tray = np.empty(2 * tray_count * counts.size, dtype=np.int64)
    column = np.empty(tray.size, dtype=np.int64)
    p = 0
    start = 0
    for j in range(counts.size):
        n, c = counts[j], columns[j]
        if racetrack:
            for t in range(tray_count):
                tray[p] = t
                column[p] = start + (t - m + n // 2) % n
                p += 1
        else:
            for t in range(tray_count):  # unmirrored passes
                q = (t - m + n // 2) % (2 * n)
                if q < c:
                    tray[p] = t
                    column[p] = start + q
                    p += 1
            for t in range(tray_count):  # mirrored passes
                q = (n - (t - m) + n // 2) % (2 * n)
                if q < c:
                    tray[p] = t
                    column[p] = start + q
                    p += 1
        start += c
    return tray[:p], column[:p]


def _fold_matrix(tray_count: int, n: int, driving: str) -> np.ndarray:
    """(C, T) matrix M with bout = M @ tray_masses (`fold_pairs` for one bout; C = n,
    or 2n for a back-and-forth period: `bout_columns`)."""
    tray, column = fold_pairs(tray_count, np.array([n]), driving)
    matrix = np.zeros((int(bout_columns(np.array([n]), driving == "racetrack")[0]), tray_count))
    np.add.at(matrix, (column, tray), 1.0)
    return matrix


def bout_pattern(trays: Trays, bout_width_m: float, driving: str) -> np.ndarray:
    """The overlapped distribution over one bout (n = W / w values, kg per tray,
    left to right, tray centres (q - n // 2) * w for q = 0..n-1; for back-and-forth
    with n even the period, q = 0..2n-1: `bout_columns`). Its mean is the field's."""
    _check_driving(driving)
    n = bout_tray_count(bout_width_m, trays.width_m)
    return _fold_matrix(trays.count, n, driving) @ trays.mass_kg


@KERNEL
def row_cv(values, trays) -> float:
    """CV in % of a bout of `trays` trays given as the 1-D `values`: its `trays` values,
    or a back-and-forth period of 2 `trays` (`bout_columns`). 100 s / mean, sums in
    order, s with ddof = 1 over the bout: the sum of squares over (trays - 1), for a
    period over 2 (trays - 1) (each tray of the period weighs 1/2); 0 for one tray; NaN
    where the mean is not > 0 (no mass). Compiled: the estimate's kernel
    (`estimate.bout_cvs`) calls it for every bout."""
    size = values.size
    total = 0.0
    for i in range(size):
        total += values[i]
    mean = total / size
    if not mean > 0.0:
        return math.nan
    if trays == 1:
        return 0.0
    spread = 0.0
    for i in range(size):
        spread += (values[i] - mean) * (values[i] - mean)
    return 100.0 * math.sqrt(spread / ((trays - 1) * (size // trays))) / mean


def cv_percent(trays: Trays, bout_width_m: float, driving: str) -> float:
    """Coefficient of variation (%) of the overlapped pattern over one bout."""
    return float(row_cv(bout_pattern(trays, bout_width_m, driving), bout_tray_count(bout_width_m, trays.width_m)))


def default_widths_m(trays: Trays) -> np.ndarray:
    """Every multiple of the tray width from one tray up to the symmetric reach of
    the pattern, (2 max|i| + 1) w over loaded trays: at least the pattern width and
    at most about twice it. Beyond it neighbouring passes no longer meet."""
    top = 2 * trays.reach_trays + 1
    return np.round(np.arange(1, top + 1) * trays.width_m, 9)  # widths as the grid gives them, not 0.8999...


def cv_curve(
    trays: Trays, driving: str, widths_m: Optional[Sequence[float]] = None
) -> tuple[np.ndarray, np.ndarray]:
    """(widths, CV %) over bout widths (default: `default_widths_m`)."""
    _check_driving(driving)
    widths = default_widths_m(trays) if widths_m is None else np.asarray(widths_m, dtype=float).reshape(-1)
    cvs = np.array([cv_percent(trays, W, driving) for W in widths])
    return widths, cvs


def effective_swath_m(trays: Trays, driving: str, threshold_percent: float,
                      widths_m: Optional[Sequence[float]] = None) -> float:
    """The largest bout width whose CV is at or below threshold_percent (0.0 if
    none). Non-monotone curves: the largest satisfying width wins, even if some
    narrower widths fail. One tray's CV is 0 whatever the pattern, so a run where
    anything lands has a swath of at least one tray (`report.swath_text` calls a
    swath under two trays none)."""
    return swath_from_curve(*cv_curve(trays, driving, widths_m), threshold_percent)


def swath_from_curve(widths_m: np.ndarray, cvs_percent: np.ndarray, threshold_percent: float) -> float:
    """The largest width of a computed CV curve whose CV meets the threshold (0.0 if none)."""
    thr = float(threshold_percent)
    if not (np.isfinite(thr) and thr > 0):
        raise ConfigError("pattern.cv_threshold_percent", f"must be > 0, got {threshold_percent!r}")
    ok = np.isfinite(cvs_percent) & (cvs_percent <= thr * (1.0 + 1e-12))
    return float(widths_m[ok].max()) if ok.any() else 0.0
