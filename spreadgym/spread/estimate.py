"""A bias-corrected estimate of the tray-test CV from independent randomised replicates.

A run's granules come in K independent replicates (independent scrambles of a
randomised quasi-Monte Carlo point set, or plain Monte Carlo draws): each replicate's
tray masses m_k (T,) are an independent, identically distributed estimate, and the
run's pattern is their sum m = sum_k m_k. The overlapped bout at width W is b = F m
(F the fold matrix of `pattern.bout_pattern`).

The plain CV of b is biased upwards by the sampling noise (its between-tray variance
and squared mean both carry it); that bias is c/K + O(1/K^2) in the replicates K,
whatever the sampler. The corrected CV removes the first-order term with the
delete-one-replicate jackknife,

    CV_corrected = K CV(all K) - (K - 1) mean_j CV(all but replicate j)   (clipped at 0),

its standard error is the same jackknife's (K >= 3), and the 95 % interval uses
Student's t with K - 1 degrees of freedom. docs/estimate.md, section 3, derives it and
says why the explicit plug-in correction of the variance was not kept (unbiased in the
variance, biased low after the root and noisier); the tests check it on patterns with
a known exact CV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Optional

import numpy as np
from scipy.special import stdtrit

from spreadgym import threads
from spreadgym.physics.compiled.options import KERNEL
from spreadgym.spread import pattern

MIN_REPLICATES_FOR_SE = 3
CONFIDENCE_LEVEL = 0.95


@dataclass(frozen=True)
class CvEstimate:
    """The CV at one bout width (percent); None where no mass landed."""

    cv_percent: Optional[float]  # corrected for the sampling noise of the tray masses
    standard_error_percent: Optional[float]  # jackknife over replicates (None below 3)
    raw_percent: Optional[float]  # the plain tray CV of the pooled pattern
    interval_percent: Optional[tuple[float, float]]  # CONFIDENCE_LEVEL, Student t, K - 1 dof


def estimate_cv(replicate_masses: np.ndarray, tray_width_m: float, bout_width_m: float,
                driving: str) -> CvEstimate:
    """Corrected CV, jackknife standard error and plain CV at one bout width.

    `replicate_masses` (K, T): tray masses of each independent replicate on one row of
    T trays centred on the axis (T odd), as `replicate_tray_masses` returns them.
    """
    masses = _replicate_rows(replicate_masses)
    raw, cv, se, usable = _bout_cvs(masses, pattern.bout_tray_counts([bout_width_m], tray_width_m), driving)
    return estimate_from(float(raw[0]), float(cv[0]), float(se[0]), bool(usable[0]), masses.shape[0])


def estimate_from(raw: float, cv: float, se: float, usable: bool, replicates: int) -> CvEstimate:
    """The `CvEstimate` of one width from `bout_cvs`' figures there, K = `replicates`."""
    if not math.isfinite(raw):
        return CvEstimate(None, None, None, None)
    if not usable:  # one replicate, or one holds all the mass: no correction
        return CvEstimate(raw, None, raw, None)
    if replicates < MIN_REPLICATES_FOR_SE:
        return CvEstimate(cv, None, raw, None)
    half = _t_quantile(replicates - 1) * se
    return CvEstimate(cv, se, raw, (max(0.0, cv - half), cv + half))


@lru_cache(maxsize=None)
def _t_quantile(dof: int) -> float:
    """Two-sided CONFIDENCE_LEVEL quantile of Student's t (cached: scipy's ppf costs ~0.5 ms)."""
    return float(stdtrit(dof, 0.5 + CONFIDENCE_LEVEL / 2))  # scipy.stats.t.ppf, without importing scipy.stats


@dataclass(frozen=True)
class TraySample:
    """What a row of trays catches, per landed granule (or release-angle copy): where it
    lands across the track (m), its mass (kg) and its independent replicate."""

    x_m: np.ndarray
    mass_kg: np.ndarray
    replicate: np.ndarray


def replicate_tray_masses(x_m: np.ndarray, mass_kg: np.ndarray, replicate: np.ndarray, replicates: int,
                          tray_width_m: float, min_half_width_m: float = 0.0) -> tuple[pattern.Trays, np.ndarray]:
    """The pooled `Trays` and the (K, T) tray masses of each replicate on the same row.

    `replicate` (N,) gives each granule's replicate index in 0..replicates-1."""
    trays, per_replicate, _ = pattern.collect_replicates(x_m, mass_kg, replicate, replicates, tray_width_m,
                                                         min_half_width_m)
    return trays, per_replicate


def cv_curve(replicate_masses: np.ndarray, tray_width_m: float, driving: str,
             widths_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corrected CV (%) and its standard error (NaN where unknown) at every width: the
    numbers of `estimate_cv` width by width, to the bit, in one compiled pass."""
    masses = _replicate_rows(replicate_masses)
    counts = pattern.bout_tray_counts(widths_m, tray_width_m)
    if counts.size == 0:
        return np.zeros(0), np.zeros(0)
    return curve_from(*_bout_cvs(masses, counts, driving), masses.shape[0])


def curve_from(raw: np.ndarray, cv: np.ndarray, se: np.ndarray, usable: np.ndarray,
               replicates: int) -> tuple[np.ndarray, np.ndarray]:
    """`cv_curve`'s (CV, s.e.) from `bout_cvs`' figures at every width, K = `replicates`."""
    with_se = usable & (replicates >= MIN_REPLICATES_FOR_SE)
    return np.where(usable, cv, raw), np.where(with_se, se, np.nan)


def _replicate_rows(replicate_masses: np.ndarray) -> np.ndarray:
    """(K, T) float tray masses, C order, T odd."""
    masses = np.ascontiguousarray(np.atleast_2d(np.asarray(replicate_masses, dtype=float)))
    if masses.ndim != 2 or masses.shape[1] % 2 != 1:
        raise ValueError(f"replicate masses must be (K, T) with T odd, got shape {masses.shape}")
    return masses


def _bout_cvs(masses: np.ndarray, counts: np.ndarray, driving: str) -> tuple:
    """`bout_cvs` of the bouts of `counts` trays; the fold pairs come from `pattern.fold_pairs`.
    Where the leave-one-out sums are many (a pooled reference: hundreds of replicates),
    the widths are shared out over spreadgym.threads' threads in runs of about equal work;
    every width's figures are computed alone, so they are the same bits on any count."""
    pattern._check_driving(driving)
    work = masses.shape[0] ** 2 * np.asarray(counts, dtype=float)  # twice each width's leave-one-out additions
    parts = min(threads.thread_count(), counts.size, int(work.sum() // SPLIT_WORK) + 1)
    if parts <= 1:
        return _bout_cvs_of(masses, counts, driving)
    cuts = np.searchsorted(np.cumsum(work), work.sum() * np.arange(1, parts) / parts)
    groups = [group for group in np.split(counts, cuts) if group.size]
    found = threads.thread_map(lambda g: _bout_cvs_of(masses, groups[g], driving), len(groups))
    return tuple(np.concatenate(pieces) for pieces in zip(*found))


SPLIT_WORK = 4e6
"""Work (K^2 x the widths' trays summed; about 1 ms per 4e6 on one core) above which
`_bout_cvs` shares the widths out over threads: a 512-replicate reference's curve (about
4e7) splits, a run's 8 replicates (about 1e4) never do."""


def _bout_cvs_of(masses: np.ndarray, counts: np.ndarray, driving: str) -> tuple:
    tray, column = pattern.fold_pairs_cached(masses.shape[1], tuple(int(n) for n in counts), driving)
    return bout_cvs(masses, tray, column, counts, pattern.bout_columns(counts, driving == "racetrack"))


@KERNEL
def bout_cvs(masses, tray, column, counts, columns):
    """Plain and corrected CV of the overlapped bouts of several widths, from the (K, T)
    tray masses of K replicates: (raw (W,), corrected (W,), jackknife s.e. (W,), usable
    (W,) bool), W = counts.size.

    Bout j has counts[j] trays, held in columns[j] columns (`pattern.bout_columns`), the
    bouts side by side (bout j starts at column sum(columns[:j])); tray `tray[p]` adds
    its mass to column `column[p]` (`pattern.fold_pairs`). raw: `pattern.row_cv` of the pooled bout; with K >= 2, the
    leave-one-out CVs c_i (every replicate but i, summed, not subtracted, so a replicate
    holding all the mass leaves exact zeros) give corrected = max(0, K raw - (K - 1)
    mean c) and s.e. = sqrt((K - 1) / K sum (c_i - mean c)^2). usable: raw and every c_i
    finite, K >= 2 (else corrected and s.e. are NaN). The sum without replicate i is the
    running sum of replicates 0..i-1 (kept from one i to the next) plus i+1..K-1 added in
    order: the same additions in the same order as a fresh sum, at half the work (the
    pooled reference's 512 replicates). Compiled and GIL-free: a batch scores its runs
    side by side on threads."""
    k = masses.shape[0]
    total = 0
    widest = 0
    for j in range(counts.size):
        total += columns[j]
        widest = max(widest, columns[j])
    bouts = np.zeros((k, total))
    for p in range(tray.size):
        for r in range(k):
            bouts[r, column[p]] += masses[r, tray[p]]
    raw = np.full(counts.size, np.nan)
    cv = np.full(counts.size, np.nan)
    se = np.full(counts.size, np.nan)
    usable = np.zeros(counts.size, dtype=np.bool_)
    row = np.empty(widest)
    before = np.empty(widest)  # replicates 0..i-1 summed
    loo = np.empty(k)
    start = 0
    for j in range(counts.size):
        n, c = counts[j], columns[j]
        for q in range(c):
            row[q] = 0.0
            for r in range(k):
                row[q] += bouts[r, start + q]
        raw[j] = pattern.row_cv(row[:c], n)
        finite = k >= 2 and math.isfinite(raw[j])
        before[:c] = 0.0
        for i in range(k if finite else 0):
            for q in range(c):
                row[q] = before[q]
                for r in range(i + 1, k):
                    row[q] += bouts[r, start + q]
                before[q] += bouts[i, start + q]
            loo[i] = pattern.row_cv(row[:c], n)
            finite = finite and math.isfinite(loo[i])
        if finite:
            mean = 0.0
            for i in range(k):
                mean += loo[i]
            mean /= k
            spread = 0.0
            for i in range(k):
                spread += (loo[i] - mean) * (loo[i] - mean)
            cv[j] = max(0.0, k * raw[j] - (k - 1) * mean)
            se[j] = math.sqrt((k - 1) / k * spread)
            usable[j] = True
        start += c
    return raw, cv, se, usable
