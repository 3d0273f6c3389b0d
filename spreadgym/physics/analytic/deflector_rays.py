"""Deflector plates by exact plan-view ray tracing: straight paths and impulsive bounces.

After leaving the disc a granule moves in a straight line in plan view (constant
horizontal velocity: drag is neglected over these few decimetres, and the plates are
assumed tall enough to be hit whatever the height), while its height falls
ballistically, z(t) = z0 + vz t - g t^2 / 2 (relative to the disc plane). A plate is
a capsule: its segment thickened by half its thickness; the granule's centre hits the
capsule grown by the granule radius r, on a flat side or on an end cap.

A hit is an impulse (per unit mass) with the normal n at the contact:
  normal:      v_n -> -e v_n, impulse J_n = (1 + e) |v_n|;
  tangential:  Coulomb, |J_t| <= mu J_n, acting against the slip of the contact point
               s = v.t - r spin (t = z x n) and never reversing it: a free sphere
               (I = 2/5 m r^2) needs J_t = -s / (1 + 1/kappa) = -(2/7) s to stop slipping
               (it then rolls off the plate), a locked one J_t = -s;
  spin:        spin -> spin - J_t / (kappa r) for rotation "free", 0 for "locked".
Several bounces are followed, granule by granule in compiled code
(`spreadgym.physics.compiled.plates`), until each granule leaves the deflector zone:
the circle about the axis used by the pymunk stage (`spreadgym.physics.geometry.zone_radius_m`:
every plate end plus its half thickness, plus the largest granule radius, plus 1 cm). The state returned is the one
on that circle, for every departed granule, whether it met a plate or not, so both
deflector stages hand the flight the same kind of state. Retained granules are
returned unchanged; with no plates the departure is returned as it is.
"""

from __future__ import annotations

from typing import Sequence, Union

import numpy as np

from spreadgym.config.scene import Deflector
from spreadgym.physics.compiled import plates as plate_stage
from spreadgym.physics.compiled.plates import MAX_BOUNCES, pack_plates, pass_turned
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR
from spreadgym.physics.contacts import Contacts, PlateContact
from spreadgym.physics.departure import Departure
from spreadgym.physics.geometry import zone_radius_m


def _plate_coefficients(contacts, count):
    if isinstance(contacts, Contacts):
        contacts = contacts.deflectors
    contacts = list(contacts)
    if len(contacts) != count:
        raise ValueError(f"deflect: {count} plates but {len(contacts)} plate contacts")
    return (np.array([c.friction for c in contacts], dtype=float),
            np.array([c.restitution for c in contacts], dtype=float))


def deflect(
    departure: Departure,
    plates: Sequence[Deflector],
    contacts: Union[Contacts, Sequence[PlateContact]],
    granule_radius_m,
    rotation: str,
    gravity_m_s2: float = GRAVITY_M_S2,
    max_bounces: int = MAX_BOUNCES,
) -> Departure:
    """Carry departed granules past the plates; their states where they leave the zone.

    `contacts`: the scene's Contacts (its `deflectors`) or one PlateContact per plate.
    """
    if not plates:
        return departure
    if rotation not in ("free", "locked"):
        raise ValueError(f"rotation must be 'free' or 'locked', got {rotation!r}")
    mu, e = _plate_coefficients(contacts, len(plates))
    n = departure.position_m.shape[0]
    r = np.broadcast_to(np.asarray(granule_radius_m, dtype=float), (n,)).copy()
    zone = zone_radius_m(plates, float(r.max()) if n else 0.0)
    live = np.flatnonzero(departure.departed)
    moved = (np.empty((live.size, 2)), np.empty((live.size, 2)), np.empty(live.size))
    passed = (np.empty(live.size), np.empty(live.size, dtype=np.int64), np.empty(live.size, dtype=np.int8))
    pass_turned(live, np.ones(live.size), np.zeros(live.size), np.ascontiguousarray(departure.position_m, dtype=float),
                np.ascontiguousarray(departure.velocity_m_s, dtype=float),
                np.ascontiguousarray(departure.spin_rad_s, dtype=float), r, pack_plates(plates, mu, e), zone,
                0.0 if rotation == "locked" else 1.0 / SPHERE_INERTIA_FACTOR, max_bounces, *moved, *passed)
    pos, vel, spin = (np.array(a, dtype=float) for a in (departure.position_m, departure.velocity_m_s,
                                                           departure.spin_rad_s))
    elapsed, bounces, status = np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int8)
    pos[live], vel[live], spin[live] = moved
    elapsed[live], bounces[live], status[live] = passed
    trapped = status == plate_stage.TRAPPED

    vz0 = departure.vertical_velocity_m_s
    notes = list(departure.notes)
    gone = departure.departed
    notes.append(
        f"deflectors (rays): zone radius {zone:.3f} m; {int(np.sum(bounces[gone] > 0))} of {int(gone.sum())} "
        f"departed granules met a plate ({int(bounces.sum())} bounces); straight paths, no drag, "
        "plates tall enough; height falls ballistically"
    )
    if trapped.any():
        notes.append(f"deflectors (rays): {int(trapped.sum())} granule(s) did not leave the zone "
                     f"(at rest or over {max_bounces} bounces): left at their last point")
    return Departure(
        position_m=pos,
        velocity_m_s=vel,
        spin_rad_s=spin,
        height_m=departure.height_m + vz0 * elapsed - 0.5 * gravity_m_s2 * elapsed**2,
        vertical_velocity_m_s=vz0 - gravity_m_s2 * elapsed,
        time_s=departure.time_s + elapsed,
        outcome=departure.outcome,
        model=departure.model,
        dt_s=departure.dt_s,
        notes=notes,
        tracks=departure.tracks,
    )
