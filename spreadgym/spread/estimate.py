"""An unbiased estimate of the tray-test CV from independent randomised replicates.

A run's granules come in K independent replicates (independent scrambles of a
randomised quasi-Monte Carlo point set, or plain Monte Carlo draws): each replicate's
tray masses m_k (T,) are an independent, identically distributed estimate, and the
run's pattern is their sum m = sum_k m_k. The overlapped bout at width W is b = F m
(F the (n, T) fold matrix of `pattern.bout_pattern`).

The plain CV of b is biased upwards: with b = beta + e, E[e] = 0, Cov(e) = S,

    E[sum_q (b_q - mean(b))^2] = sum_q (beta_q - mean(beta))^2 + tr(C S),
    E[mean(b)^2]               = mean(beta)^2 + 1' S 1 / n^2,

C = I - 11'/n. Both sampling terms are estimated without bias from the replicates,
whatever the sampler, because b_k = F m_k are i.i.d. with Cov(b) = K Cov(b_k):

    S_hat = K / (K - 1) sum_k (b_k - b/K)(b_k - b/K)'.

The corrected CV is 100 sqrt(max(s2 - tr(C S_hat)/(n - 1), 0) / (mean(b)^2 - 1'S_hat 1/n^2)):
numerator and denominator are each unbiased; the ratio and the root leave a bias of
order 1/N_granules squared relative to the plain CV's order 1/N (checked in the tests
on patterns with a known exact CV). Its standard error is the delete-one-replicate
jackknife over the K replicates (K >= 3), and the 95 % interval uses Student's t with
K - 1 degrees of freedom.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Optional

import numpy as np
from scipy.special import stdtrit

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


def replicate_bouts(replicate_masses: np.ndarray, tray_width_m: float, bout_width_m: float,
                    driving: str) -> np.ndarray:
    """(K, n) overlapped bouts of each replicate's tray masses (K, T) on the centred tray row."""
    masses = np.atleast_2d(np.asarray(replicate_masses, dtype=float))
    tray_count = masses.shape[1]
    n = pattern.bout_tray_count(bout_width_m, tray_width_m)
    return masses @ pattern._fold_matrix(tray_count, n, driving).T


def estimate_cv(replicate_masses: np.ndarray, tray_width_m: float, bout_width_m: float,
                driving: str) -> CvEstimate:
    """Corrected CV, jackknife standard error and plain CV at one bout width.

    `replicate_masses` (K, T): tray masses of each independent replicate on one row of
    T trays centred on the axis (T odd), as `replicate_tray_masses` returns them.
    """
    bouts = replicate_bouts(replicate_masses, tray_width_m, bout_width_m, driving)
    k = bouts.shape[0]
    raw = float(pattern._cv_rows(bouts.sum(axis=0)))
    if not np.isfinite(raw):
        return CvEstimate(None, None, None, None)
    if k < 2:
        return CvEstimate(raw, None, raw, None)
    keep = ~np.eye(k, dtype=bool)  # row j: every replicate but j
    leave_one_out = pattern._cv_rows(np.stack([bouts[row].sum(axis=0) for row in keep]))
    if not np.all(np.isfinite(leave_one_out)):  # a replicate holds all the mass
        return CvEstimate(raw, None, raw, None)
    cv = max(0.0, k * raw - (k - 1) * float(leave_one_out.mean()))
    se = interval = None
    if k >= MIN_REPLICATES_FOR_SE:
        se = float(np.sqrt((k - 1) / k * np.sum((leave_one_out - leave_one_out.mean()) ** 2)))
        half = _t_quantile(k - 1) * se
        interval = (max(0.0, cv - half), cv + half)
    return CvEstimate(cv, se, raw, interval)


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
    numbers of `estimate_cv` width by width (to rounding), in one pass over all widths."""
    masses = np.atleast_2d(np.asarray(replicate_masses, dtype=float))
    k, tray_count = masses.shape
    counts = np.array([pattern.bout_tray_count(w, tray_width_m) for w in widths_m], dtype=np.int64)
    if counts.size == 0:
        return np.zeros(0), np.zeros(0)
    tray, column = pattern.fold_pairs(tray_count, counts, driving)
    total = int(counts.sum())
    flat = (np.arange(k)[:, None] * total + column[None, :]).ravel()
    # (K, sum of n): every width's bout side by side
    bouts = np.bincount(flat, weights=masses[:, tray].ravel(), minlength=k * total).reshape(k, total)
    keep = ~np.eye(k, dtype=bool)  # row j: every replicate but j (summed, not subtracted:
    leave_one_out = keep.astype(float) @ bouts  # a replicate holding all the mass leaves exact zeros)
    rows = _segment_cv(np.vstack([bouts.sum(axis=0), leave_one_out]), counts)
    raw, loo = rows[0], rows[1:]
    cvs, ses = raw.copy(), np.full(raw.shape, np.nan)
    if k < 2:
        return cvs, ses
    usable = np.isfinite(raw) & np.all(np.isfinite(loo), axis=0)
    mean_loo = loo.mean(axis=0)
    cvs[usable] = np.maximum(0.0, k * raw[usable] - (k - 1) * mean_loo[usable])
    if k >= MIN_REPLICATES_FOR_SE:
        spread = np.sqrt((k - 1) / k * np.sum((loo - mean_loo) ** 2, axis=0))
        ses[usable] = spread[usable]
    return cvs, ses


def _segment_cv(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """`pattern._cv_rows` of each row's consecutive segments of the given lengths: (R, len(counts))."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    mean = np.add.reduceat(values, starts, axis=1) / counts
    deviation = values - np.repeat(mean, counts, axis=1)
    spread = np.add.reduceat(deviation * deviation, starts, axis=1)
    sd = np.sqrt(spread / np.maximum(counts - 1, 1))
    safe = np.where(mean > 0, mean, 1.0)
    return np.where(mean > 0, np.where(counts > 1, 100.0 * sd / safe, 0.0), np.nan)
