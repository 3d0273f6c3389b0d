"""Deflector plates in pymunk: granules that left the disc, until they leave the plate zone.

Plates are static capsules (segment + half thickness) in the machine frame. Granules
keep their departure state: horizontal motion in plan view (no drag over this short
distance), spin for free rotation, and their height falling ballistically. Each
granule runs on its own clock from its departure (granules never touch each other),
and its state is taken where its centre crosses the zone circle, which encloses every
plate; the flight starts from there.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import pymunk
import pymunk.batch as batch

from spreadgym.contacts import PlateContact
from spreadgym.physics.departure import Departure
from spreadgym.physics.vertical import GRAVITY_M_S2
from spreadgym.scene import Deflector

GRANULES_PER_SPACE = 100
TUNNEL_SAFETY = 0.5
ZONE_MARGIN_M = 0.01
MAX_ZONE_TIME_S = 2.0
_STATE = (
    batch.BodyFields.BODY_ID
    | batch.BodyFields.POSITION
    | batch.BodyFields.VELOCITY
    | batch.BodyFields.ANGULAR_VELOCITY
)


def zone_radius_m(plates: Sequence[Deflector], max_granule_radius_m: float) -> float:
    """Radius of the circle about the axis that holds every plate with clearance."""
    reach = 0.0
    for plate in plates:
        for x, y in plate.endpoints():
            reach = max(reach, math.hypot(x, y) + 0.5 * plate.thickness_m)
    return reach + max_granule_radius_m + ZONE_MARGIN_M


def deflector_time_step(speed_max_m_s: float, min_granule_radius_m: float, plates: Sequence[Deflector]) -> float:
    """Half the step at which the fastest granule could jump over the thinnest plate."""
    reach = min_granule_radius_m + 0.5 * min(p.thickness_m for p in plates)
    return TUNNEL_SAFETY * reach / max(speed_max_m_s, 1e-9)


def advance_to_circle(position, velocity, radius_m):
    """Time (N,) for straight-line motion from inside to the circle |x| = radius."""
    a = np.sum(velocity * velocity, axis=1)
    b = 2.0 * np.sum(position * velocity, axis=1)
    c = np.sum(position * position, axis=1) - radius_m * radius_m
    disc = np.maximum(b * b - 4.0 * a * c, 0.0)
    return np.where(a > 0, (-b + np.sqrt(disc)) / np.maximum(2.0 * a, 1e-300), 0.0)


def deflect_pymunk(
    departure: Departure,
    plates: Sequence[Deflector],
    contacts: Sequence[PlateContact],
    radius_m: np.ndarray,
    mass_kg: np.ndarray,
    rotation: str,
) -> Departure:
    """Carry departed granules through the plate zone; return their states at its edge."""
    if not plates:
        return departure
    moving = np.flatnonzero(departure.departed)
    zone = zone_radius_m(plates, float(radius_m.max()))
    speed = departure.speed_m_s[moving]
    dt = deflector_time_step(float(speed.max(initial=0.0)), float(radius_m.min()), plates)

    position = departure.position_m.copy()
    velocity = departure.velocity_m_s.copy()
    spin = departure.spin_rad_s.copy()
    elapsed = np.zeros(position.shape[0])

    groups = [moving[k :: max(1, math.ceil(moving.size / GRANULES_PER_SPACE))] for k in
              range(max(1, math.ceil(moving.size / GRANULES_PER_SPACE)))]
    for group in groups:
        if group.size:
            _run_group(group, plates, contacts, radius_m, mass_kg, rotation, zone, dt,
                       position, velocity, spin, elapsed)

    height = departure.height_m + departure.vertical_velocity_m_s * elapsed - 0.5 * GRAVITY_M_S2 * elapsed**2
    return Departure(
        position_m=position,
        velocity_m_s=velocity,
        spin_rad_s=spin,
        height_m=height,
        vertical_velocity_m_s=departure.vertical_velocity_m_s - GRAVITY_M_S2 * elapsed,
        time_s=departure.time_s + elapsed,
        outcome=departure.outcome,
        model=departure.model,
        dt_s=departure.dt_s,
        notes=departure.notes + [f"deflectors: pymunk, step {dt:.3g} s, zone radius {zone:.3f} m"],
    )


def _run_group(group, plates, contacts, radius_m, mass_kg, rotation, zone, dt,
               position, velocity, spin, elapsed) -> None:
    """Step one space of granules until each crosses the zone circle (in place)."""
    space = pymunk.Space()
    space.collision_slop = 1e-5
    for plate, contact in zip(plates, contacts):
        a, b = plate.endpoints()
        shape = pymunk.Segment(space.static_body, a, b, 0.5 * plate.thickness_m)
        shape.elasticity, shape.friction = contact.restitution, contact.friction
        space.add(shape)
    no_contact = pymunk.ShapeFilter(group=1)
    index_of = {}
    for i in group:
        m, r = float(mass_kg[i]), float(radius_m[i])
        body = pymunk.Body(m, math.inf if rotation == "locked" else 0.4 * m * r * r)
        body.position, body.velocity = tuple(position[i]), tuple(velocity[i])
        body.angular_velocity = float(spin[i])
        shape = pymunk.Circle(body, r)
        shape.elasticity, shape.friction, shape.filter = 1.0, 1.0, no_contact
        space.add(body, shape)
        index_of[body.id] = (i, body, shape)

    buffer = batch.Buffer()
    previous = {i: (position[i].copy(), velocity[i].copy(), spin[i]) for i in group}
    for step in range(1, int(MAX_ZONE_TIME_S / dt) + 1):
        space.step(dt)
        buffer.clear()
        batch.get_space_bodies(space, _STATE, buffer)
        ids = np.frombuffer(buffer.int_buf(), dtype=np.uintp)
        state = np.frombuffer(buffer.float_buf(), dtype=np.float64).reshape(-1, 5)
        r_now = np.hypot(state[:, 0], state[:, 1])
        for row in np.flatnonzero(r_now >= zone):
            i, body, shape = index_of.pop(int(ids[row]))
            p0, v0, w0 = previous[i]
            p1, v1, w1 = state[row, 0:2], state[row, 2:4], state[row, 4]
            f = _fraction(p0, p1, zone)
            position[i], velocity[i] = p0 + f * (p1 - p0), v0 + f * (v1 - v0)
            spin[i], elapsed[i] = w0 + f * (w1 - w0), (step - 1 + f) * dt
            space.remove(body, shape)
        if not index_of:
            return
        for row, body_id in enumerate(ids):
            entry = index_of.get(int(body_id))
            if entry is not None:
                previous[entry[0]] = (state[row, 0:2].copy(), state[row, 2:4].copy(), state[row, 4])
    for i, _, _ in index_of.values():  # still inside after the time limit: leave as they are
        position[i], velocity[i], spin[i] = previous[i]
        elapsed[i] = MAX_ZONE_TIME_S


def _fraction(p0, p1, radius) -> float:
    d = p1 - p0
    a, b, c = d @ d, 2.0 * (p0 @ d), p0 @ p0 - radius * radius
    return float(np.clip((-b + math.sqrt(max(b * b - 4 * a * c, 0.0))) / max(2 * a, 1e-300), 0.0, 1.0))
