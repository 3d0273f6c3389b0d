"""The likelihood of a tray test given a simulated pattern: catch noise on the shape.

A tray test measures the shape of the pattern, not the rate (how much the machine let
out during the pass is rarely known), so the scale is free. Per tray i with a catch
(m_i > 0):

    log m_i = a + log mu_i(theta) + e_i,   e_i ~ N(0, s_i^2),   s_i^2 = sigma^2 + v_sim,i + v_count,i

* mu_i(theta): the simulated single-pass mass under tray i (pass lanes shifted and,
  for back-and-forth driving, mirrored), plus half a landing sample's mass so an
  empty simulated tray stays finite;
* a: the log scale, profiled out (weighted mean of the residuals);
* sigma: the multiplicative catch noise (tray placement, losses, weighing), unknown,
  estimated from the residuals;
* v_sim,i: the relative variance of mu_i, its Monte Carlo error (fixed across theta by
  common random numbers: sim.seed fixed), c / mu_i with c pooled over the trays from the
  simulation's independent replicates;
* v_count,i = m_g / m_i: the counting noise of a tray holding m_i / m_g granules
  (m_g the mass-weighted mean granule mass of the scene's fertilizer).
Trays that caught nothing carry no log-shape and are left out of the sum.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from spreadgym.config.base import brief
from spreadgym.config.scene import MAX_GRANULE_COPIES, Scene, granule_copies, scene_with
from spreadgym.errors import SpreadgymError
from spreadgym.fit.regime import rolling
from spreadgym.fit.space import FitSpace
from spreadgym.fit.trays import TrayTest
from spreadgym.spread.batch import run_batch
from spreadgym.spread.pipeline import SimulationResult

SIGMA_BOUNDS = (1e-3, 3.0)  # catch noise s.d. of log mass: 0.1 % .. 300 %
SOFT_WIDTH = 0.25  # landing spread, in trays (see soft_tray_masses)
MIN_COVERED_SHARE = 0.9  # of the measured mass, in trays the simulated pattern reaches; below it the model
# does not describe the test (trays on the wrong axis or pass, or settings the test was not made at). A test
# made by the model itself leaves only its outermost grams uncovered (stray granules the fit's sample missed)


@dataclass(frozen=True)
class Prediction:
    """A simulated pattern on the measured trays (the rows that caught something)."""

    log_mu: np.ndarray  # (n,) log simulated mass, kg (floored)
    variance: np.ndarray  # (n,) v_sim + v_count, relative (log scale)
    replicate_kg: np.ndarray  # (K, n) each independent replicate's share of the simulated mass
    floor_kg: float  # added to every tray's mass (half a landing sample)
    rolling: np.ndarray  # (N,) bool: each simulated granule left its disc rolling (regime.rolling)
    covered_share: float  # share of the measured mass in trays where any simulated landing fell

    def leave_out(self, k: int) -> "Prediction":
        """The prediction from every replicate but `k` (rescaled to all K), same variances."""
        count = self.replicate_kg.shape[0]
        kept = (self.replicate_kg.sum(axis=0) - self.replicate_kg[k]) * count / (count - 1)
        return Prediction(np.log(kept + self.floor_kg), self.variance, self.replicate_kg, self.floor_kg, self.rolling,
                          self.covered_share)


class PatternModel:
    """Simulated patterns of `scene` at points of `space`, on the trays of `test`.

    Every evaluation uses the same granules (the scene's sim.seed): common random numbers,
    so the likelihood changes smoothly with the parameters. Results are cached by point."""

    def __init__(self, scene: Scene, space: FitSpace, test: TrayTest, model: str = "auto"):
        self.scene, self.space, self.test, self.model = scene, space, test, model
        caught = test.mass_kg > 0
        self.rows = np.flatnonzero(caught)
        self.log_mass = np.log(test.mass_kg[caught])
        self.local_x_m = pass_frame(test, scene)[caught]
        self.evaluations = 0
        self._cache: dict[tuple, Prediction] = {}

    @property
    def trays(self) -> int:
        return int(self.rows.size)

    def scene_at(self, unit: Sequence[float]) -> Scene:
        return scene_with(self.scene, self.space.overrides(unit))

    def predict(self, units: Sequence[Sequence[float]]) -> list[Prediction]:
        """Predictions at unit-cube points, the uncached ones simulated in batches of at
        most MAX_GRANULE_COPIES landing points (as `simulate` pools its runs: the memory
        of a batch stays bounded whatever the granules and the design's size)."""
        keys = [_key(u) for u in units]
        todo = list(dict.fromkeys(k for k in keys if k not in self._cache))
        size = max(1, MAX_GRANULE_COPIES // granule_copies(self.scene))
        for first in range(0, len(todo), size):
            chunk = todo[first:first + size]
            results = run_batch([self.scene_at(k) for k in chunk], model=self.model, ci=False)
            self.evaluations += len(chunk)
            for key, result in zip(chunk, results):
                self._cache[key] = self.prediction(result)
        return [self._cache[k] for k in keys]

    def prediction(self, result: SimulationResult) -> Prediction:
        """A run's pattern on the measured trays, with its Monte Carlo and counting variances."""
        sample = result.sample
        k = int(result.granules.replicate.max()) + 1
        per = soft_tray_masses(sample.x_m, sample.mass_kg, sample.replicate, k, self.local_x_m,
                               self.scene.pattern.tray_width_m)
        pooled = per.sum(axis=0)
        floor = 0.5 * float(np.mean(sample.mass_kg)) if sample.mass_kg.size else 1e-12
        # Monte Carlo variance of a tray's mass, proportional to the mass (as for a count), the
        # factor pooled over the trays: one tray's own estimate from K - 1 = 7 degrees of freedom
        # is too rough to weigh it by (its inverse is 40 % too large on average)
        spread = k / (k - 1) * np.sum((per - pooled / k) ** 2, axis=0) if k > 1 else pooled ** 2
        per_kg = float(spread.sum() / pooled.sum()) if pooled.sum() > 0 else floor
        mu = pooled + floor
        v_sim = (per_kg * mu + floor ** 2) / mu ** 2
        masses = result.granules.mass_kg
        granule_kg = float(np.sum(masses ** 2) / np.sum(masses))  # mass-weighted mean granule mass
        measured = self.test.mass_kg[self.rows]
        v_count = granule_kg / measured
        covered = float(measured[pooled > 0].sum() / measured.sum())
        return Prediction(np.log(mu), v_sim + v_count, per, floor, rolling(result), covered)


def check_covered(prediction: Prediction, test: TrayTest, where: str) -> None:
    """Refuse a fit whose simulated pattern misses the measured mass (`MIN_COVERED_SHARE`)."""
    if not prediction.covered_share >= MIN_COVERED_SHARE:
        raise SpreadgymError(
            f"--trays: {brief(test.source)}: {100 * prediction.covered_share:.0f} % of the measured mass lies in "
            f"trays the simulated pattern reaches {where}; at least {100 * MIN_COVERED_SHARE:.0f} % must, or the fit "
            "has nothing to fit (check x: 0 on the machine's track, positive to its right; the pass column; the "
            "scene's settings and the --fit ranges; --granules: too few leave trays of the simulated pattern empty)")


def pass_frame(test: TrayTest, scene: Scene) -> np.ndarray:
    """(n,) each tray's centre in its own pass's frame (m): pass j shifted by j W and, for
    back-and-forth driving, mirrored on odd j, so every row sits on the single pass."""
    p = scene.pattern
    local = test.x_m - test.lane * p.target_swath_m
    mirrored = (p.driving == "back-and-forth") & (test.lane % 2 == 1)
    return np.where(mirrored, -local, local)


def soft_tray_masses(x_m: np.ndarray, mass_kg: np.ndarray, replicate: np.ndarray, replicates: int,
                     centre_m: np.ndarray, tray_width_m: float) -> np.ndarray:
    """(K, n) mass of each replicate in trays of width w centred at `centre_m` (any layout,
    gaps and overlaps allowed), each landing spread evenly over SOFT_WIDTH * w across the
    track, so a landing that moves with the parameters passes its mass from tray to tray
    (or into a gap) continuously instead of in one jump (the fit's objective is then
    smooth at the scale of its steps; the blur changes a tray's catch by about
    (SOFT_WIDTH w)^2 / 24 times the pattern's curvature).

    A tray [a, b) catches F(b) - F(a), F(t) = sum of m_j clip((t - s_j) / h, 0, 1) over
    the landings (s_j the left end of landing j's spread, h its width): with A(t) and
    B(t) the mass and first moment of the landings with s_j <= t,
    F(t) = A(t - h) + (t (A(t) - A(t - h)) - (B(t) - B(t - h))) / h. A and B are read at
    the 4 n points t and t - h of the tray edges only, so the work is O(N log n) and the
    memory O(K n) however far apart the trays lie."""
    h = SOFT_WIDTH * tray_width_m
    centre = np.asarray(centre_m, dtype=float)
    edges = np.concatenate([centre - 0.5 * tray_width_m, centre + 0.5 * tray_width_m])
    queries = np.unique(np.concatenate([edges, edges - h]))
    start = np.asarray(x_m, dtype=float) - 0.5 * h
    slot = np.searchsorted(queries, start, side="left")  # landing j counts at every query q_k >= s_j: k >= slot
    size = queries.size + 1
    flat = np.asarray(replicate, dtype=np.int64) * size + slot
    mass = np.asarray(mass_kg, dtype=float)
    below = [np.cumsum(np.bincount(flat, weights=w, minlength=replicates * size).reshape(replicates, size),
                       axis=1)[:, :queries.size] for w in (mass, mass * start)]  # A(q_k), B(q_k) per replicate

    def caught_below(t: np.ndarray) -> np.ndarray:
        at, back = np.searchsorted(queries, t), np.searchsorted(queries, t - h)
        (a, a_back), (b, b_back) = ((m[:, at], m[:, back]) for m in below)
        return a_back + (t * (a - a_back) - (b - b_back)) / h

    n = centre.size
    caught = caught_below(edges)
    return np.maximum(caught[:, n:] - caught[:, :n], 0.0)


def _key(unit: Sequence[float]) -> tuple:
    return tuple(round(float(u), 12) for u in np.clip(unit, 0.0, 1.0))


def residuals(y: np.ndarray, prediction: Prediction, sigma: float) -> tuple[np.ndarray, float]:
    """Standardised residuals (y - a - log mu) / s with the log scale `a` profiled out; and `a`."""
    weight = 1.0 / (sigma ** 2 + prediction.variance)
    gap = y - prediction.log_mu
    a = float(np.sum(weight * gap) / np.sum(weight))
    return (gap - a) * np.sqrt(weight), a


def catch_sigma(y: np.ndarray, prediction: Prediction) -> float:
    """Maximum-likelihood catch-noise s.d. (log scale) at one prediction."""
    def nll(log_sigma: float) -> float:
        sigma = float(np.exp(log_sigma))
        r, _ = residuals(y, prediction, sigma)
        return float(np.sum(r ** 2) + np.sum(np.log(sigma ** 2 + prediction.variance)))

    lo, hi = np.log(SIGMA_BOUNDS)
    return float(np.exp(minimize_scalar(nll, bounds=(lo, hi), method="bounded",
                                        options={"xatol": 1e-4}).x))
