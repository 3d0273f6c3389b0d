"""Finding the estimate: a scrambled-Sobol batch over the search box, then bounded
Gauss-Newton (`scipy.optimize.least_squares`, trust-region reflective) from the best
points, with the Jacobian from central differences simulated in one batch.

The catch noise sigma weighs the residuals; it is estimated at the optimum and the
least-squares fit repeated once with it (the weights change little after that).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc

from spreadgym.fit.likelihood import PatternModel, catch_sigma, check_covered, residuals

START_SIGMA = 0.05  # first guess of the catch noise (log s.d.); re-estimated at the optimum
DIFF_STEP = 0.02  # central-difference step in the unit cube: many granules cross a tray edge, so
# the steps see the smooth pattern, not single granules jumping trays
MAX_NFEV = 25  # Gauss-Newton iterations per start


@dataclass
class Objective:
    """Sum of squared standardised residuals of the tray test over the unit cube."""

    model: PatternModel
    sigma: float = START_SIGMA

    def residuals_at(self, units: Sequence[Sequence[float]]) -> list[np.ndarray]:
        return [residuals(self.model.log_mass, p, self.sigma)[0] for p in self.model.predict(units)]

    def cost(self, unit: Sequence[float]) -> float:
        r = self.residuals_at([unit])[0]
        return float(r @ r)


@dataclass(frozen=True)
class Minimum:
    unit: np.ndarray  # (d,) the whole point, fixed coordinates included
    cost: float  # sum of squared standardised residuals


def minimise(objective: Objective, starts: Sequence[np.ndarray], free: Optional[np.ndarray] = None) -> Minimum:
    """Bounded least squares over the `free` coordinates (mask; default all) from each
    start; the best end point. Fixed coordinates keep each start's values."""
    best: Optional[Minimum] = None
    for start in starts:
        start = np.clip(np.asarray(start, dtype=float), 0.0, 1.0)
        mask = np.ones(start.size, bool) if free is None else np.asarray(free, bool)
        if not mask.any():
            found = Minimum(start, objective.cost(start))
        else:
            found = _least_squares(objective, start, mask)
        if best is None or found.cost < best.cost:
            best = found
    return best


def _least_squares(objective: Objective, start: np.ndarray, mask: np.ndarray) -> Minimum:
    def whole(x: np.ndarray) -> np.ndarray:
        point = start.copy()
        point[mask] = x
        return point

    def fun(x: np.ndarray) -> np.ndarray:
        return objective.residuals_at([whole(x)])[0]

    def jac(x: np.ndarray) -> np.ndarray:
        return central_jacobian(objective, whole(x), mask)

    x0 = np.clip(start[mask], 0.0, 1.0)
    solution = least_squares(fun, x0, jac=jac, bounds=(0.0, 1.0), method="trf", x_scale=1.0, max_nfev=MAX_NFEV,
                             xtol=1e-4, ftol=1e-6)
    point = whole(solution.x)
    return Minimum(point, objective.cost(point))


def central_jacobian(objective: Objective, point: np.ndarray, mask: Optional[np.ndarray] = None,
                     step: float = DIFF_STEP) -> np.ndarray:
    """d residuals / d u over the `mask` coordinates: central differences of `step` (unit
    cube; one-sided at a bound), all 2 d points simulated in one batch. (n, d_free)."""
    mask = np.ones(point.size, bool) if mask is None else mask
    columns = np.flatnonzero(mask)
    points = []
    for j in columns:
        up, down = point.copy(), point.copy()
        up[j] = min(1.0, point[j] + step)
        down[j] = max(0.0, point[j] - step)
        points += [up, down]
    values = objective.residuals_at(points)
    jac = np.empty((values[0].size, columns.size))
    for c, j in enumerate(columns):
        up, down = points[2 * c], points[2 * c + 1]
        jac[:, c] = (values[2 * c] - values[2 * c + 1]) / (up[j] - down[j])
    return jac


def sobol_points(dims: int, seed: int) -> np.ndarray:
    """A scrambled Sobol design over the unit cube: 2^m >= 8 d + 8 points."""
    m = int(np.ceil(np.log2(8 * dims + 8)))
    return qmc.Sobol(dims, scramble=True, seed=seed).random_base2(m)


def fit(model: PatternModel, seed: int = 0, starts: int = 2) -> tuple[Objective, Minimum]:
    """The estimate: the best of a Sobol design (one batch), refined from the `starts` best
    design points that are at least 0.25 apart in the unit cube; then sigma estimated and
    the refinement repeated from the optimum."""
    objective = Objective(model)
    design = sobol_points(model.space.dims, seed)
    costs = np.array([r @ r for r in objective.residuals_at(list(design))])
    check_covered(max(model.predict(list(design)), key=lambda p: p.covered_share), model.test,
                  "at any point of the start design over the search box")
    chosen: list[np.ndarray] = []
    for i in np.argsort(costs, kind="stable"):
        if all(np.max(np.abs(design[i] - c)) >= 0.25 for c in chosen):
            chosen.append(design[i])
        if len(chosen) == starts:
            break
    best = minimise(objective, chosen)
    objective.sigma = catch_sigma(model.log_mass, model.predict([best.unit])[0])
    best = minimise(objective, [best.unit])
    objective.sigma = catch_sigma(model.log_mass, model.predict([best.unit])[0])
    return objective, Minimum(best.unit, objective.cost(best.unit))
