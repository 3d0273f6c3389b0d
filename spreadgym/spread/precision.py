"""Precision as the person's knob: independent runs of a scene pooled until the standard
error of the CV at the target width reaches what was asked.

Run j draws the replicates j R .. (j + 1) R - 1 of the scene's seed (R replicates per
run, `sim.replicates`), so n runs pooled are exactly one run of n times the granules,
and the CV's bias correction and jackknife rest on all n R replicates (spread.estimate).

The stopping rule is a count fixed from a pilot, topped up: PILOT_RUNS runs give the
pooled standard error s; the standard error of independent replicates falls as
1/sqrt(runs), so n = ceil(runs (s / p)^2) runs are made in all and pooled. If the pooled
standard error is still above p (the pilot's s is itself an estimate), the count is
topped up by the same rule, at most `max_runs`. The estimate is the pooled one over every
run made. Its 95 % intervals cover the exact CV 90-99 % of the time on patterns with a
known CV (tests/spread/test_precision.py), so the rule leaves the stated standard error
honest. The pilot is as many runs as give the pooled CV the 3 replicates its standard
error needs (a granule count with few divisors makes a run one replicate: 2047
granules), at least PILOT_RUNS; a pattern for which no standard error exists even so
(nothing landed, or one replicate holding all the mass) stops after the pilot.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable, Optional

import numpy as np

from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.config.scene import MAX_GRANULE_COPIES, Scene, granule_copies
from spreadgym.errors import SpreadgymError
from spreadgym.physics.granules import replicate_sizes
from spreadgym.spread import estimate, pattern
from spreadgym.spread.batch import run_batch
from spreadgym.spread.pipeline import SimulationResult, run_scene
from spreadgym.spread.reference import MIN_RUNS, Reference, reference_from

PILOT_RUNS = 2
SIMULATE_PRECISION_PP = 0.2
"""Default of `spreadgym simulate --precision`: the standard error (percentage points) of
the CV at the target width. A person reads the CV to one decimal."""
SIMULATE_MAX_RUNS = 64
REFERENCE_PRECISION_PP = 0.1
"""Default of `spreadgym reference --precision`: half simulate's."""
REFERENCE_MAX_RUNS = 512
MIN_PRECISION_PP = 0.001


def check_precision(value: float, flag: str = "--precision") -> float:
    """A requested standard error in percentage points: finite and at least MIN_PRECISION_PP."""
    if not (math.isfinite(value) and value >= MIN_PRECISION_PP):
        raise SpreadgymError(f"{flag}: {value!r} must be a number of percentage points >= {MIN_PRECISION_PP:g}")
    return float(value)


def reached(standard_error_pp: Optional[float], precision_pp: float) -> bool:
    """Whether a stated standard error (None: unknown) is within the precision asked."""
    return standard_error_pp is not None and standard_error_pp <= precision_pp


def runs_needed(standard_error_pp: Optional[float], runs: int, precision_pp: float, max_runs: int) -> int:
    """Runs to make in all so that the standard error, now `standard_error_pp` after `runs`
    runs, falls to `precision_pp` (it falls as 1/sqrt(runs)); `runs` where it already has
    or where no standard error is known."""
    if standard_error_pp is None or not math.isfinite(standard_error_pp) or standard_error_pp <= precision_pp:
        return runs
    wanted = math.ceil(runs * (standard_error_pp / precision_pp) ** 2 * (1.0 - 1e-12))
    return min(max(wanted, runs + 1), max_runs)


def pilot_runs_of(scene: Scene, max_runs: int) -> int:
    """PILOT_RUNS, or the fewest runs whose replicates pooled reach
    `estimate.MIN_REPLICATES_FOR_SE` (a run has as many replicates as divide its granule
    count, at most `sim.replicates`), at most `max_runs`."""
    per_run = replicate_sizes(scene.sim.granules, scene.sim.replicates).size
    return min(max(PILOT_RUNS, math.ceil(estimate.MIN_REPLICATES_FOR_SE / per_run)), max(max_runs, PILOT_RUNS))


def pool_until_precise(add_runs: Callable[[int], Optional[float]], precision_pp: float, max_runs: int,
                       pilot_runs: int = PILOT_RUNS) -> int:
    """Call `add_runs(n)` (n more independent runs pooled; it returns the pooled standard
    error, None if unknown) by the rule of this module; returns the number of runs made.
    A pilot of `max_runs` runs is a fixed count: exactly that many."""
    if max_runs < pilot_runs:
        raise SpreadgymError(f"max runs: {max_runs} must be at least the {pilot_runs} pilot runs")
    runs = pilot_runs
    se = add_runs(pilot_runs)
    target = runs_needed(se, runs, precision_pp, max_runs)
    while runs < target:
        se = add_runs(target - runs)
        runs = target
        target = runs_needed(se, runs, precision_pp, max_runs)
    return runs


class PooledMasses:
    """Tray masses of each replicate of several runs on one common row of trays: a run's
    (R, T) masses sit on trays i w, i = -m..m, so rows of different reach pad with zeros."""

    def __init__(self, tray_width_m: float):
        self.tray_width_m = tray_width_m
        self.parts: list[np.ndarray] = []

    def add(self, replicate_masses: np.ndarray) -> None:
        self.parts.append(np.asarray(replicate_masses, dtype=float))

    def masses(self) -> np.ndarray:
        """(sum of R, T) on the widest row."""
        widest = max(p.shape[1] for p in self.parts)
        return np.vstack([np.pad(p, ((0, 0), ((widest - p.shape[1]) // 2,) * 2)) for p in self.parts])

    def trays(self) -> pattern.Trays:
        """The pooled single pass on that row."""
        masses = self.masses()
        half = masses.shape[1] // 2
        return pattern.Trays(np.arange(-half, half + 1) * self.tray_width_m, masses.sum(axis=0), self.tray_width_m)


@dataclass(frozen=True)
class PooledRuns:
    """Runs pooled as replicate tray masses, with what a `reference.Reference` reports of
    them (the metadata of `reference.PooledLandings`, without keeping every landing)."""

    pooled: PooledMasses
    replicates: int
    granules: int  # simulated on the spinner, landed or not
    landed_granules: int
    angle_copies: int
    released_kg: float
    model: str
    model_reason: str
    wall_s: float

    def replicate_masses(self, tray_width_m: float, min_half_width_m: float) -> tuple[pattern.Trays, np.ndarray]:
        """(Trays, (K, T) masses); every run's row already reaches the target swath."""
        del min_half_width_m  # each run's row was laid out to reach it
        if tray_width_m != self.pooled.tray_width_m:
            raise SpreadgymError(f"tray width {tray_width_m} m: the runs were caught on {self.pooled.tray_width_m} m")
        return self.pooled.trays(), self.pooled.masses()


@dataclass(frozen=True)
class PreciseEstimate:
    """A scene's pattern from `runs` pooled runs: what `spreadgym simulate` reports."""

    first: SimulationResult  # run 0: its granules, paths and departure summary
    runs: int
    precision_pp: float  # what was asked
    max_runs: int
    reference: Reference  # the pooled pattern's figures (reference.reference_from)
    retained_kg: float
    intercepted_kg: float
    outcomes: dict[str, int]
    wall_s: float

    @property
    def masses(self) -> np.ndarray:
        """(runs R, T) replicate tray masses."""
        return self.reference.pooled.pooled.masses()

    @property
    def at_target(self) -> estimate.CvEstimate:
        return self.reference.at_target

    @property
    def granules_simulated(self) -> int:
        """Granules behind the estimate (release-angle copies not counted)."""
        return self.runs * self.first.metrics.granules

    @property
    def precision_met(self) -> bool:
        return reached(self.at_target.standard_error_percent, self.precision_pp)

    def as_result(self) -> SimulationResult:
        """Run 0 (granules, paths, landings for pictures) carrying the pooled trays and figures."""
        m = self.first.metrics
        notes = list(m.notes)
        if not self.precision_met and self.at_target.standard_error_percent is not None:
            notes.append(f"standard error {self.at_target.standard_error_percent:.2g} pp after the cap of "
                         f"{self.max_runs} runs: above the {self.precision_pp:g} pp asked")
        ref = self.reference
        interval = ref.at_target.interval_percent
        metrics = replace(
            m, outcomes=self.outcomes, cv_percent_at_target=ref.at_target.cv_percent,
            cv_standard_error_percent=ref.at_target.standard_error_percent, cv_raw_percent=ref.at_target.raw_percent,
            cv_ci_percent=None if interval is None else list(interval), effective_swath_m=ref.effective_swath_m,
            curve_bout_width_m=ref.widths_m, curve_cv_percent=ref.cv_percent, trays=ref.trays,
            released_kg=ref.pooled.released_kg, retained_kg=self.retained_kg, intercepted_kg=self.intercepted_kg,
            notes=notes, wall_s=self.wall_s)
        return replace(self.first, trays=ref.trays, replicate_masses_kg=self.masses, metrics=metrics)

    def to_json(self) -> dict:
        """`spreadgym simulate --json`: a run's keys with the pooled pattern's figures, plus
        `granules_simulated`, `runs`, `precision_percent` and `precision_met`."""
        out = self.as_result().metrics.to_json()
        out.update({"granules_simulated": self.granules_simulated, "runs": self.runs,
                    "precision_percent": self.precision_pp, "precision_met": self.precision_met})
        return out


@dataclass
class _Pool:
    """What `_pool_runs` gathers while it runs."""

    first: Optional[SimulationResult] = None
    runs: int = 0
    landed: int = 0
    released_kg: float = 0.0
    retained_kg: float = 0.0
    intercepted_kg: float = 0.0
    outcomes: dict = field(default_factory=dict)


def scene_runs(scene: Scene, runs: range, model: str, library: MaterialLibrary, tracks: int = 0):
    """Runs `runs` (consecutive run numbers) of `scene`, in order: side by side (spread.batch:
    the same bits as one by one), in batches of even size that hold at most
    MAX_GRANULE_COPIES landing points (64 paper runs: 32 + 32, not 61 + 3, which left a
    core idle); run 0 keeps `tracks` paths."""
    per_run = replicate_sizes(scene.sim.granules, scene.sim.replicates).size
    todo = list(runs)
    if todo and todo[0] == 0 and tracks:
        yield run_scene(scene, model=model, library=library, ci=False, tracks=tracks)
        todo = todo[1:]
    most = max(1, MAX_GRANULE_COPIES // granule_copies(scene))
    batches = max(1, math.ceil(len(todo) / most))  # as few as the cap allows, of even size
    for chunk in np.array_split(np.array(todo, dtype=int), batches):
        chunk = chunk.tolist()
        yield from run_batch([scene] * len(chunk), model=model, library=library, ci=False,
                             first_replicate=[j * per_run for j in chunk])


def _pool_runs(scene: Scene, precision_pp: float, max_runs: int, model: str, library: Optional[MaterialLibrary],
               tracks: int, progress: Optional[Callable[[int, int], None]],
               pilot_runs: int = PILOT_RUNS) -> tuple[_Pool, Reference]:
    """Runs 0, 1, ... of `scene` (consecutive replicates) pooled by the rule of this module,
    and the pooled pattern's figures."""
    started = time.perf_counter()
    check_precision(precision_pp)
    library = library or load_library()
    p = scene.pattern
    masses = PooledMasses(p.tray_width_m)
    pool = _Pool()

    def add(result: SimulationResult) -> None:
        pool.first = pool.first or result
        pool.runs += 1
        masses.add(result.replicate_masses_kg)
        m = result.metrics
        pool.landed += int(result.landed.sum())
        pool.released_kg += m.released_kg
        pool.retained_kg += m.retained_kg
        pool.intercepted_kg += m.intercepted_kg
        for key, count in m.outcomes.items():
            pool.outcomes[key] = pool.outcomes.get(key, 0) + count
        if progress:
            progress(pool.runs, max_runs)

    def add_runs(count: int) -> Optional[float]:
        for result in scene_runs(scene, range(pool.runs, pool.runs + count), model, library, tracks):
            add(result)
        return estimate.estimate_cv(masses.masses(), p.tray_width_m, p.target_swath_m, p.driving).standard_error_percent

    pool_until_precise(add_runs, precision_pp, max_runs, pilot_runs)
    m = pool.first.metrics
    summary = PooledRuns(masses, masses.masses().shape[0], pool.runs * m.granules, pool.landed, m.angle_copies,
                         pool.released_kg, m.model, m.model_reason, time.perf_counter() - started)
    return pool, reference_from(scene, summary)


def simulate_precisely(scene: Scene, precision_pp: float = SIMULATE_PRECISION_PP, max_runs: int = SIMULATE_MAX_RUNS,
                       model: str = "auto", library: Optional[MaterialLibrary] = None, tracks: int = 0,
                       progress: Optional[Callable[[int, int], None]] = None) -> PreciseEstimate:
    """Runs of `scene` pooled until the CV at the target has standard error `precision_pp`
    (percentage points), at most `max_runs` runs; `progress(runs, cap)` after each."""
    started = time.perf_counter()
    pool, reference = _pool_runs(scene, precision_pp, max_runs, model, library, tracks, progress,
                                 pilot_runs_of(scene, max_runs))
    return PreciseEstimate(pool.first, pool.runs, precision_pp, max_runs, reference, pool.retained_kg,
                           pool.intercepted_kg, pool.outcomes, time.perf_counter() - started)


def reference_precisely(scene: Scene, precision_pp: float = REFERENCE_PRECISION_PP,
                        max_runs: int = REFERENCE_MAX_RUNS, model: str = "auto",
                        library: Optional[MaterialLibrary] = None,
                        progress: Optional[Callable[[int, int], None]] = None, runs: Optional[int] = None) -> Reference:
    """`spreadgym reference`: the converged pattern of runs pooled by this module's rule (at
    least MIN_RUNS; exactly `runs` where given), as `reference.reference_from` reports it."""
    cap = runs if runs is not None else max(max_runs, MIN_RUNS)
    return _pool_runs(scene, precision_pp, cap, model, library, 0, progress,
                      pilot_runs=runs if runs is not None else pilot_runs_of(scene, cap))[1]
