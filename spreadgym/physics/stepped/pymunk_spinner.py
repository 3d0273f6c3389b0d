"""The `pymunk` spinner model: granules on a spinning disc with vanes, in plan view.

The spinner is a kinematic pymunk body turning at omega and carrying the vanes as
segments (radius = half the vane thickness), so contacts see the right surface
velocity. Granules are circles; rotation `free` gives them a sphere's moment of
inertia (2/5 m r^2, spin about the vertical axis: they can roll along a vane face),
`locked` an infinite one (the point mass of the classic models). Granules never
touch each other (one shape group). The height above the disc (drop, bounces) is the
1-D model of `vertical.py`; the disc's Coulomb drag is applied as a body force through
`pymunk.batch`, limited so it never reverses the relative velocity within a step.

The vane's rolling resistance (`contacts.vane_rolling_resistance`, mu_r) is a torque
against each granule's spin relative to the vane, s - omega: over a step, an angular
impulse of mu_r r J_n (J_n the normal impulse the vanes gave it in the step before),
at most what stops that relative spin (it never reverses it, as the disc friction).
It is written as a torque before the step, so the solver's friction sees it.

Granules are spread over several small independent spaces (interleaved by release
phase): Chipmunk's broad phase then stays cheap although all granules start on one
ring, and the numpy work is still done once per step for all of them.
A fresh set of spaces is built for every run, so a seed reproduces a result bit for bit.
"""

from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np
import pymunk
import pymunk.batch as batch

from spreadgym.config.scene import Scene
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import DEPARTED, Departure
from spreadgym.physics.disc_friction import friction_velocity_change
from spreadgym.physics.geometry import machine_frame_tracks, vane_segments
from spreadgym.physics.granules import GranuleBatch
from spreadgym.physics.numerics import choose_time_step, collision_bias_for
from spreadgym.physics.stepped.finish import (
    MAX_SPINNER_TIME_S,
    DepartureRecord,
    Kinematics,
    held_by_disc,
    start_at_vane_tops,
)
from spreadgym.physics.vertical import VerticalState

GRANULES_PER_SPACE = 200
SOLVER_ITERATIONS = 10
COLLISION_SLOP_M = 1e-5

# Collision categories: a granule touches the vanes only while it is lower than they are.
_GRANULE, _VANE = 0b01, 0b10
_BELOW_VANE_TOPS = pymunk.ShapeFilter(group=1, categories=_GRANULE, mask=_VANE)
_ABOVE_VANE_TOPS = pymunk.ShapeFilter(group=1, categories=_GRANULE, mask=0)

_CONTACTS = (
    batch.ArbiterFields.BODY_A_ID
    | batch.ArbiterFields.BODY_B_ID
    | batch.ArbiterFields.TOTAL_IMPULSE
    | batch.ArbiterFields.NORMAL
)
_STATE = (
    batch.BodyFields.BODY_ID
    | batch.BodyFields.POSITION
    | batch.BodyFields.VELOCITY
    | batch.BodyFields.ANGULAR_VELOCITY
)


class _SpinnerSpace:
    """One pymunk space: the spinner body with its vanes and a share of the granules."""

    def __init__(self, scene, contacts, granules, indices, dt, start_xy, below_vane_tops):
        space = pymunk.Space()
        space.iterations = SOLVER_ITERATIONS
        space.collision_slop = COLLISION_SLOP_M
        space.collision_bias = collision_bias_for(dt)
        spinner = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        spinner.angular_velocity = scene.spinner.omega_rad_s
        inner, outer = vane_segments(scene)
        half_thickness = 0.5 * scene.vanes.thickness_m
        vanes = [pymunk.Segment(spinner, tuple(a), tuple(b), half_thickness) for a, b in zip(inner, outer)]
        for vane in vanes:
            vane.elasticity = contacts.vane_restitution
            vane.friction = contacts.vane_friction
            vane.filter = pymunk.ShapeFilter(categories=_VANE, mask=_GRANULE)
        space.add(spinner, *vanes)
        locked = scene.granule.rotation == "locked"
        self.shapes = {}
        for i in indices:
            mass, radius = float(granules.mass_kg[i]), float(granules.radius_m[i])
            moment = math.inf if locked else SPHERE_INERTIA_FACTOR * mass * radius * radius
            body = pymunk.Body(mass, moment)
            body.position = tuple(start_xy[i])
            shape = pymunk.Circle(body, radius)
            shape.elasticity, shape.friction = 1.0, 1.0
            shape.filter = _BELOW_VANE_TOPS if below_vane_tops[i] else _ABOVE_VANE_TOPS
            space.add(body, shape)
            self.shapes[body.id] = (body, shape)
        self.space = space
        self.buffer = batch.Buffer()
        self._write_buffer = batch.Buffer()
        self._contact_buffer = batch.Buffer()
        # Body ids (sorted) and their granule indices; the spinner maps to -1.
        ids = np.array([spinner.id] + list(self.shapes), dtype=np.uintp)
        order = np.argsort(ids)
        self._sorted_ids = ids[order]
        self._index = np.concatenate([[-1], np.asarray(indices, dtype=np.int64)])[order]

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Granule indices of the rows (spinner row = -1) and the (rows, 5) state."""
        self.buffer.clear()
        batch.get_space_bodies(self.space, _STATE, self.buffer)
        ids = np.frombuffer(self.buffer.int_buf(), dtype=np.uintp)
        rows = self._index[np.searchsorted(self._sorted_ids, ids)]
        return rows, np.frombuffer(self.buffer.float_buf(), dtype=np.float64).reshape(-1, 5)

    def write_forces(self, forces: np.ndarray) -> None:
        """Set the force (rows of fx, fy) or the force and torque (fx, fy, torque) of every
        row (rows in the order of the last read)."""
        fields = batch.BodyFields.FORCE | batch.BodyFields.TORQUE if forces.shape[1] == 3 else batch.BodyFields.FORCE
        self._forces = np.ascontiguousarray(forces, dtype=np.float64).ravel()
        self._write_buffer.set_float_buf(self._forces)
        batch.set_space_bodies(self.space, fields, self._write_buffer)

    def vane_impulses(self) -> tuple[np.ndarray, np.ndarray]:
        """Granule indices and the normal impulse (N s) of each of their vane contacts in the last step."""
        self._contact_buffer.clear()
        batch.get_space_arbiters(self.space, _CONTACTS, self._contact_buffer)
        ids = np.frombuffer(self._contact_buffer.int_buf(), dtype=np.uintp).reshape(-1, 2)
        data = np.frombuffer(self._contact_buffer.float_buf(), dtype=np.float64).reshape(-1, 4)
        ends = self._index[np.searchsorted(self._sorted_ids, ids)]
        granule = np.max(ends, axis=1)  # the other end is the spinner (-1)
        return granule, np.abs(data[:, 0] * data[:, 2] + data[:, 1] * data[:, 3])

    @property
    def empty(self) -> bool:
        return not self.shapes

    def set_below_vane_tops(self, body_ids: np.ndarray, below: np.ndarray) -> None:
        """Let granules that fell below the vane tops meet the vanes (and the reverse)."""
        for body_id, is_below in zip(body_ids, below):
            self.shapes[int(body_id)][1].filter = _BELOW_VANE_TOPS if is_below else _ABOVE_VANE_TOPS

    def remove(self, body_ids: np.ndarray) -> None:
        objects = []
        for body_id in body_ids:
            objects.extend(self.shapes.pop(int(body_id)))
        if objects:
            self.space.remove(*objects)


def _resisting_torque(spaces, rolling_resistance, n, radius_m, moment, relative_spin, dt):
    """Torque (N m, (n,)) of the vanes' rolling resistance over the next step: an angular
    impulse of mu_r r J_n (J_n: the vane normal impulse of the last step) against the spin
    relative to the vane, at most the impulse that stops it."""
    impulse = np.zeros(n)
    for space in spaces:
        granule, normal = space.vane_impulses()
        impulse += np.bincount(granule, normal, minlength=n)
    angular = np.minimum(rolling_resistance * radius_m * impulse, moment * np.abs(relative_spin))
    return -np.sign(relative_spin) * angular / dt


def simulate_pymunk(
    scene: Scene,
    granules: GranuleBatch,
    contacts: Contacts,
    progress: Optional[Callable[[float], None]] = None,
    disc_friction_guard: bool = True,
    track_count: int = 0,
) -> Departure:
    """Run every granule from release to the disc edge; return their departure states.

    `track_count` granules (the first ones) also have their paths recorded for plots.
    """
    omega = scene.spinner.omega_rad_s
    radius = scene.spinner.radius_m
    choice = choose_time_step(scene, float(granules.radius_m.min()))
    dt = choice.dt_s
    n = granules.count
    # The run starts at the vane tops (see finish.py).
    vane_top = scene.vanes.height_m
    first = start_at_vane_tops(scene, granules)
    start = first.position_m
    vertical = VerticalState(first.height_m, n, contacts.disc_restitution, dt, first.vz_m_s)
    below_vane_tops = vertical.z < vane_top

    n_spaces = max(1, math.ceil(n / GRANULES_PER_SPACE))
    spaces = [
        _SpinnerSpace(scene, contacts, granules, np.arange(k, n, n_spaces), dt, start, below_vane_tops)
        for k in range(n_spaces)
    ]

    position, velocity, spin = start.copy(), np.zeros((n, 2)), np.zeros(n)
    record = DepartureRecord(first)
    active = np.ones(n, dtype=bool)
    stuck_accel = contacts.disc_friction * GRAVITY_M_S2
    rolling_resistance = 0.0 if scene.granule.rotation == "locked" else contacts.vane_rolling_resistance
    moment = SPHERE_INERTIA_FACTOR * granules.mass_kg * granules.radius_m**2

    steps = int(math.ceil(MAX_SPINNER_TIME_S / dt))
    tracked = np.arange(min(track_count, n))
    track_points = []
    t = 0.0
    for step in range(steps + 1):
        t = step * dt
        reads = [s.read() for s in spaces]
        rows = np.concatenate([r for r, _ in reads])
        state = np.concatenate([d for _, d in reads])
        granule_rows = rows >= 0
        idx = rows[granule_rows]
        new_pos, new_vel, new_spin = state[granule_rows, 0:2], state[granule_rows, 2:4], state[granule_rows, 4]

        # Departure: the centre crossed the disc radius during the last step.
        r_new = np.hypot(new_pos[:, 0], new_pos[:, 1])
        leaving = r_new >= radius
        if leaving.any():
            li = idx[leaving]
            frac = record.depart(li, Kinematics(position[li], velocity[li], spin[li]),
                                 Kinematics(new_pos[leaving], new_vel[leaving], new_spin[leaving]), radius, t, dt)
            record.height_m[li], record.vz_m_s[li] = vertical.at_fraction(li, frac)

        stuck = ~leaving & vertical.resting[idx] & held_by_disc(new_pos, new_vel, omega, stuck_accel, dt)
        if stuck.any():
            record.stuck(idx[stuck])
        finished = idx[leaving | stuck]
        active[finished] = False
        position[idx], velocity[idx], spin[idx] = new_pos, new_vel, new_spin
        if tracked.size:
            track_points.append(np.where(active[tracked, None], position[tracked], np.nan))
        if not active.any() or step == steps:
            break

        normal_impulse = vertical.step()
        dv = friction_velocity_change(
            new_pos, new_vel, omega, contacts.disc_friction, normal_impulse[idx], disc_friction_guard
        )
        forces = np.zeros((rows.size, 3 if rolling_resistance > 0.0 else 2))
        forces[granule_rows, :2] = dv * (granules.mass_kg[idx] / dt)[:, None]
        if rolling_resistance > 0.0:
            forces[granule_rows, 2] = _resisting_torque(spaces, rolling_resistance, n, granules.radius_m, moment,
                                                        spin - omega, dt)[idx]
        now_below = vertical.z < vane_top
        offset = 0
        for space, (space_rows, _) in zip(spaces, reads):
            count = space_rows.size
            space.write_forces(forces[offset : offset + count])
            offset += count
            is_granule = space_rows >= 0
            ids = np.frombuffer(space.buffer.int_buf(), dtype=np.uintp)
            rows_index = np.where(is_granule, space_rows, 0)
            gone = is_granule & ~active[rows_index]
            crossed = is_granule & ~gone & (now_below[rows_index] != below_vane_tops[rows_index])
            if crossed.any():
                space.set_below_vane_tops(ids[crossed], now_below[space_rows[crossed]])
            if gone.any():
                space.remove(ids[gone])
        below_vane_tops = now_below
        spaces = [space for space in spaces if not space.empty]
        for space in spaces:
            space.space.step(dt)
        if progress is not None:
            progress(t)

    # Retained granules keep their last state.
    tracks = machine_frame_tracks(track_points, record.position_m[tracked], first.spinner_angle_rad[tracked])
    kept = np.flatnonzero(record.outcome != DEPARTED)
    record.keep(kept, Kinematics(position[kept], velocity[kept], spin[kept]), vertical.z[kept], vertical.vz[kept])
    notes = [
        f"time step {dt:.3g} s: {choice.reason}",
        f"free fall above the vane tops solved exactly ({first.fall_s * 1e3:.1f} ms)",
    ]
    return record.departure(t, "pymunk", dt, notes, tracks)
