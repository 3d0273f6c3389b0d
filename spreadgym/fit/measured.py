"""The tray test's own pattern and CV, to show beside the fitted model's.

The measured trays, each pass in its own frame (`likelihood.pass_frame`; trays of
several passes at one place averaged), are read onto the fitted row's tray grid
(multiples of `pattern.tray_width_m`): a grid tray between two measured trays takes the
linear interpolation of their catches, one outside the measured span nothing. On a
complete regular test (every tray of the row weighed) that is the test itself; on a
spaced kit it fills the gaps with straight lines. The CV is then computed as `simulate`
computes it (`spreadgym.spread.estimate.cv_curve`, one replicate: the plain CV of the
overlapped bout) at the widths of the fitted CV curve.

Filling gaps and taking nothing outside assume the trays span the pattern: the
measured CV is given only where the fitted single pass has at least
MIN_SPANNED_SHARE of its mass inside the measured span (else None, and the share says
why).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.fit.likelihood import pass_frame
from spreadgym.fit.trays import TrayTest
from spreadgym.spread import estimate

MIN_SPANNED_SHARE = 0.95  # of the fitted single pass's mass, inside the measured trays' span


@dataclass(frozen=True)
class MeasuredPattern:
    """The measured single pass on the fitted row's grid and its CV curve."""

    center_m: np.ndarray  # (T,) the grid
    mass_g: np.ndarray  # (T,) measured (interpolated between measured trays, 0 outside their span)
    spanned_share: float  # the fitted single pass's mass inside the measured span
    cv_percent: Optional[np.ndarray]  # (W,) at the fitted curve's widths; None: the trays do not span the pattern
    cv_percent_at_target: Optional[float]


def measured_pattern(test: TrayTest, scene: Scene, center_m: np.ndarray, fitted_g: np.ndarray,
                     widths_m: np.ndarray) -> MeasuredPattern:
    """The measured pattern of `test` on the grid `center_m` (odd, centred on the axis) of
    the fitted single pass `fitted_g` (g per tray), and its CV at `widths_m`."""
    p = scene.pattern
    local = np.round(pass_frame(test, scene), 9)
    places, where = np.unique(local, return_inverse=True)
    mean_g = np.bincount(where, weights=1e3 * test.mass_kg) / np.bincount(where)
    tolerance = 1e-9 * max(1.0, p.tray_width_m)
    inside = (center_m >= places[0] - tolerance) & (center_m <= places[-1] + tolerance)
    grid_g = np.where(inside, np.interp(center_m, places, mean_g), 0.0)
    total = float(np.sum(fitted_g))
    spanned = float(np.sum(fitted_g[inside]) / total) if total > 0 else 0.0
    if spanned < MIN_SPANNED_SHARE or not grid_g.sum() > 0:
        return MeasuredPattern(center_m, grid_g, spanned, None, None)
    widths = np.asarray(widths_m, dtype=float)
    cv = estimate.cv_curve(grid_g[None, :], p.tray_width_m, p.driving, widths)[0]
    at_target = estimate.cv_curve(grid_g[None, :], p.tray_width_m, p.driving, np.array([p.target_swath_m]))[0][0]
    return MeasuredPattern(center_m, grid_g, spanned, cv, float(at_target) if np.isfinite(at_target) else None)
