"""90 % intervals from the profile likelihood, and which parameters the test determines.

Profile of key j: the least sum of squared standardised residuals S_j(t) with u_j = t
held and every other key refitted. With the catch noise estimated from the same n trays
(p = keys + 1 fitted, the scale included), the interval is the profile-t one of
nonlinear regression: { t : S_j(t) - S_min <= F(1, n - p; 0.9) n / (n - p) } (exact for
a linear model with Gaussian noise; the factor n / (n - p) undoes the maximum-likelihood
sigma's shrinkage). The profile is walked out from the estimate on both sides until it
crosses that level or meets the search bound; the crossing is interpolated on the
signed root of S_j - S_min, which a near-linear model makes linear. The simulation's own
Monte Carlo error, the same at every point under common random numbers, is added in
quadrature (`simulation_sd`): on the field scene at 4096 granules it is as large as the
catch noise's part, and without it 18 of 30 one-key intervals held the truth. So is the
fit model's measured discrepancy from the full model (`model_sd`, `spreadgym.fit.discrepancy`).

A key is identifiable when its interval covers at most IDENTIFIABLE_SHARE of its search
range and the vane friction turns at most REGIME_SWITCH of the granules between sliding
and rolling inside it (`determined`, `spreadgym.fit.regime`). Trade-offs come from the
Gauss-Newton information J'J at the estimate: the correlation of each pair, and the
weakest direction (the eigenvector of the smallest eigenvalue), which a flat ridge such
as drag coefficient x air density shows at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.stats import f as f_distribution
from scipy.stats import t as t_distribution

from spreadgym.fit.likelihood import residuals
from spreadgym.fit.optimise import Minimum, Objective, central_jacobian, minimise
from spreadgym.fit.regime import switched

LEVEL = 0.90
IDENTIFIABLE_SHARE = 0.5  # an interval over half the search range: the test does not determine the key
REGIME_SWITCH = 0.03  # share of the granules the vane friction may turn over inside an identifiable interval:
# the compiled and the full model disagree on the regime of 0.014-0.030 of the same granules at the same parameters
# (shipped scenes, free rotation, vane friction 0.3-0.6), which the stored discrepancy carries; more is not carried
TRADE_OFF_CORRELATION = 0.9  # |correlation| at or above this: the pair trades off
INFORMATION_STEP = 0.05  # unit cube: the information describes the region at the interval's scale, and
# smaller steps let the granules' jumps between trays blur an exact ridge (correlation -0.87 at 1024 granules
# and a 0.02 step where drag coefficient x air density is exactly flat; -0.98 at 0.05)
MAX_STEPS = 12  # profile points per side
MIN_STEP, MAX_STEP = 0.01, 0.25  # unit-cube steps


@dataclass(frozen=True)
class Interval:
    low: float  # unit cube
    high: float
    low_point: np.ndarray  # (d,) the profile's whole point at each end (for propagating the band)
    high_point: np.ndarray
    low_open: bool  # the profile stayed below the level up to the search bound
    high_open: bool
    lowest: Minimum  # the lowest point the profile met (below the estimate: the fit stopped short)


def threshold(trays: int, keys: int) -> float:
    """The rise of S over its minimum that bounds the 90 % profile-t interval."""
    dof = trays - keys - 1
    if dof < 1:
        return float("inf")
    return float(f_distribution.ppf(LEVEL, 1, dof) * trays / dof)


def jacobian(objective: Objective, best: Minimum) -> np.ndarray:
    """d standardised residuals / d u at the estimate; J'J is the Gauss-Newton information."""
    return central_jacobian(objective, best.unit, step=INFORMATION_STEP)


def simulation_sd(objective: Objective, best: Minimum, jac: np.ndarray) -> np.ndarray:
    """(d,) unit-cube s.d. of the estimate from the simulation's own Monte Carlo error.

    Common random numbers fix one sample of granules for every point, so its error is
    the same everywhere, and part of it looks like a parameter change (a sample whose
    granules run a little fast stretches the pattern as a lower restitution would). The
    delete-one-replicate jackknife over the K independent replicates measures it: each
    replicate left out moves the Gauss-Newton estimate by -(J'J)^+ J' dr_k."""
    model, sigma = objective.model, objective.sigma
    prediction = model.predict([best.unit])[0]
    base, _ = residuals(model.log_mass, prediction, sigma)
    step = np.linalg.pinv(jac.T @ jac) @ jac.T
    k = prediction.replicate_kg.shape[0]
    if k < 2:
        return np.zeros(best.unit.size)
    moves = np.array([-step @ (residuals(model.log_mass, prediction.leave_out(i), sigma)[0] - base)
                      for i in range(k)])
    return np.sqrt((k - 1) / k * np.sum((moves - moves.mean(axis=0)) ** 2, axis=0))


def model_sd(objective: Objective, best: Minimum, jac: np.ndarray, delta: np.ndarray,
             variance: np.ndarray) -> np.ndarray:
    """(d,) unit-cube s.d. of the estimate from the fit model's discrepancy from the full model.

    `delta` (C, n): measured full-minus-compiled log masses on the test's trays at C
    calibration points, `variance` (C, n) their Monte Carlo variances. Data shifted by a
    discrepancy move the Gauss-Newton estimate by (J'J)^+ J' L delta, L the standardised
    residuals' linear map (the log scale profiled out); the mean square of the C moves,
    less their mean Monte Carlo variance, estimates the squared model error (clipped at 0)."""
    prediction = objective.model.predict([best.unit])[0]
    root_w = 1.0 / np.sqrt(objective.sigma ** 2 + prediction.variance)
    weight = root_w ** 2
    # L = diag(root_w) (I - 1 w' / sum w), applied without forming the (n, n) matrix
    step = np.linalg.pinv(jac.T @ jac) @ jac.T * root_w  # (d, n)
    move = step - np.outer(step.sum(axis=1), weight / weight.sum())  # (d, n)
    moves = np.asarray(delta) @ move.T  # (C, d)
    noise = np.asarray(variance) @ (move ** 2).T  # (C, d)
    return np.sqrt(np.clip(np.mean(moves ** 2, axis=0) - np.mean(noise, axis=0), 0.0, None))


def determined(low: float, high: float, switch: float) -> bool:
    """Whether the test determines a key whose interval is [low, high] (unit cube) and
    between whose ends the vane friction turns the share `switch` of the granules from
    sliding to rolling or back (`regime_switches`): the interval covers at most
    IDENTIFIABLE_SHARE of the search range and at most REGIME_SWITCH of the granules change
    regime inside it. Where more do, the interval places the fit model's change of regime,
    which the full model makes at another friction (`spreadgym.fit.regime`)."""
    return bool(high - low <= IDENTIFIABLE_SHARE and switch <= REGIME_SWITCH)


def regime_switches(objective: Objective, intervals: Sequence[Interval], low: Sequence[float],
                    high: Sequence[float], regime_keys: Sequence[int]) -> np.ndarray:
    """(d,) per key j, the share of the granules whose regime the keys that set the roll's
    limits (vane friction, rolling resistance: coordinates `regime_keys`) change between
    its interval's two ends: the profile's low end (key j moved to `low`[j], unit cube)
    against the same point with those coordinates moved to their values at the high end
    (key j at `high`[j]); all simulated in one batch. Zeros when none is fitted: the regime
    then does not move with the fit."""
    if not regime_keys:
        return np.zeros(len(intervals))
    pairs = []
    for j, interval in enumerate(intervals):
        start, end = interval.low_point.copy(), interval.high_point.copy()
        start[j], end[j] = low[j], high[j]
        moved = start.copy()
        moved[list(regime_keys)] = end[list(regime_keys)]
        pairs += [start, moved]
    runs = objective.model.predict(pairs)
    return np.array([switched(runs[2 * j].rolling, runs[2 * j + 1].rolling) for j in range(len(intervals))])


def widened(estimate: float, low: float, high: float, parts: Sequence[tuple[float, int]]) -> tuple[float, float]:
    """The profile interval's two half-widths combined in quadrature with further error parts,
    each an s.d. (unit cube) and its degrees of freedom (Student t): the simulation's Monte
    Carlo part (K - 1 for the jackknife), the model's discrepancy (C calibration points);
    clipped to the cube."""
    q = float(np.hypot.reduce([0.0] + [float(t_distribution.ppf(0.5 + LEVEL / 2, max(dof, 1))) * sd
                                       for sd, dof in parts]))
    return (max(0.0, estimate - float(np.hypot(estimate - low, q))),
            min(1.0, estimate + float(np.hypot(high - estimate, q))))


def profile_interval(objective: Objective, best: Minimum, j: int, level: float, info: np.ndarray) -> Interval:
    """The profile interval of coordinate `j` (see the module's docstring)."""
    d = best.unit.size
    free = np.ones(d, bool)
    free[j] = False
    try:
        wald = float(np.sqrt(level * np.linalg.inv(info)[j, j])) if np.isfinite(level) else 1.0
    except np.linalg.LinAlgError:
        wald = 1.0
    if not np.isfinite(wald) or wald <= 0:
        wald = 1.0
    # the valley's direction: how the other coordinates follow u_j at the Gauss-Newton optimum,
    # so each profile point starts on the ridge, not across it (friction and restitution correlate ~0.8)
    follow = -np.linalg.pinv(info[np.ix_(free, free)]) @ info[free, j]
    lowest = best
    ends = []
    for sign in (-1.0, 1.0):
        step = float(np.clip(0.5 * wald, MIN_STEP, MAX_STEP))
        previous, previous_rise = best.unit, 0.0
        end = None
        for _ in range(MAX_STEPS):
            t = float(np.clip(previous[j] + sign * step, 0.0, 1.0))
            start = previous.copy()
            start[j] = t
            start[free] = np.clip(previous[free] + (t - previous[j]) * follow, 0.0, 1.0)
            here = _profile_point(objective, start, free)
            lowest = here if here.cost < lowest.cost else lowest
            rise = max(here.cost - best.cost, 0.0)
            if rise >= level:
                guess = _crossing(previous, previous_rise, here.unit, rise, level)
                probe = _profile_point(objective, guess, free)  # one secant step: the walk's steps are coarse
                probe_rise = max(probe.cost - best.cost, 0.0)
                if probe_rise >= level:
                    end = _crossing(previous, previous_rise, probe.unit, probe_rise, level), False
                else:
                    end = _crossing(probe.unit, probe_rise, here.unit, rise, level), False
                break
            if t in (0.0, 1.0):
                end = here.unit, True
                break
            if rise < 0.25 * level:
                step = min(2.0 * step, MAX_STEP)
            previous, previous_rise = here.unit, rise
        ends.append(end if end is not None else (previous, True))
    (low_point, low_open), (high_point, high_open) = ends
    return Interval(float(low_point[j]), float(high_point[j]), low_point, high_point, low_open, high_open, lowest)


def _profile_point(objective: Objective, start: np.ndarray, free: np.ndarray) -> Minimum:
    """The profile at `start`'s fixed coordinate: the other coordinates refitted from `start`."""
    return minimise(objective, [start], free) if free.any() else Minimum(start, objective.cost(start))


def _crossing(inside: np.ndarray, inside_rise: float, outside: np.ndarray, outside_rise: float,
              level: float) -> np.ndarray:
    """The point between two profile points where the rise meets `level` (linear in its root)."""
    a, b = np.sqrt(inside_rise), np.sqrt(outside_rise)
    w = (np.sqrt(level) - a) / (b - a) if b > a else 1.0
    return inside + float(np.clip(w, 0.0, 1.0)) * (outside - inside)


def correlations(info: np.ndarray) -> np.ndarray:
    """Correlation matrix from the information (pseudo-inverse where it is singular)."""
    cov = np.linalg.pinv(info)
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    return np.clip(cov / np.outer(sd, sd), -1.0, 1.0)


def weakest_direction(info: np.ndarray) -> tuple[np.ndarray, float]:
    """The unit-cube direction the test determines least (first nonzero entry positive) and
    its eigenvalue of the information (0 on an exact ridge)."""
    values, vectors = np.linalg.eigh(info)
    vector = vectors[:, 0]
    vector = vector * (1.0 if vector[np.flatnonzero(np.abs(vector) > 1e-12)[0]] > 0 else -1.0)
    return vector, float(values[0])
