"""Release-angle copies: each spinner run reused at several release angles, exactly.

Why it is exact. The disc is axisymmetric and the spinner's phase at release is uniform
and independent of everything else, so what happens on the disc depends only on the
release radius r, the release angle relative to the vanes psi = theta - phase, and the
granule. Turning a granule's release point and phase by the same angle s turns its
whole path, and its departure state, by s. So one spinner run gives the departure of
the granule released at (r, theta + s, phase + s) for any s, for the price of a rotation.

The release point is the feed point (r0, theta0) plus an isotropic normal offset of
s.d. sigma per axis. Its density in polar coordinates about the axis is proportional to
exp(-(r^2 + r0^2 - 2 r r0 cos(theta - theta0)) / (2 sigma^2)), so given r the release
angle is von Mises(theta0, kappa = r r0 / sigma^2). Copy k of a granule takes a fresh
angle theta'_k from that law (copy 0 is the granule itself) and the shift
s_k = theta'_k - theta; the phase shifts by s_k too, so psi stays and phase'_k is again
uniform and independent. Every copy is therefore a draw from the granule distribution
itself, and the mean over copies is an unbiased estimate; copies of one granule share
(r, psi, size) and are dependent, but they stay in the granule's replicate, so the
replicates remain independent and the CV's bias correction and standard error
(`spread.estimate`) hold unchanged. A granule whose release point was pulled back
inside the vanes (the clip of `sample_granules`) is not von Mises in angle; its copies
keep its own angle (s = 0), which is still exact.

Each copy carries 1/K of its granule's mass. The angles of replicate r come from a
generator seeded by (seed, r, COPY_STREAM) alone, so pooled runs stay the one long run.

The copies cost no spinner run and no flight: without wind or forward speed the flight
is rotation-equivariant about the disc's axis (drag, gravity and the Magnus lift about
the vertical axis turn with the granule), so a copy lands where its granule lands,
turned by s. What they cost is a von Mises draw, a rotation and a tray bin each.

Plates break the symmetry: a turned granule meets them elsewhere. But a copy whose
straight path clears every plate meets none, so it lands as its granule's plate-free
throw, turned (one extra flight per granule whose own path comes near a plate); copy 0
is the granule's own run; the other copies near a plate pass the plates by the
compiled plate stage, and those it bounces fly each on their own (`plate_replays`,
`plate_copied_sample`; spread.pipeline runs the stages).

When they do not apply (`copies_for`): a flight with a direction (wind or forward speed:
every copy would have to fly), a feed without spread (a single release angle) and
plates beside two discs. There the count is 1 and the run is the plain one, bit for bit.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from spreadgym.config.scene import Deflector, Flight, Scene
from spreadgym.physics.compiled.options import KERNEL
from spreadgym.physics.compiled.plates import MAX_BOUNCES, near_plates, pack_plates, pass_plates, path_near_plates
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR
from spreadgym.physics.departure import Departure
from spreadgym.physics.geometry import ZONE_MARGIN_M, advance_to_circle, zone_radius_m
from spreadgym.physics.granules import GranuleBatch, clip_test_radius_m
from spreadgym.spread import von_mises
from spreadgym.spread.discs import Disc, Throw
from spreadgym.spread.estimate import TraySample
from spreadgym.spread.twin import onto_disc_axis

COPY_STREAM = 1
"""Third word of the seed of the copies' angles (the sampler's uniforms use (seed, r))."""


def copies_for(scene: Scene, discs: int = 1) -> tuple[int, str]:
    """How many release angles each simulated granule takes in `scene` (one of `discs` discs), and why."""
    asked = int(scene.sim.angle_copies)
    if asked == 1:
        return 1, "sim.angle_copies = 1"
    if scene.deflectors and discs > 1:
        return 1, "plates beside two discs: one release angle per granule"
    if not flight_is_equivariant(scene.flight):
        return 1, "wind or forward speed gives the flight a direction: one release angle per granule"
    if scene.feed.spread_m == 0.0 or scene.feed.radius_m == 0.0:
        return 1, "the feed has a single release angle (no spread or on the axis): nothing to copy"
    if scene.deflectors:
        return asked, ("a feed spot and a flight without direction: copies whose path clears the plates are exact, "
                       "the others near a plate pass it by the closed-form ray stage")
    return asked, "no plates, a feed spot and a flight without direction: the copies are exact"


def flight_is_equivariant(flight: Flight) -> bool:
    """Whether the flight turns with the launch state about the disc's axis (no wind, no forward speed)."""
    return flight.forward_speed_m_s == 0.0 and tuple(flight.wind_m_s) == (0.0, 0.0)


class Turn:
    """The rotations of K copies of N granules, copy-major, as cosines and sines (K * N,)."""

    def __init__(self, cos: np.ndarray, sin: np.ndarray, copies: int) -> None:
        self.cos, self.sin, self.copies = cos, sin, copies


def copy_turns(granules: GranuleBatch, scene: Scene, copies: int, seed: int, first_replicate: int) -> Turn:
    """The turns s_k of `copies` copies of every granule; copy 0 is the granule itself (s = 0).

    s_k = theta0 + phi_k - theta, so s_k is von Mises about theta0 - theta; the other
    angles come in antithetic pairs theta0 +- phi (the law is symmetric about the feed
    angle, so each is still a von Mises draw; the pair halves the draws and cancels the
    odd part of the noise). Only cos s and sin s are needed, and
    `von_mises.fill_turns` gives them without forming an angle. `granules` holds the
    replicates first_replicate, first_replicate + 1, ... in order (each a consecutive run
    of granules), `granules.replicate` 0, 1, ..."""
    if copies == 1:
        return Turn(np.ones(granules.count), np.zeros(granules.count), 1)
    return drawn_turns(granules.replicate, TurnLaws.of(granules.release_xy_m, [scene], [granules.count]), copies,
                       seed, first_replicate)


@dataclasses.dataclass(frozen=True)
class TurnLaws:
    """The von Mises law of each granule's turn, for granules of one or more scenes side
    by side: cos and sin of its mean theta0 - theta, its concentration r r0 / sigma^2, and
    whether the clip pulled its release point back (its turn is then 0)."""

    cos_mu: np.ndarray
    sin_mu: np.ndarray
    kappa: np.ndarray
    held: np.ndarray  # bool

    @staticmethod
    def of(release_xy_m: np.ndarray, scenes: Sequence[Scene], counts: Sequence[int]) -> "TurnLaws":
        """The laws of `counts[d]` granules of each scene d in turn (release points (N, 2),
        disc frame): one numpy pass for all of them, each scene's constants repeated."""
        xy = release_xy_m
        r = np.hypot(xy[:, 0], xy[:, 1])
        to_feed = np.repeat([s.feed.angle_rad for s in scenes], counts) - np.arctan2(xy[:, 1], xy[:, 0])
        kappa = r * np.repeat([s.feed.radius_m for s in scenes], counts) / np.repeat(
            [s.feed.spread_m**2 for s in scenes], counts)
        held = ~(r < np.repeat([clip_test_radius_m(s) for s in scenes], counts))
        return TurnLaws(np.cos(to_feed), np.sin(to_feed), kappa, held)


def turn_streams(replicate: np.ndarray, first: np.ndarray, seeds: Sequence[int],
                 first_replicates: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """The replicates of granules of one or more designs side by side (design d's granules
    first[d]..first[d + 1] - 1, its replicates 0, 1, ... each a consecutive run), as their
    turns are drawn: each design's first run (D + 1,), each run's first and last-plus-one
    granule within its design, and its stream (seeds[d], first_replicates[d] + replicate,
    COPY_STREAM)."""
    starts = np.ones(replicate.size, dtype=bool)
    starts[1:] = replicate[1:] != replicate[:-1]
    starts[first[:-1]] = True  # every design starts a run
    at = np.flatnonzero(starts)
    owner = np.searchsorted(first, at, side="right") - 1
    stops = np.append(at[1:], replicate.size)
    streams = [(seeds[o], first_replicates[o] + int(replicate[a]), COPY_STREAM) for o, a in zip(owner, at)]
    return np.searchsorted(at, first), at - first[owner], stops - first[owner], streams


def drawn_turns(replicate: np.ndarray, laws: TurnLaws, copies: int, seed: int, first_replicate: int) -> Turn:
    """`copy_turns` of granules in replicates `replicate` (0, 1, ... in consecutive runs)
    whose turns follow `laws`. Each replicate draws from its own stream (seed,
    first_replicate + replicate, COPY_STREAM), so the turns are the same however the
    granules were batched."""
    n = replicate.size
    # rows 1.. are filled for every granule below (each is in one replicate); row 0 is s = 0
    cos_turn, sin_turn = np.empty((copies, n)), np.empty((copies, n))
    cos_turn[0], sin_turn[0] = 1.0, 0.0
    _, starts, stops, streams = turn_streams(replicate, np.array([0, n]), [seed], [first_replicate])
    von_mises.fill_turns(streams, starts, stops, laws.kappa, laws.cos_mu, laws.sin_mu, cos_turn, sin_turn)
    held = np.flatnonzero(laws.held)  # a point pulled back by the clip keeps its angle (s = 0)
    if held.size:
        cos_turn[:, held], sin_turn[:, held] = 1.0, 0.0
    return Turn(cos_turn.ravel(), sin_turn.ravel(), copies)


def copied_sample(throws: list[Throw], landings_m: list[np.ndarray], turns: list[Turn], parts: list[Disc],
                  mirror: bool) -> tuple[TraySample, list[float]]:
    """The tray sample of every disc's copies, and each disc's mass thrown onto the other disc (kg).

    `throws`, `landings_m` (N, 2; NaN for granules that did not depart) are in each disc's
    frame, its axis at the origin; the flight turns with the copies (`flight_is_equivariant`).
    A copy whose turned launch ray meets the other disc is intercepted, as
    `twin.intercepted` marks granules: the granule's own ray is tested against the other
    disc's axis turned back by the copy's angle (the same geometry, turned as a whole).
    With `mirror`, the second disc takes the first's marks."""
    xs, masses, replicates, lost_kg = [], [], [], []
    local_x = None  # the first disc's copies across the track, its own frame
    for i, (throw, landed_at, turn, disc) in enumerate(zip(throws, landings_m, turns, parts)):
        if mirror and i == 1:  # the first disc's copies mirrored: x -> -x, same masses and marks
            xs.append(disc.centre_m[0] - local_x)
            masses.append(masses[0])
            replicates.append(replicates[0])
            lost_kg.append(lost_kg[0])
            continue
        g, launch = throw.granules, throw.launch
        copies = turn.copies
        every = bool(launch.departed.all())  # the usual case: every copy, in order
        # copy-major: copy k of granule j is k N + j
        departed_copies = np.zeros(0, dtype=np.int64) if every else np.flatnonzero(np.tile(launch.departed, copies))
        size = copies * g.count if every else departed_copies.size
        local_x, mass, replicate = np.empty(size), np.empty(size), np.empty(size, dtype=g.replicate.dtype)
        turned_copies(every, departed_copies, turn.cos, turn.sin, landed_at[:, 0], landed_at[:, 1], g.mass_kg,
                      g.replicate, copies, local_x, mass, replicate)
        lost = 0.0  # one disc: every copy is kept
        if len(parts) > 1:
            if every:
                departed_copies = np.arange(size)
            c, s, granule = turn.cos[departed_copies], turn.sin[departed_copies], departed_copies % g.count
            other = np.subtract(parts[1 - i].centre_m, disc.centre_m)  # the other axis, this disc's frame
            axis = np.column_stack([c * other[0] + s * other[1], c * other[1] - s * other[0]])
            kept = ~onto_disc_axis(launch.position_m[granule], launch.velocity_m_s[granule], g.radius_m[granule],
                                   axis, parts[1 - i].scene.spinner.radius_m)
            lost = float(mass[~kept].sum())
            local_x, mass, replicate = local_x[kept], mass[kept], replicate[kept]
        xs.append(local_x + disc.centre_m[0])
        masses.append(mass)
        replicates.append(replicate)
        lost_kg.append(lost)
    if len(xs) == 1:
        return TraySample(xs[0], masses[0], replicates[0]), lost_kg
    return TraySample(np.concatenate(xs), np.concatenate(masses), np.concatenate(replicates)), lost_kg


@KERNEL
def turned_copies(every, departed_copies, cos, sin, landed_x, landed_y, mass, replicate, copies, out_x, out_mass,
                  out_replicate):
    """Where copies land across the track (disc frame), their masses and replicates:
    every copy in copy-major order when `every`, else those listed in `departed_copies`.

    `departed_copies` (M,): copy-major indices k N + j (copy k of granule j, N granules);
    `cos`, `sin` (K N,): the copies' turns; `landed_x`, `landed_y` (N,): the granules'
    landings in the disc's frame (m); `mass` (N,) kg, shared by the `copies` copies.
    Fills `out_x`, `out_mass`, `out_replicate` (M,). Compiled and GIL-free: batches finish scenes side by side."""
    n = landed_x.size
    for i in range(out_x.size):
        row = i if every else departed_copies[i]
        j = row % n
        out_x[i] = cos[row] * landed_x[j] - sin[row] * landed_y[j]
        out_mass[i] = mass[j] / copies
        out_replicate[i] = replicate[j]


def straight_paths(departure: Departure, plates: Sequence[Deflector], radius_m: np.ndarray) -> Departure:
    """Every departed granule's state where its straight plan-view path leaves the plate
    zone, as if there were no plates: what both deflector stages hand the flight for a
    granule that passes no plate (`pymunk_deflectors.deflect_pymunk`, closed form)."""
    zone = zone_radius_m(plates, float(radius_m.max()))
    gone = departure.departed
    elapsed = np.zeros(departure.time_s.shape)
    elapsed[gone] = advance_to_circle(departure.position_m[gone], departure.velocity_m_s[gone], zone)
    position = departure.position_m.copy()
    position[gone] = departure.position_m[gone] + elapsed[gone, None] * departure.velocity_m_s[gone]
    return dataclasses.replace(
        departure, position_m=position, time_s=departure.time_s + elapsed,
        height_m=departure.height_m + departure.vertical_velocity_m_s * elapsed - 0.5 * GRAVITY_M_S2 * elapsed**2,
        vertical_velocity_m_s=departure.vertical_velocity_m_s - GRAVITY_M_S2 * elapsed)


def near_own_paths(throw: Throw, free: Departure, plates: Sequence[Deflector]) -> np.ndarray:
    """(N,) bool: the departed granules whose own straight path comes near a plate (those
    the pymunk stage steps); `free` from `straight_paths`."""
    gone = np.flatnonzero(free.departed)
    near = np.zeros(free.time_s.shape, dtype=bool)
    near[gone] = near_plates(throw.departure.position_m, free.position_m, throw.granules.radius_m, plates, granule=gone)
    return near


@dataclasses.dataclass(frozen=True)
class PlateReplays:
    """The copies (k > 0) of one disc's departed granules that the plates turned: their
    copy-major index k N + j, and their launch states where they leave the plate zone
    (disc frame; height above the ground, never below it)."""

    row: np.ndarray  # (M,) k N + j
    position_m: np.ndarray  # (M, 2)
    height_m: np.ndarray  # (M,)
    velocity_m_s: np.ndarray  # (M, 3) with the vertical speed
    spin_rad_s: np.ndarray  # (M,)

    def granule(self, count: int) -> np.ndarray:
        return self.row % count


def plate_replays(throw: Throw, free: Departure, turn: Turn, plates: Sequence[Deflector], contacts: Sequence,
                  rotation: str, disc_height_m: float) -> PlateReplays:
    """Every departed copy (k > 0) whose turned straight path comes near a plate
    (`near_plates`' test and margin) is carried past the plates by the compiled plate
    stage (`physics.compiled.plates`); those it bounced are returned with their launch
    states. The others meet no plate and land as their granule's plate-free throw, turned."""
    g, departure = throw.granules, throw.departure
    n = g.count
    gone = np.flatnonzero(free.departed)
    most = (turn.copies - 1) * gone.size
    out = (np.empty(most, dtype=np.int64), np.empty((most, 2)), np.empty(most), np.empty((most, 3)), np.empty(most))
    table = pack_plates(plates, [c.friction for c in contacts], [c.restitution for c in contacts])
    kept = replay_plate_copies(gone, n, turn.copies, turn.cos, turn.sin, departure.position_m, free.position_m,
                               departure.velocity_m_s, departure.spin_rad_s, departure.height_m,
                               departure.vertical_velocity_m_s, g.radius_m, table, ZONE_MARGIN_M,
                               zone_radius_m(plates, float(g.radius_m.max())),
                               0.0 if rotation == "locked" else 1.0 / SPHERE_INERTIA_FACTOR, MAX_BOUNCES, GRAVITY_M_S2,
                               disc_height_m, *out)
    return PlateReplays(*(a[:kept] for a in out))


@KERNEL
def replay_plate_copies(gone, n, copies, cos, sin, position, free_end, velocity, spin, height, vz, radius, plates,
                        margin, zone, inv_kappa, max_bounces, gravity, disc_height, out_row, out_position, out_height,
                        out_velocity, out_spin):
    """`plate_replays`' work: copy k of granule j = gone[i] is row k N + j of cos and sin;
    its straight path is the granule's (position to free_end) turned. Fills the first M
    rows of the outputs, copy-major, and returns M. Compiled and GIL-free."""
    kept = 0
    for k in range(1, copies):
        for i in range(gone.size):
            j = gone[i]
            row = k * n + j
            c, s = cos[row], sin[row]
            if not path_near_plates(c * position[j, 0] - s * position[j, 1], s * position[j, 0] + c * position[j, 1],
                                    c * free_end[j, 0] - s * free_end[j, 1], s * free_end[j, 0] + c * free_end[j, 1],
                                    radius[j], plates, margin):
                continue
            px, py, vx, vy, w, elapsed, bounces, _ = pass_plates(
                c * position[j, 0] - s * position[j, 1], s * position[j, 0] + c * position[j, 1],
                c * velocity[j, 0] - s * velocity[j, 1], s * velocity[j, 0] + c * velocity[j, 1], spin[j], radius[j],
                plates, zone, inv_kappa, max_bounces)
            if bounces == 0:
                continue
            out_row[kept] = row
            out_position[kept, 0], out_position[kept, 1] = px, py
            out_height[kept] = max(disc_height + (height[j] + vz[j] * elapsed - 0.5 * gravity * elapsed**2), 0.0)
            out_velocity[kept, 0], out_velocity[kept, 1], out_velocity[kept, 2] = vx, vy, vz[j] - gravity * elapsed
            out_spin[kept] = w
            kept += 1
    return kept


def plate_copied_sample(throw: Throw, turn: Turn, landing_m: np.ndarray, free_landing_m: np.ndarray,
                        replays: PlateReplays, replayed_x_m: np.ndarray) -> TraySample:
    """The tray sample of one disc's copies among plates (disc axis at the origin), every
    departed copy in copy-major order, each 1/copies of its granule's mass: copy 0 is the
    granule itself, landing where the model's own plate stage put it (`landing_m`); a copy
    the plates turned lands where it flew (`replayed_x_m`, across the track, in the order
    of `replays`); every other copy meets no plate and lands where its granule's
    plate-free throw lands (`free_landing_m`), turned."""
    g = throw.granules
    gone = np.flatnonzero(throw.launch.departed)
    size = turn.copies * gone.size
    x, mass, replicate = np.empty(size), np.empty(size), np.empty(size, dtype=g.replicate.dtype)
    fill_plate_copies(gone, g.count, turn.copies, turn.cos, turn.sin, landing_m, free_landing_m, replays.row,
                      replayed_x_m, g.mass_kg, g.replicate, x, mass, replicate)
    return TraySample(x, mass, replicate)


@KERNEL
def fill_plate_copies(gone, n, copies, cos, sin, landing, free_landing, replay_row, replay_x, mass, replicate, out_x,
                      out_mass, out_replicate):
    """`plate_copied_sample`'s work, one pass over the departed copies. Compiled and GIL-free."""
    at = 0
    next_replay = 0
    for k in range(copies):
        for i in range(gone.size):
            j = gone[i]
            row = k * n + j
            if k == 0:
                out_x[at] = landing[j, 0]
            elif next_replay < replay_row.size and replay_row[next_replay] == row:
                out_x[at] = replay_x[next_replay]
                next_replay += 1
            else:
                out_x[at] = cos[row] * free_landing[j, 0] - sin[row] * free_landing[j, 1]
            out_mass[at] = mass[j] / copies
            out_replicate[at] = replicate[j]
            at += 1
