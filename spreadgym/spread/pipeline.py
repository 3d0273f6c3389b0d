"""The whole chain for one scene: spinner -> deflectors -> flight -> tray pattern -> metrics.

`run_scene` is what `spreadgym simulate` and the environments call. Its `metrics`
(`RunMetrics`) give the JSON of `spreadgym simulate --json` through `.to_json()`.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from spreadgym import heap
from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.config.scene import Flight, Scene
from spreadgym.physics.contacts import Contacts, resolve_contacts
from spreadgym.physics.departure import Departure, tilted_by_cone
from spreadgym.physics.granules import GranuleBatch, sample_granules
from spreadgym.physics.selection import DEFLECTOR_METHODS, SPINNER_MODELS
from spreadgym.spread import discs, estimate, pattern, rotations, twin
from spreadgym.spread import flight as flight_model
from spreadgym.spread.metrics import RunMetrics


@dataclass
class SimulationResult:
    """One run: the simulated granules (machine frame) and the tray pattern of their
    `sample` (their release-angle copies when `metrics.angle_copies` > 1)."""

    scene: Scene
    granules: GranuleBatch
    departure: Departure  # state at the disc edge
    launch: Departure  # state where the flight starts (after the deflector zone)
    landed: np.ndarray  # (N,) bool: the granules whose landings `landing` holds, in order
    landing: flight_model.Landing
    sample: estimate.TraySample  # what the trays caught: landing across the track, mass, replicate
    trays: pattern.Trays
    replicate_masses_kg: np.ndarray  # (K, T) tray masses of each independent replicate
    metrics: RunMetrics


def run_spinner(
    scene: Scene,
    granules: GranuleBatch,
    contacts: Contacts,
    model: str,
    progress: Optional[Callable[[float], None]] = None,
    tracks: int = 0,
) -> Departure:
    """Departure states from the chosen spinner model (`tracks` paths kept for plots)."""
    return SPINNER_MODELS[model].run(scene, granules, contacts, progress, tracks)


@dataclass(frozen=True)
class ScenePlan:
    """A scene's run up to its spinner runs: the discs, the model, and each disc's granules
    and contacts (None for a disc whose throw is the first disc's mirrored)."""

    scene: Scene
    parts: list[discs.Disc]
    chosen: str
    reason: str
    spins: list[Optional[tuple[GranuleBatch, Contacts]]]
    first_replicate: int

    def spinner_runs(self) -> list[tuple[Scene, GranuleBatch, Contacts]]:
        """(disc scene, granules, contacts) of every disc that runs its spinner, in order."""
        return [(disc.scene, *spin) for disc, spin in zip(self.parts, self.spins) if spin is not None]


def plan_scene(scene: Scene, model: str, library: MaterialLibrary, first_replicate: int = 0) -> ScenePlan:
    """The discs, model, granules (the replicates of sim.seed from `first_replicate`) and contacts of `scene`."""
    parts = discs.discs(scene)
    chosen, reason = discs.choose_for_discs(parts, model, library)
    fertilizer = library.fertilizer_of(scene)
    spins: list[Optional[tuple[GranuleBatch, Contacts]]] = []
    for i, disc in enumerate(parts):
        if i and discs.is_mirror_image(parts[0].scene, disc.scene):
            spins.append(None)
        else:
            spins.append((sample_granules(disc.scene, fertilizer, scene.sim.replicates, first_replicate),
                          resolve_contacts(disc.scene, library)))
    return ScenePlan(scene, parts, chosen, reason, spins, first_replicate)


def run_scene(
    scene: Scene,
    model: str = "auto",
    library: Optional[MaterialLibrary] = None,
    progress: Optional[Callable[[float], None]] = None,
    ci: bool = True,
    tracks: int = 0,
    first_replicate: int = 0,
) -> SimulationResult:
    """Simulate `scene` end to end; the granules are the replicates of sim.seed from `first_replicate`.

    `progress(t)` is called with the simulated spinner time (s); `ci` adds the 95 %
    interval of the CV; `tracks` keeps that many granule paths for pictures. A twin
    scene runs each disc on its own (spreadgym.spread.discs) and scores both discs'
    landings as one pattern; the result's granule arrays hold the first disc's granules,
    then the second's, in the machine frame, and `metrics.departure` is the first disc's.
    spreadgym.spread.batch runs many scenes at once, with the same results.
    """
    started = time.perf_counter()
    heap.tune()
    plan = plan_scene(scene, model, library or load_library(), first_replicate)
    departures = [run_spinner(*run, plan.chosen, progress, tracks) for run in plan.spinner_runs()]
    result = finish_scene(plan, departures, ci)
    result.metrics = dataclasses.replace(result.metrics, wall_s=time.perf_counter() - started)
    return result


def finish_scene(plan: ScenePlan, departures: list[Departure], ci: bool = True,
                 deflector: Optional[str] = None) -> SimulationResult:
    """The rest of the chain after the spinner runs (`departures`, one per `plan.spinner_runs()`):
    cone, deflectors, release-angle copies, flight, trays and metrics (wall_s left 0).
    `deflector`: a plate stage (selection.DEFLECTOR_METHODS) other than the model's own,
    for the studies that compare plate stages on the same departures."""
    scene, parts, chosen, first_replicate = plan.scene, plan.parts, plan.chosen, plan.first_replicate
    throws: list[discs.Throw] = []
    turns: list[rotations.Turn] = []  # each disc's release-angle copies (spread.rotations)
    mirror = False  # the second disc's throw is the first's mirrored
    spun = iter(departures)
    for disc, spin in zip(parts, plan.spins):
        if spin is None:
            throws.append(discs.mirrored(throws[0]))
            turns.append(turns[0])  # its copies are the first disc's mirrored (rotations.copied_sample)
            mirror = True
            continue
        granules, contacts = spin
        departure = tilted_by_cone(next(spun), np.radians(disc.scene.spinner.cone_deg))
        launch = DEFLECTOR_METHODS[deflector or SPINNER_MODELS[chosen].deflector](departure, disc.scene, contacts,
                                                                                  granules)
        throws.append(discs.Throw(granules, departure, launch))
        copies, copies_reason = rotations.copies_for(disc.scene, len(parts))
        turns.append(rotations.copy_turns(granules, disc.scene, copies, scene.sim.seed, first_replicate))
    # every disc flies in its own frame; the pattern is in the machine frame
    local = discs.combined(throws)
    placed = [discs.moved(t, d.centre_m) for t, d in zip(throws, parts)]
    machine = discs.combined(placed)
    granules, departure, launch = machine.granules, machine.departure, machine.launch
    lost = twin.intercepted(placed, parts, mirror)  # thrown onto the other disc: not in the pattern
    flying = launch.departed & ~lost  # the granules that fly and land
    counts = [t.granules.count for t in throws]
    disc_height = np.repeat([d.scene.spinner.height_m for d in parts], counts)
    centre = np.repeat(np.asarray([d.centre_m for d in parts]), counts, axis=0)
    # a mirrored throw in a flight without crosswind lands mirrored, to the bit: fly the first disc only
    fly_once = mirror and scene.flight.wind_m_s[0] == 0.0
    copies = max(t.copies for t in turns)  # the most release angles any disc takes
    if copies == 1:
        landing = _flight(local.launch, granules, flying, disc_height, scene.flight,
                          int(flying[:counts[0]].sum()) if fly_once else None)
        landing = flight_model.Landing(landing.position_m + centre[flying], landing.time_s)
        sample = estimate.TraySample(landing.position_m[:, 0], granules.mass_kg[flying], granules.replicate[flying])
        lost_kg = [float(m.sum()) for m in np.split(granules.mass_kg * lost, np.cumsum(counts)[:-1])]
    else:  # every departed granule flies: its copies may miss the other disc where it does not
        gone = local.launch.departed
        flown = _flight(local.launch, granules, gone, disc_height, scene.flight,
                        int(gone[:counts[0]].sum()) if fly_once else None)
        local_landing = np.full((granules.count, 2), np.nan)
        local_landing[gone] = flown.position_m
        time_s = np.full(granules.count, np.nan)
        time_s[gone] = flown.time_s
        landing = flight_model.Landing(local_landing[flying] + centre[flying], time_s[flying])
        if parts[0].scene.deflectors:  # one disc among plates (rotations.copies_for)
            sample = _plate_sample(throws[0], parts[0].scene, plan.spins[0][1], local_landing, turns[0])
            lost_kg = [0.0]
        else:
            sample, lost_kg = rotations.copied_sample(throws, np.split(local_landing, np.cumsum(counts)[:-1]),
                                                     turns, parts, mirror)
    return scored(plan, throws, machine, flying, landing, sample, copies, copies_reason, lost_kg, ci)


def scored(plan: ScenePlan, throws: list[discs.Throw], machine: discs.Throw, flying: np.ndarray,
           landing: flight_model.Landing, sample: estimate.TraySample, copies: int, copies_reason: str,
           lost_kg: list[float], ci: bool) -> SimulationResult:
    """The run's trays, CV estimate, curve and metrics from what the trays caught
    (`sample`); `throws` per disc, `machine` all discs in the machine frame, `flying` the
    granules that fly and land (`landing`), `lost_kg` each disc's mass thrown onto the
    other. The end of `finish_scene`, shared with `spread.plain_finish`."""
    p = plan.scene.pattern
    trays, replicate_masses = estimate.replicate_tray_masses(
        sample.x_m, sample.mass_kg, sample.replicate, int(machine.granules.replicate.max()) + 1,
        p.tray_width_m, min_half_width_m=p.target_swath_m)
    at_target = estimate.estimate_cv(replicate_masses, p.tray_width_m, p.target_swath_m, p.driving)
    widths = curve_widths_m(trays)
    cvs, _ = estimate.cv_curve(replicate_masses, p.tray_width_m, p.driving, widths)
    return result_of(plan, throws, machine, flying, landing, sample, copies, copies_reason, lost_kg, ci, trays,
                     replicate_masses, at_target, widths, cvs)


def curve_widths_m(trays: pattern.Trays) -> np.ndarray:
    """The bout widths of a run's CV curve: `pattern.default_widths_m`, none where no mass landed."""
    return pattern.default_widths_m(trays) if trays.total_kg > 0.0 else np.zeros(0)


def result_of(plan: ScenePlan, throws: list[discs.Throw], machine: discs.Throw, flying: np.ndarray,
              landing: flight_model.Landing, sample: estimate.TraySample, copies: int, copies_reason: str,
              lost_kg: list[float], ci: bool, trays: pattern.Trays, replicate_masses: np.ndarray,
              at_target: estimate.CvEstimate, widths: np.ndarray, cvs: np.ndarray,
              departure_means: Optional[tuple] = None) -> SimulationResult:
    """The run's `SimulationResult` from its trays (`replicate_masses` (K, T) per replicate),
    its CV estimate at the target swath and its CV curve (`cvs` at `widths`);
    `departure_means`: the first disc's `Departure.means`, where already computed."""
    scene, chosen = plan.scene, plan.chosen
    granules, departure, launch = machine.granules, machine.departure, machine.launch
    p = scene.pattern
    has_mass = widths.size > 0
    metrics = RunMetrics(
        model=chosen,
        model_reason=plan.reason,
        dt_s=departure.dt_s if departure.dt_s > 0.0 else None,  # None: closed forms, no step
        granules=granules.count,
        angle_copies=copies,
        angle_copies_reason=copies_reason,
        outcomes=departure.outcome_counts(),
        departure=departure_summary(throws[0].departure, scene.spinner.omega_rad_s, departure_means),
        target_swath_m=p.target_swath_m,
        driving=p.driving,
        tray_width_m=p.tray_width_m,
        cv_threshold_percent=p.cv_threshold_percent,
        cv_percent_at_target=at_target.cv_percent,
        cv_standard_error_percent=at_target.standard_error_percent,
        cv_raw_percent=at_target.raw_percent,
        cv_ci_percent=list(at_target.interval_percent) if ci and at_target.interval_percent is not None else None,
        effective_swath_m=(pattern.swath_from_curve(widths, cvs, p.cv_threshold_percent)
                           if has_mass else 0.0),
        curve_bout_width_m=widths,
        curve_cv_percent=cvs,
        trays=trays,
        released_kg=float(granules.mass_kg.sum()),
        retained_kg=float(granules.mass_kg[~departure.departed].sum()),
        intercepted_kg=float(sum(lost_kg)),
        notes=_notes(scene, chosen, departure, launch, trays) + twin.interception_notes(throws, plan.parts, lost_kg),
        wall_s=0.0,
    )
    return SimulationResult(scene, granules, departure, launch, flying, landing, sample, trays, replicate_masses,
                            metrics)


def _plate_sample(throw: discs.Throw, disc: Scene, contacts: Contacts, landing_m: np.ndarray,
                  turn: rotations.Turn) -> estimate.TraySample:
    """The tray sample of one disc's release-angle copies among plates: copy 0 is the
    granule's own run; a copy whose turned path the plates bounce (the compiled plate
    stage, the model's own for `compiled`) flies on its own; every other copy meets no
    plate and lands as its granule's plate-free throw, turned (it flies once per granule)."""
    plates, g = disc.deflectors, throw.granules
    free = rotations.straight_paths(throw.departure, plates, g.radius_m)
    near = rotations.near_own_paths(throw, free, plates)
    free_landing = landing_m.copy()
    height = np.full(g.count, disc.spinner.height_m)
    if near.any():
        free_landing[near] = _flight(free, g, near, height, disc.flight, None).position_m
    replays = rotations.plate_replays(throw, free, turn, plates, contacts.deflectors, disc.granule.rotation,
                                      disc.spinner.height_m)
    who = replays.granule(g.count)
    landed = flight_model.fly(replays.position_m, replays.height_m, replays.velocity_m_s, g.diameter_m[who],
                              g.density_kg_m3, disc.flight, spin_rad_s=replays.spin_rad_s)
    return rotations.plate_copied_sample(throw, turn, landing_m, free_landing, replays, landed.position_m[:, 0])


def _flight(launch: Departure, granules: GranuleBatch, flying: np.ndarray, disc_height_m: np.ndarray,
            flight: Flight, mirrored_after: Optional[int]) -> flight_model.Landing:
    """Landings of the `flying` granules (disc frames). With `mirrored_after` = n, the
    flying granules are a disc pair whose second half mirrors the first n, and without
    crosswind the mirrored granules land mirrored, to the bit (the flight's arithmetic is
    odd in x): only the first n fly."""
    position, height, velocity3, spin = launch_columns(launch, flying, disc_height_m)
    flown = int(flying.sum()) if mirrored_after is None else mirrored_after
    landing = flight_model.fly(position[:flown], height[:flown], velocity3[:flown],
                               granules.diameter_m[flying][:flown], granules.density_kg_m3, flight,
                               spin_rad_s=spin[:flown])
    return landing if mirrored_after is None else discs.mirrored_landing(landing)


def launch_columns(launch: Departure, flying: np.ndarray, disc_height_m: np.ndarray) -> tuple[np.ndarray, ...]:
    """What the flight takes of the `flying` granules' launch states: launch point (M, 2),
    height above the ground (M,; the disc's height plus the granule's, never below 0),
    velocity with its vertical part (M, 3) and spin (M,)."""
    velocity3 = np.column_stack([launch.velocity_m_s[flying], launch.vertical_velocity_m_s[flying]])
    height = np.maximum(disc_height_m[flying] + launch.height_m[flying], 0.0)
    return launch.position_m[flying], height, velocity3, launch.spin_rad_s[flying]


def departure_summary(departure: Departure, omega_rad_s: float, means: Optional[tuple] = None) -> dict:
    """Means over departed granules: speed, spin, angle from the tangent, time on the spinner
    (`means`: `departure.means(omega_rad_s)`, where already computed).

    The departure angle is measured from the disc's tangent at the departure point
    (direction of rotation) towards the outward radial: 0 deg tangential, 90 deg radial.
    """
    count, speed, speed_sd, spin, angle, time_s = departure.means(omega_rad_s) if means is None else means
    if not count:
        return {"speed_mean_m_s": None, "speed_std_m_s": None, "spin_mean_rad_s": None,
                "angle_mean_deg": None, "time_on_spinner_mean_s": None}  # nothing to average
    return {"speed_mean_m_s": speed, "speed_std_m_s": speed_sd, "spin_mean_rad_s": spin, "angle_mean_deg": angle,
            "time_on_spinner_mean_s": time_s}


def _notes(scene: Scene, model: str, departure: Departure, launch: Departure, trays: pattern.Trays) -> list[str]:
    """Warnings about the run: the deflectors' own, an ignored time step, passes that do not meet."""
    p = scene.pattern
    notes = list(launch.notes)
    if departure.dt_s == 0.0 and scene.sim.dt_s is not None:
        notes.append(f"sim.dt_s = {scene.sim.dt_s:g} s is ignored: the {model} model has no time step")
    if trays.total_kg > 0.0 and p.target_swath_m > 2.0 * trays.pattern_width_m:
        notes.append(f"the target swath {p.target_swath_m:g} m is over twice the pattern's width "
                     f"({trays.pattern_width_m:g} m): passes do not meet, so the CV there says little")
    return notes
