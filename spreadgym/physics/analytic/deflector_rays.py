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
Several bounces are followed (rounds vectorised over granules) until each granule
leaves the deflector zone: the circle about the axis used by the pymunk stage
(`spreadgym.physics.geometry.zone_radius_m`: every plate end plus its half
thickness, plus the largest granule radius, plus 1 cm). The state returned is the one
on that circle, for every departed granule, whether it met a plate or not, so both
deflector stages hand the flight the same kind of state. Retained granules are
returned unchanged; with no plates the departure is returned as it is.
"""

from __future__ import annotations

from typing import Sequence, Union

import numpy as np

from spreadgym.config.scene import Deflector
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR
from spreadgym.physics.contacts import Contacts, PlateContact
from spreadgym.physics.departure import Departure
from spreadgym.physics.geometry import zone_radius_m

MAX_BOUNCES = 200
_APPROACH_TOL = 1e-12  # relative normal speed below which a touching granule is not hitting


def circle_exit_time(position, velocity, radius_m):
    """Time (N,) to the circle |x| = radius along straight paths from inside (0 if at rest)."""
    a = np.sum(velocity * velocity, axis=1)
    b = np.sum(position * velocity, axis=1)
    c = np.sum(position * position, axis=1) - radius_m * radius_m  # <= 0 inside
    root = np.sqrt(np.maximum(b * b - a * c, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(b > 0, -c / (b + root), (root - b) / a)
    return np.where((a > 0) & np.isfinite(t), np.maximum(t, 0.0), np.inf)


def capsule_hit(position, velocity, a, b, reach):
    """First entry of the points P + V t (t >= 0) into a capsule, element-wise.

    a, b: segment end points (2,); reach: (N,) capsule radius (half thickness plus
    granule radius). Returns (t, normal) with t = inf where the path misses or moves
    away; a point already inside and approaching is hit at t = 0.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d = b - a
    length = float(np.hypot(*d))
    e = d / length
    m = np.array([-e[1], e[0]])
    rel = position - a
    pa, pb = rel @ e, rel @ m
    va, vb = velocity @ e, velocity @ m
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    tol = _APPROACH_TOL * np.maximum(speed, 1e-300)
    n = position.shape[0]
    best = np.full(n, np.inf)
    normal = np.zeros((n, 2))
    # flat sides at pb = +reach (approached with vb < 0) and pb = -reach (vb > 0)
    inside = np.abs(pb) < reach  # overlapping the band of the plate already
    for side in (1.0, -1.0):
        coming = side * vb < -tol
        outside = side * pb >= reach
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(coming & outside, (side * reach - pb) / vb, np.inf)
        # overlapping: the face on the centre's side pushes it out at once
        t = np.where(coming & inside & (side * pb >= 0.0), 0.0, t)
        t = np.where(t >= 0, t, np.inf)
        along = pa + va * np.where(np.isfinite(t), t, 0.0)
        ok = np.isfinite(t) & (along >= 0.0) & (along <= length) & (t < best)
        best = np.where(ok, t, best)
        normal[ok] = side * m
    # end caps
    for c in (a, b):
        q = position - c
        qv = np.sum(q * velocity, axis=1)
        q2 = np.sum(q * q, axis=1) - reach * reach
        v2 = speed * speed
        disc = qv * qv - v2 * q2
        dist = np.sqrt(np.maximum(q2 + reach * reach, 0.0))
        coming = qv < -tol * dist
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(coming & (disc >= 0), q2 / (-qv + np.sqrt(np.maximum(disc, 0.0))), np.inf)
        t = np.where(coming & (q2 <= 0), 0.0, t)
        ok = np.isfinite(t) & (t >= 0) & (t < best)
        hit = q + velocity * np.where(ok, t, 0.0)[:, None]
        hn = np.hypot(hit[:, 0], hit[:, 1])
        best = np.where(ok, t, best)
        normal[ok] = hit[ok] / np.maximum(hn[ok], 1e-300)[:, None]
    return best, normal


def bounce(velocity, spin, normal, radius, restitution, friction, rotation):
    """Impulsive bounce of granules on a surface with outward unit normal `normal`.

    Returns (velocity, spin). Coulomb friction on the contact-point slip, limited
    so that the slip is stopped but never reversed (see the module docstring).
    """
    tangent = np.stack([-normal[:, 1], normal[:, 0]], axis=1)
    vn = np.sum(velocity * normal, axis=1)
    vt = np.sum(velocity * tangent, axis=1)
    jn = (1.0 + restitution) * np.maximum(-vn, 0.0)
    if rotation == "locked":
        slip = vt
        stop = np.abs(slip)
    else:
        slip = vt - radius * spin
        stop = np.abs(slip) / (1.0 + 1.0 / SPHERE_INERTIA_FACTOR)
    jt = -np.sign(slip) * np.minimum(friction * jn, stop)
    new_v = velocity + jn[:, None] * normal + jt[:, None] * tangent
    new_spin = np.zeros_like(spin) if rotation == "locked" else spin - jt / (SPHERE_INERTIA_FACTOR * radius)
    return new_v, new_spin


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
    ends = [tuple(np.asarray(p, dtype=float) for p in plate.endpoints()) for plate in plates]
    half = np.array([0.5 * plate.thickness_m for plate in plates])

    pos = departure.position_m.astype(float).copy()
    vel = departure.velocity_m_s.astype(float).copy()
    spin = departure.spin_rad_s.astype(float).copy()
    elapsed = np.zeros(n)
    bounces = np.zeros(n, dtype=np.int32)
    live = np.flatnonzero(departure.departed)
    trapped = np.zeros(n, dtype=bool)
    for _ in range(max_bounces + 1):
        if live.size == 0:
            break
        P, V = pos[live], vel[live]
        t_best = circle_exit_time(P, V, zone)
        which = np.full(live.size, -1)
        nrm = np.zeros((live.size, 2))
        for j, (a, b) in enumerate(ends):
            t, nj = capsule_hit(P, V, a, b, half[j] + r[live])
            closer = t < t_best
            t_best = np.where(closer, t, t_best)
            which = np.where(closer, j, which)
            nrm[closer] = nj[closer]
        stuck = ~np.isfinite(t_best)  # at rest (or parked in a corner): stays where it is
        t_adv = np.where(stuck, 0.0, t_best)
        pos[live] = P + V * t_adv[:, None]
        elapsed[live] += t_adv
        hit = which >= 0
        if np.any(hit):
            i = live[hit]
            j = which[hit]
            vel[i], spin[i] = bounce(vel[i], spin[i], nrm[hit], r[i], e[j], mu[j], rotation)
            bounces[i] += 1
        trapped[live[stuck]] = True
        live = live[hit & ~stuck]
    else:
        trapped[live] = True  # bounce limit reached: left where the last bounce put it

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
