"""Converged references: many independent runs of one scene pooled into one tray pattern.

Run j of a reference draws the replicates j R .. (j + 1) R - 1 of the scene's seed
(R = `sim.replicates` per run), so pooling K runs of N granules gives exactly the one
run of K N granules in K R replicates, and the CV's jackknife then rests on all K R
replicates. The landing points are kept per granule (a float, a mass and a replicate
index each; with release-angle copies, per copy), so the pooled tray row is as wide as
the widest landing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError
from spreadgym.physics.granules import replicate_sizes
from spreadgym.spread import estimate, pattern
from spreadgym.spread.batch import run_batch

MIN_RUNS = 2
BATCH_RUNS = 64  # runs evaluated together by `pool_runs`
SE_MULTIPLE_FOR_SWATH = 2.0


@dataclass(frozen=True)
class PooledLandings:
    """Where the granules of all runs landed (across the track) and their replicates."""

    x_m: np.ndarray
    mass_kg: np.ndarray
    replicate: np.ndarray
    replicates: int
    granules: int  # simulated on the spinner, landed or not
    angle_copies: int  # release angles per simulated granule (spread.rotations)
    released_kg: float
    model: str
    model_reason: str
    wall_s: float

    @property
    def landed_granules(self) -> int:
        """Simulated granules that landed (each lands as `angle_copies` copies)."""
        return int(round(self.x_m.size / self.angle_copies))

    def replicate_masses(self, tray_width_m: float, min_half_width_m: float) -> tuple[pattern.Trays, np.ndarray]:
        return estimate.replicate_tray_masses(self.x_m, self.mass_kg, self.replicate, self.replicates,
                                              tray_width_m, min_half_width_m)


def pool_runs(scene: Scene, runs: int, model: str = "auto", library: Optional[MaterialLibrary] = None,
              progress: Optional[Callable[[int, int], None]] = None) -> PooledLandings:
    """Run `scene` `runs` times on consecutive replicates and keep every landing point."""
    if runs < MIN_RUNS:
        raise ConfigError("replicates", f"must be at least {MIN_RUNS} independent runs, got {runs}")
    library = library or load_library()
    per_run = replicate_sizes(scene.sim.granules, scene.sim.replicates).size
    xs, masses, replicates = [], [], []
    granules, released, wall = 0, 0.0, 0.0
    result = None
    for start in range(0, runs, BATCH_RUNS):  # runs side by side (spread.batch), the same bits
        chunk = range(start, min(start + BATCH_RUNS, runs))
        for j, result in zip(chunk, run_batch([scene] * len(chunk), model=model, library=library,
                                              first_replicate=[j * per_run for j in chunk])):
            xs.append(result.sample.x_m)
            masses.append(result.sample.mass_kg)
            replicates.append(result.sample.replicate + j * per_run)
            granules += result.metrics.granules
            released += float(result.granules.mass_kg.sum())
            wall += result.metrics.wall_s
        if progress:
            progress(chunk.stop, runs)
    return PooledLandings(np.concatenate(xs), np.concatenate(masses), np.concatenate(replicates),
                          runs * per_run, granules, result.metrics.angle_copies, released, result.metrics.model,
                          result.metrics.model_reason, wall)


@dataclass(frozen=True)
class Reference:
    """A converged pattern: the CV at the target and along the bout widths, with standard errors."""

    scene: Scene
    pooled: PooledLandings  # or anything with its metadata, `landed_granules` and `replicate_masses`
    trays: pattern.Trays
    at_target: estimate.CvEstimate
    widths_m: np.ndarray
    cv_percent: np.ndarray  # corrected, NaN where nothing landed
    cv_standard_error_percent: np.ndarray
    effective_swath_m: float
    effective_swath_interval_m: tuple[float, float]  # the swath with the CV moved by -/+ 2 SE

    def to_json(self) -> dict:
        p = self.scene.pattern
        return {
            "scene": self.scene.name,
            "model": self.pooled.model,
            "model_reason": self.pooled.model_reason,
            "granules": self.pooled.granules,
            "landed_granules": self.pooled.landed_granules,
            "angle_copies": self.pooled.angle_copies,
            "replicates": self.pooled.replicates,
            "target_swath_m": p.target_swath_m,
            "driving": p.driving,
            "tray_width_m": p.tray_width_m,
            "cv_threshold_percent": p.cv_threshold_percent,
            "cv_percent_at_target": self.at_target.cv_percent,
            "cv_standard_error_percent": self.at_target.standard_error_percent,
            "cv_raw_percent": self.at_target.raw_percent,
            "cv_ci_percent": None if self.at_target.interval_percent is None else list(self.at_target.interval_percent),
            "effective_swath_m": self.effective_swath_m,
            "effective_swath_interval_m": list(self.effective_swath_interval_m),
            "cv_curve": {
                "bout_width_m": self.widths_m,
                "cv_percent": _nulls(self.cv_percent),
                "cv_standard_error_percent": _nulls(self.cv_standard_error_percent),
            },
            "trays": {"center_m": self.trays.center_m, "mass_kg": self.trays.mass_kg},
            "wall_s": self.pooled.wall_s,
        }


def _nulls(values: np.ndarray) -> list:
    return [None if not np.isfinite(v) else float(v) for v in values]


def swath_interval(widths_m: np.ndarray, cvs: np.ndarray, ses: np.ndarray,
                   threshold_percent: float) -> tuple[float, float]:
    """The effective swaths of the curve moved up and down by SE_MULTIPLE_FOR_SWATH standard
    errors. Where a CV has no standard error (under 3 replicates) it may be anything: the
    lower end counts it as failing, the upper as passing, so the interval stays honest
    instead of shrinking to the swath."""
    band = np.where(np.isfinite(cvs) & ~np.isfinite(ses), np.inf, SE_MULTIPLE_FOR_SWATH * ses)
    return (pattern.swath_from_curve(widths_m, cvs + band, threshold_percent),
            pattern.swath_from_curve(widths_m, np.maximum(cvs - band, 0.0), threshold_percent))


def reference_from(scene: Scene, pooled: PooledLandings) -> Reference:
    """The pattern estimate of pooled landings, on the scene's trays and threshold."""
    p = scene.pattern
    trays, masses = pooled.replicate_masses(p.tray_width_m, p.target_swath_m)
    widths = pattern.default_widths_m(trays) if trays.total_kg > 0.0 else np.zeros(0)  # nothing landed: no curve
    cvs, ses = estimate.cv_curve(masses, p.tray_width_m, p.driving, widths)
    swath = pattern.swath_from_curve(widths, cvs, p.cv_threshold_percent)
    interval = swath_interval(widths, cvs, ses, p.cv_threshold_percent)
    at_target = estimate.estimate_cv(masses, p.tray_width_m, p.target_swath_m, p.driving)
    return Reference(scene, pooled, trays, at_target, widths, cvs, ses, swath, interval)
