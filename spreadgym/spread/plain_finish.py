"""The finish of a batch's plain designs as a few compiled calls for the whole batch.

A plain design has one disc, no plates and release-angle copies (a flight without
direction and a feed spot, `rotations.copies_for`): the scenes of SpinnerDesign, of the
searches and of `reference`. `finish_plain(plans, departures, ci)` returns, bit for bit,
`[pipeline.finish_scene(plan, departure, ci) ...]`; spreadgym.spread.batch sends it the
batch's plain designs and every other design to `finish_scene`.

Why: `finish_scene` is ~80 % compiled kernels that release the GIL and ~20 % small numpy
and Python steps between them that hold it, some forty per design; on many threads a
batch waited on those (docs/performance.md, the 16-core figures). Here the finish of the
whole batch is:

1. the laws of the copies' turns (`rotations.TurnLaws`) and the launch states of every
   departed granule (`pipeline.launch_columns`) of all designs, one numpy pass each;
2. the flights of the departed granules of designs that fly alike, in parts on the
   threads (`flight.fly`: each granule is flown on its own, so its landing does not depend
   on which granules fly beside it; tests/spread/test_flight.py);
3. every design's turns, copies, trays, CV at the target and CV curve in one parallel
   kernel (`finish_kernel.finish_designs`: the same kernels `finish_scene` calls, with the
   same glue compiled between them);
4. per design, the result's objects and metrics (`pipeline.result_of`).

A design the kernel cannot finish exactly as `finish_scene` does (a feed spot so small
that numpy draws its turns, a landing point that is not finite, a row of trays wider than
allowed) goes through `finish_scene` itself, which also gives its error.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Sequence

import numpy as np

from spreadgym import threads
from spreadgym.physics.compiled import pcg64
from spreadgym.physics.departure import Departure, tilted_by_cone
from spreadgym.spread import discs, estimate, pattern, rotations
from spreadgym.spread import flight as flight_model
from spreadgym.spread.binning import OK
from spreadgym.spread.finish_kernel import finish_designs
from spreadgym.spread.pipeline import (
    ScenePlan,
    SimulationResult,
    curve_widths_m,
    finish_scene,
    launch_columns,
    result_of,
)
from spreadgym.spread.von_mises import LARGE_KAPPA

PART_GRANULES = 4096
"""Departed granules per part of the flight stage at most (about 2 ms of flight); on more
than one thread a batch has at least PARTS_PER_THREAD parts per thread, so that the parts
share out evenly (on one, parts of PART_GRANULES: splitting would only add calls)."""
PARTS_PER_THREAD = 4
SMALLEST_PART = 256  # granules: a part's call and checks cost about what 20 granules' flights do


def is_plain(plan: ScenePlan) -> bool:
    """Whether `finish_plain` finishes `plan`: one disc, no plates, release-angle copies."""
    return len(plan.parts) == 1 and not plan.scene.deflectors and rotations.copies_for(plan.scene)[0] > 1


def finish_plain(plans: Sequence[ScenePlan], departures: Sequence[list[Departure]],
                 ci: bool = True) -> list[SimulationResult]:
    """`pipeline.finish_scene` of every plan (each `is_plain`, with its one spinner
    run's departure in `departures`), computed for all of them at once."""
    if not plans:
        return []
    scenes = [plan.scene for plan in plans]
    throws = []
    for plan, (departure,) in zip(plans, departures):
        tilted = tilted_by_cone(departure, np.radians(plan.scene.spinner.cone_deg))
        throws.append(discs.Throw(plan.spins[0][0], tilted, tilted))  # no plates: the launch is the departure
    every = discs.combined(throws)
    g = every.granules
    counts = np.array([t.granules.count for t in throws])
    first = np.concatenate([[0], np.cumsum(counts)])
    departed = every.launch.departed
    flown = np.add.reduceat(departed, first[:-1])
    flown_first = np.concatenate([[0], np.cumsum(flown)])
    laws = rotations.TurnLaws.of(g.release_xy_m, scenes, counts)
    landing_xy, landing_t = _flights(scenes, throws, every, departed, counts, flown)

    copies_and_reasons = [rotations.copies_for(scene) for scene in scenes]
    copies = np.array([count for count, _ in copies_and_reasons])
    replicates = np.maximum.reduceat(g.replicate, first[:-1]) + 1
    run_first, run_start, run_stop, streams = rotations.turn_streams(
        g.replicate, first, [scene.sim.seed for scene in scenes], [plan.first_replicate for plan in plans])
    runs = (run_first, run_start, run_stop, pcg64.seeded(streams))
    width = np.array([float(scene.pattern.tray_width_m) for scene in scenes])
    min_half = np.array([pattern.min_half_trays(scene.pattern.target_swath_m, w) for scene, w in zip(scenes, width)])
    room = _tray_room(landing_xy, flown, flown_first, width, min_half)
    tray_first = np.concatenate([[0], np.cumsum(room)])
    masses_first = np.concatenate([[0], np.cumsum(replicates * room)])
    sample_first = np.concatenate([[0], np.cumsum(copies * flown)])
    out_x, out_mass = np.empty(sample_first[-1]), np.empty(sample_first[-1])
    out_replicate = np.empty(sample_first[-1], dtype=g.replicate.dtype)
    out_pooled, out_masses = np.empty(tray_first[-1]), np.empty(masses_first[-1])
    status, half_trays = np.empty(len(plans), dtype=np.int64), np.empty(len(plans), dtype=np.int64)
    target, curve = np.empty((len(plans), 4)), np.empty((tray_first[-1], 4))
    target_trays = np.array([_target_trays(scene.pattern.target_swath_m, w) for scene, w in zip(scenes, width)])
    numpy_turns = np.logical_or.reduceat(laws.kappa > LARGE_KAPPA, first[:-1])  # `von_mises.fill_turns`' own case
    means = np.empty((len(plans), 6))
    sense = np.array([math.copysign(1.0, scene.spinner.omega_rad_s) for scene in scenes])
    racetrack = np.array([scene.pattern.driving == "racetrack" for scene in scenes])
    with threads.numba_threads():
        finish_designs(numpy_turns, first, copies, *runs, laws.kappa, laws.cos_mu, laws.sin_mu, laws.held, departed,
                       flown_first, landing_xy, g.mass_kg, g.replicate, replicates, sample_first, out_x, out_mass,
                       out_replicate, width, min_half, pattern.MAX_TRAYS, tray_first, room, masses_first, out_pooled,
                       out_masses, target_trays, racetrack, status, half_trays, target, curve,
                       every.departure.position_m, every.departure.velocity_m_s, every.departure.spin_rad_s,
                       every.departure.time_s, sense, means)
    landing_xy += 0.0  # finish_scene adds the disc's centre, 0 here, which turns -0.0 into 0.0: the same bits

    results = []
    for d, (plan, throw) in enumerate(zip(plans, throws)):
        if numpy_turns[d] or status[d] != OK:
            results.append(finish_scene(plan, departures[d], ci))
            continue
        w, m, k = width[d], int(half_trays[d]), int(replicates[d])
        trays = pattern.tray_row(out_pooled[tray_first[d]:tray_first[d] + 2 * m + 1], m, w)
        masses = out_masses[masses_first[d]:masses_first[d] + k * (2 * m + 1)].reshape(k, 2 * m + 1)
        at_target = estimate.estimate_from(*(float(v) for v in target[d, :3]), bool(target[d, 3]), k)
        widths = curve_widths_m(trays)
        figures = curve[tray_first[d]:tray_first[d] + widths.size]
        cvs, _ = estimate.curve_from(figures[:, 0], figures[:, 1], figures[:, 2], figures[:, 3] != 0.0, k)
        flights = slice(flown_first[d], flown_first[d + 1])
        samples = slice(sample_first[d], sample_first[d + 1])
        flying = departed[first[d]:first[d + 1]]
        results.append(result_of(
            plan, [throw], throw, flying, flight_model.Landing(landing_xy[flights], landing_t[flights]),
            estimate.TraySample(out_x[samples], out_mass[samples], out_replicate[samples]), int(copies[d]),
            copies_and_reasons[d][1], [0.0], ci, trays, masses, at_target, widths, cvs,
            (int(means[d, 0]), *(float(v) for v in means[d, 1:]))))
    return results


def _tray_room(landing_xy: np.ndarray, flown: np.ndarray, flown_first: np.ndarray, width: np.ndarray,
               min_half: np.ndarray) -> np.ndarray:
    """Trays to make room for per design: a row reaching every landing's distance from the
    axis (a copy lands at its granule's distance, turned), one tray spare, at most MAX_TRAYS."""
    reach = np.zeros(flown.size)
    some = flown > 0
    if some.any():
        distance = np.hypot(landing_xy[:, 0], landing_xy[:, 1])
        reach[some] = np.maximum.reduceat(distance, flown_first[:-1][some])
    with np.errstate(invalid="ignore", over="ignore"):
        trays = np.floor(reach / width + 0.5) + 1.0
    trays = np.where(np.isfinite(trays), np.minimum(trays, pattern.MAX_TRAYS), 0.0)  # not finite: binning says so
    return np.minimum(2 * np.maximum(min_half, trays.astype(np.int64)) + 1, pattern.MAX_TRAYS)


@lru_cache(maxsize=256)
def _target_trays(target_swath_m: float, tray_width_m: float) -> int:
    """Trays in the target's bout (`pattern.bout_tray_counts`)."""
    return int(pattern.bout_tray_counts([target_swath_m], tray_width_m)[0])


def _flights(scenes: list, throws: list[discs.Throw], every: discs.Throw, departed: np.ndarray,
             counts: np.ndarray, flown: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Landing points (M, 2; disc frame) and times (M,) of the departed granules of all
    designs, in order: designs that fly alike (one flight, the lift on or off) in parts on
    the threads, each part a `flight.fly` call given the lift of its designs (on the CPU
    also where the spinner ran on a GPU: docs/performance.md, "What stays on the CPU")."""
    heights = np.repeat([s.spinner.height_m for s in scenes], counts)
    position, height, velocity, spin = launch_columns(every.launch, departed, heights)
    diameter = every.granules.diameter_m[departed]
    density = np.repeat([t.granules.density_kg_m3 for t in throws], counts)[departed]
    owner = np.repeat(np.arange(len(throws)), flown)
    kinds: list[tuple] = []  # designs that fly alike: (flight, lift, designs)
    for d, (scene, throw) in enumerate(zip(scenes, throws)):
        lift = flight_model.lift_acts(scene.flight, throw.launch.spin_rad_s[throw.launch.departed])
        kind = next((k for k in kinds if k[1] == lift and k[0] == scene.flight), None)
        if kind is None:
            kinds.append(kind := (scene.flight, lift, []))
        kind[2].append(d)
    parts = []  # (flight, lift, granule rows: a slice or indices)
    count = threads.thread_count()
    parts_wanted = PARTS_PER_THREAD * count if count > 1 else 1  # on one thread, more parts only add calls
    step = int(np.clip(-(-owner.size // parts_wanted), SMALLEST_PART, PART_GRANULES))
    for flight, lift, members in kinds:
        rows = np.flatnonzero(np.isin(owner, members)) if len(kinds) > 1 else None
        size = owner.size if rows is None else rows.size
        for a in range(0, size, step):
            b = min(a + step, size)
            parts.append((flight, lift, slice(a, b) if rows is None else rows[a:b]))
    landing_xy, landing_t = np.empty((owner.size, 2)), np.empty(owner.size)

    def fly(p: int) -> None:
        flight, lift, rows = parts[p]
        landed = flight_model.fly(position[rows], height[rows], velocity[rows], diameter[rows], density[rows], flight,
                                  spin_rad_s=spin[rows], lift=lift)
        landing_xy[rows], landing_t[rows] = landed.position_m, landed.time_s

    threads.thread_map(fly, len(parts))
    return landing_xy, landing_t
