"""Deflector plates, compiled: exact plan-view paths with impulsive bounces, granule by granule.

The physics is `spreadgym.physics.analytic.deflector_rays`' (its docstring states it):
a straight path in plan view, an impulse at every hit on a plate's capsule (restitution
on the normal speed, Coulomb friction on the contact point's slip that never reverses
it, spin from the friction impulse for free rotation), until the path leaves the
deflector zone. It is the limit the pymunk plate stage converges to as its step shrinks
(the stepped contact is found one step late, up to a step's travel inside the plate:
docs/fidelity.md measures the difference falling with the step).

Every function here is scalar code on floats and flat arrays (what numba.cuda could
compile as the spinner's functions are, spreadgym.device; only the spinner stage runs
on a GPU so far). Plates are rows of a float array `plates` (K, PLATE_SIZE), in the
frame the states are in.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np

from spreadgym.config.scene import Deflector
from spreadgym.physics.compiled.options import KERNEL
from spreadgym.physics.geometry import ZONE_MARGIN_M

# Columns of a plate row: end a, end b, unit vector e from a to b, length, half thickness,
# friction and restitution of the granule-plate pair.
AX, AY, BX, BY, EX, EY, LENGTH, HALF, MU, E = range(10)
PLATE_SIZE = 10

MAX_BOUNCES = 200
"""A granule still bouncing after this many hits is left where the last one put it (trapped)."""
APPROACH_TOL = 1e-12
"""Relative normal speed below which a touching granule is not hitting."""

# what `pass_plates` reports per granule
PASSED, TRAPPED = 0, 1


def pack_plates(plates: Sequence[Deflector], friction: Sequence[float], restitution: Sequence[float]) -> np.ndarray:
    """The plate array (K, PLATE_SIZE) of `plates` and their pairs' coefficients."""
    rows = np.zeros((len(plates), PLATE_SIZE))
    for row, plate, mu, e in zip(rows, plates, friction, restitution):
        a, b = (np.asarray(p, dtype=float) for p in plate.endpoints())
        d = b - a
        length = float(np.hypot(*d))
        row[[AX, AY, BX, BY]] = (*a, *b)
        row[[EX, EY]] = d / length
        row[LENGTH], row[HALF], row[MU], row[E] = length, 0.5 * plate.thickness_m, mu, e
    return rows


def near_plates(start: np.ndarray, end: np.ndarray, radius_m: np.ndarray, plates: Sequence[Deflector],
                turn: Optional[tuple[np.ndarray, np.ndarray]] = None,
                granule: Optional[np.ndarray] = None) -> np.ndarray:
    """(M,) bool: whether straight plan-view paths start[i]-end[i] (N, 2) pass within reach
    of a plate (granule radius + half its thickness + ZONE_MARGIN_M); the others are moved
    to the zone edge in closed form. Path k is granule[k]'s (default: every granule's, in
    order), turned about the axis by the angle with cosine turn[0][k] and sine turn[1][k]
    when `turn` is given."""
    granule = np.arange(start.shape[0]) if granule is None else granule
    cos, sin = (np.ones(granule.size), np.zeros(granule.size)) if turn is None else turn
    near = np.zeros(granule.size, dtype=np.bool_)
    zeros = np.zeros(len(plates))  # the coefficients play no part
    paths_near_plates(granule, cos, sin, np.ascontiguousarray(start, dtype=float),
                      np.ascontiguousarray(end, dtype=float), np.ascontiguousarray(radius_m, dtype=float),
                      pack_plates(plates, zeros, zeros), ZONE_MARGIN_M, near)
    return near


@KERNEL
def circle_exit_time(px, py, vx, vy, radius):
    """Time to the circle |x| = radius along a straight path from inside (inf at rest)."""
    a = vx * vx + vy * vy
    b = px * vx + py * vy
    c = px * px + py * py - radius * radius  # <= 0 inside
    root = math.sqrt(max(b * b - a * c, 0.0))
    if not a > 0.0:
        return math.inf
    t = -c / (b + root) if b > 0.0 else (root - b) / a
    if not math.isfinite(t):
        return math.inf
    return max(t, 0.0)


@KERNEL
def capsule_entry(px, py, vx, vy, plates, j, reach):
    """First entry of the point P + V t (t >= 0) into plate j's capsule grown to `reach`
    (half thickness plus granule radius): (t, nx, ny), the time and the outward normal
    there; t = inf where the path misses or moves away. A point already inside and
    approaching is hit at t = 0."""
    ax, ay, ex, ey, length = plates[j, AX], plates[j, AY], plates[j, EX], plates[j, EY], plates[j, LENGTH]
    mx, my = -ey, ex
    rx, ry = px - ax, py - ay
    pa, pb = rx * ex + ry * ey, rx * mx + ry * my
    va, vb = vx * ex + vy * ey, vx * mx + vy * my
    speed = math.hypot(vx, vy)
    tol = APPROACH_TOL * max(speed, 1e-300)
    best, nx, ny = math.inf, 0.0, 0.0
    inside = abs(pb) < reach  # overlapping the band of the plate already
    for side in (1.0, -1.0):  # flat sides at pb = +reach (approached with vb < 0) and -reach
        coming = side * vb < -tol
        t = math.inf
        if coming and side * pb >= reach:
            t = (side * reach - pb) / vb
        if coming and inside and side * pb >= 0.0:  # overlapping: the face on the centre's side pushes it out
            t = 0.0
        if not t >= 0.0:
            t = math.inf
        if math.isfinite(t) and t < best:
            along = pa + va * t
            if 0.0 <= along <= length:
                best, nx, ny = t, side * mx, side * my
    for end in range(2):  # the rounded ends
        cx, cy = (ax, ay) if end == 0 else (plates[j, BX], plates[j, BY])
        qx, qy = px - cx, py - cy
        qv = qx * vx + qy * vy
        q2 = qx * qx + qy * qy - reach * reach
        disc = qv * qv - speed * speed * q2
        dist = math.sqrt(max(q2 + reach * reach, 0.0))
        if not qv < -tol * dist:
            continue
        t = math.inf
        if disc >= 0.0:
            t = q2 / (-qv + math.sqrt(disc))
        if q2 <= 0.0:
            t = 0.0
        if math.isfinite(t) and t >= 0.0 and t < best:
            hx, hy = qx + vx * t, qy + vy * t
            hn = max(math.hypot(hx, hy), 1e-300)
            best, nx, ny = t, hx / hn, hy / hn
    return best, nx, ny


@KERNEL
def bounce(vx, vy, spin, nx, ny, radius, restitution, friction, inv_kappa):
    """An impulsive bounce on a surface with outward unit normal n: (vx, vy, spin).

    Normal: v_n -> -e v_n. Coulomb friction on the contact point's slip, at most what
    stops it (a free sphere needs 1 / (1 + 1/kappa) of the slip, 2/7; a locked one all of
    it) and never reversing it. `inv_kappa` = m r^2 / I (1/0.4 free, 0 locked: spin 0)."""
    tx, ty = -ny, nx
    vn = vx * nx + vy * ny
    vt = vx * tx + vy * ty
    jn = (1.0 + restitution) * max(-vn, 0.0)
    slip = vt - radius * spin if inv_kappa > 0.0 else vt
    stop = abs(slip) / (1.0 + inv_kappa)
    sign = 1.0 if slip > 0.0 else (-1.0 if slip < 0.0 else 0.0)
    jt = -sign * min(friction * jn, stop)
    new_spin = spin - jt * inv_kappa / radius if inv_kappa > 0.0 else 0.0
    return vx + jn * nx + jt * tx, vy + jn * ny + jt * ty, new_spin


@KERNEL
def pass_plates(px, py, vx, vy, spin, radius, plates, zone, inv_kappa, max_bounces):
    """One granule carried past the plates to the zone circle (plan view, straight paths
    between bounces): (px, py, vx, vy, spin, elapsed s, bounces, status), status PASSED
    or TRAPPED (at rest, or still bouncing after `max_bounces` hits: left where it is)."""
    elapsed = 0.0
    bounces = 0
    for _ in range(max_bounces + 1):
        t_best = circle_exit_time(px, py, vx, vy, zone)
        which, nx, ny = -1, 0.0, 0.0
        for j in range(plates.shape[0]):
            t, hx, hy = capsule_entry(px, py, vx, vy, plates, j, plates[j, HALF] + radius)
            if t < t_best:
                t_best, which, nx, ny = t, j, hx, hy
        if not math.isfinite(t_best):  # at rest (or parked in a corner): stays where it is
            return px, py, vx, vy, spin, elapsed, bounces, TRAPPED
        px, py = px + vx * t_best, py + vy * t_best
        elapsed += t_best
        if which < 0:
            return px, py, vx, vy, spin, elapsed, bounces, PASSED
        vx, vy, spin = bounce(vx, vy, spin, nx, ny, radius, plates[which, E], plates[which, MU], inv_kappa)
        bounces += 1
    return px, py, vx, vy, spin, elapsed, bounces, TRAPPED


@KERNEL
def point_segment_distance2(px, py, ax, ay, bx, by):
    """Squared distance from the point p to the segment a-b."""
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = min(max(((px - ax) * dx + (py - ay) * dy) / max(length2, 1e-300), 0.0), 1.0)
    qx, qy = px - ax - t * dx, py - ay - t * dy
    return qx * qx + qy * qy


@KERNEL
def segment_distance2(p0x, p0y, p1x, p1y, ax, ay, bx, by):
    """Squared shortest distance between the segments p0-p1 and a-b."""
    dx, dy = p1x - p0x, p1y - p0y
    ex, ey = bx - ax, by - ay
    denom = dx * ey - dy * ex
    if abs(denom) > 1e-300:
        wx, wy = ax - p0x, ay - p0y
        s = (wx * ey - wy * ex) / denom
        t = (wx * dy - wy * dx) / denom
        if 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0:
            return 0.0  # they cross
    return min(min(point_segment_distance2(p0x, p0y, ax, ay, bx, by),
                   point_segment_distance2(p1x, p1y, ax, ay, bx, by)),
               min(point_segment_distance2(ax, ay, p0x, p0y, p1x, p1y),
                   point_segment_distance2(bx, by, p0x, p0y, p1x, p1y)))


@KERNEL
def segment_distance(p0x, p0y, p1x, p1y, ax, ay, bx, by):
    """Shortest distance between the segments p0-p1 and a-b."""
    return math.sqrt(segment_distance2(p0x, p0y, p1x, p1y, ax, ay, bx, by))


@KERNEL
def path_near_plates(p0x, p0y, p1x, p1y, radius, plates, margin):
    """Whether the straight path p0-p1 of a granule of `radius` passes within its reach of
    a plate (radius + half thickness + `margin`): the granules that might touch one."""
    for j in range(plates.shape[0]):
        reach = radius + plates[j, HALF] + margin
        ax, ay, bx, by = plates[j, AX], plates[j, AY], plates[j, BX], plates[j, BY]
        if (max(p0x, p1x) + reach < min(ax, bx) or min(p0x, p1x) - reach > max(ax, bx)
                or max(p0y, p1y) + reach < min(ay, by) or min(p0y, p1y) - reach > max(ay, by)):
            continue  # their boxes stand further apart than the reach: so do they
        if segment_distance2(p0x, p0y, p1x, p1y, ax, ay, bx, by) <= reach * reach:
            return True
    return False


@KERNEL
def pass_turned(granule, cos, sin, position, velocity, spin, radius, plates, zone, inv_kappa, max_bounces,
                out_position, out_velocity, out_spin, elapsed, bounces, status):
    """`pass_plates` of granule[k]'s state (position (N, 2), velocity (N, 2), spin (N,))
    turned about the axis by the angle with cosine cos[k] and sine sin[k], into row k of
    the outputs: state, time spent in the zone (s), bounces and status. A turn of (1, 0)
    leaves the state as it is, to the bit. Compiled and GIL-free: a batch finishes scenes
    side by side."""
    for k in range(granule.size):
        i, c, s = granule[k], cos[k], sin[k]
        px, py = c * position[i, 0] - s * position[i, 1], s * position[i, 0] + c * position[i, 1]
        vx, vy = c * velocity[i, 0] - s * velocity[i, 1], s * velocity[i, 0] + c * velocity[i, 1]
        (out_position[k, 0], out_position[k, 1], out_velocity[k, 0], out_velocity[k, 1], out_spin[k], elapsed[k],
         bounces[k], status[k]) = pass_plates(px, py, vx, vy, spin[i], radius[i], plates, zone, inv_kappa, max_bounces)


@KERNEL
def paths_near_plates(granule, cos, sin, start, end, radius, plates, margin, near):
    """near[k]: whether granule[k]'s straight path start-end, turned about the axis by the
    angle with cosine cos[k] and sine sin[k], passes within reach of a plate
    (`path_near_plates`). A turn of (1, 0) leaves the path as it is, to the bit."""
    for k in range(granule.size):
        i, c, s = granule[k], cos[k], sin[k]
        near[k] = path_near_plates(c * start[i, 0] - s * start[i, 1], s * start[i, 0] + c * start[i, 1],
                                   c * end[i, 0] - s * end[i, 1], s * end[i, 0] + c * end[i, 1], radius[i], plates,
                                   margin)
