"""Free phase: a granule off the vanes, in the frame turning with the disc.

Fourth-order Runge-Kutta steps of the free acceleration (contact_law). A step ends
early at the first event inside it, located on the continuous path (a crossing of a
face line or of the rim is found by safeguarded Newton on re-integrated sub-steps, so a
fast granule cannot jump through a vane): the centre reaches the disc radius, or the
granule, below the vane tops, reaches a vane face from outside (also the return
after a rebound off that face, however short the flight) or one of its rounded
ends. A granule that comes down onto a vane, or keeps pressing on a rounded end, is
found as an overlap at the end of a step (`overlap`).
"""

from __future__ import annotations

import math

from spreadgym.physics.compiled.contact_law import free_acceleration
from spreadgym.physics.compiled.event_root import MAX_ITERATIONS, newton_step
from spreadgym.physics.compiled.layout import DISC_RADIUS, LENGTH, NX, NY, OMEGA, PX, PY, UX, UY
from spreadgym.physics.compiled.options import INLINED

NONE = 0
RIM = 1
FACE = 2
END_CAP = 3  # a rounded end of a vane (side 0: inner end, 1: tip)
ON_SURFACE_M = 1e-12  # closer than this to a face line counts as on it (a rebound starts there)


@INLINED
def rk4(cx, cy, vx, vy, h, omega, drag):
    """One fourth-order step of length h (s)."""
    a1x, a1y = free_acceleration(cx, cy, vx, vy, omega, drag)
    hh = 0.5 * h
    a2x, a2y = free_acceleration(cx + hh * vx, cy + hh * vy, vx + hh * a1x, vy + hh * a1y, omega, drag)
    v2x, v2y = vx + hh * a1x, vy + hh * a1y
    a3x, a3y = free_acceleration(cx + hh * v2x, cy + hh * v2y, vx + hh * a2x, vy + hh * a2y, omega, drag)
    v3x, v3y = vx + hh * a2x, vy + hh * a2y
    v4x, v4y = vx + h * a3x, vy + h * a3y
    a4x, a4y = free_acceleration(cx + h * v3x, cy + h * v3y, v4x, v4y, omega, drag)
    h6 = h / 6.0
    nx = cx + h6 * (vx + 2.0 * v2x + 2.0 * v3x + v4x)
    ny = cy + h6 * (vy + 2.0 * v2y + 2.0 * v3y + v4y)
    return nx, ny, vx + h6 * (a1x + 2.0 * a2x + 2.0 * a3x + a4x), vy + h6 * (a1y + 2.0 * a2y + 2.0 * a3y + a4y)


@INLINED
def _event_value(kind, vane, side, cx, cy, reach, P, V):
    """Event function (positive before, negative after) of a rim or face crossing."""
    if kind == RIM:
        r = P[DISC_RADIUS]
        return r * r - cx * cx - cy * cy
    if kind == END_CAP:
        ex, ey = end_point(vane, side, V)
        return math.sqrt((cx - ex) ** 2 + (cy - ey) ** 2) - reach
    d = (cx - V[vane, PX]) * V[vane, NX] + (cy - V[vane, PY]) * V[vane, NY]
    return side * d - reach


@INLINED
def _event_rate(kind, vane, side, cx, cy, vx, vy, V):
    """d/dt of `_event_value` at position c, velocity v (disc frame, where the vanes stand still)."""
    if kind == RIM:
        return -2.0 * (cx * vx + cy * vy)
    if kind == END_CAP:
        ex, ey = end_point(vane, side, V)
        dx, dy = cx - ex, cy - ey
        return (dx * vx + dy * vy) / math.sqrt(dx * dx + dy * dy)
    return side * (vx * V[vane, NX] + vy * V[vane, NY])


@INLINED
def end_point(vane, end, V):
    """Inner end (end 0) or tip (end 1) of a vane's centre line."""
    length = end * V[vane, LENGTH]
    return V[vane, PX] + length * V[vane, UX], V[vane, PY] + length * V[vane, UY]


@INLINED
def step(cx, cy, vx, vy, h, below, drag, reach, P, V):
    """Advance up to h s. Returns (cx, cy, vx, vy, time used, event, vane, side);
    side +1 is the leading face, -1 the trailing face; `reach` = granule radius + half
    the vane thickness."""
    omega = P[OMEGA]
    ex, ey, evx, evy = rk4(cx, cy, vx, vy, h, omega, drag)
    best, kind, vane, side = 2.0, NONE, -1, 0.0
    g0 = _event_value(RIM, 0, 0.0, cx, cy, reach, P, V)
    g1 = _event_value(RIM, 0, 0.0, ex, ey, reach, P, V)
    if g1 < 0.0:
        best, kind = max(g0, 0.0) / (max(g0, 0.0) - g1), RIM
    start = best  # where Newton starts on the chosen event (best: the estimate that chose it)
    lo = 0.0  # the bracket's lower end (fractions of the step): after the start of a rebound
    near = (1.001 * reach) ** 2  # squared distance beyond which an end cap is surely not reached
    if below:
        for k in range(V.shape[0]):
            for sd in (1.0, -1.0):
                g0 = _event_value(FACE, k, sd, cx, cy, reach, P, V)
                g1 = _event_value(FACE, k, sd, ex, ey, reach, P, V)
                if g1 >= 0.0 or g0 < -ON_SURFACE_M:
                    continue
                f_lo, guess = 0.0, 2.0
                if g0 <= ON_SURFACE_M:
                    # on the face at the start (a rebound): the return, bracketed from the
                    # lower half of the parabola g = vn t - press t^2 / 2. The chord from the
                    # apex to the step's end (g curves down: its root comes early, not late)
                    # picks the first event; Newton starts from the parabola's root
                    # 2 vn / press where that lies in the step (from the chord, a poor start
                    # for a flight much shorter than the step, it took 5-9 updates, against
                    # 3-4, in the paper scene)
                    ax, ay = free_acceleration(cx, cy, vx, vy, omega, drag)
                    vn = sd * (vx * V[k, NX] + vy * V[k, NY])
                    press = -sd * (ax * V[k, NX] + ay * V[k, NY])
                    if vn <= 0.0 or press <= 0.0:
                        continue
                    f_lo = min(vn / (press * h), 0.5)
                    lx, ly, _, _ = rk4(cx, cy, vx, vy, f_lo * h, omega, drag)
                    g0 = _event_value(FACE, k, sd, lx, ly, reach, P, V)
                    if g0 <= 0.0:
                        continue
                    guess = 2.0 * vn / (press * h)
                f = f_lo + (1.0 - f_lo) * g0 / (g0 - g1)
                if f >= best:
                    continue
                # along the vane at the crossing: within the flat face? (its very ends
                # belong to the rounded ends: a granule that slid off the tip and is
                # pressed on the face line there goes round the tip, not back on)
                mx, my = cx + f * (ex - cx), cy + f * (ey - cy)
                x = (mx - V[k, PX]) * V[k, UX] + (my - V[k, PY]) * V[k, UY]
                if ON_SURFACE_M < x < V[k, LENGTH] - ON_SURFACE_M:
                    best, kind, vane, side, lo = f, FACE, k, sd, f_lo
                    start = guess if f_lo < guess < 1.0 else f
            for end in (0.0, 1.0):
                px, py = end_point(k, end, V)
                if (ex - px) ** 2 + (ey - py) ** 2 >= near:
                    continue  # g1 > 0 without the square root: no crossing
                g0 = _event_value(END_CAP, k, end, cx, cy, reach, P, V)
                g1 = _event_value(END_CAP, k, end, ex, ey, reach, P, V)
                if g0 > ON_SURFACE_M and g1 < 0.0:
                    f = g0 / (g0 - g1)
                    if f < best:
                        best, kind, vane, side, lo, start = f, END_CAP, k, end, 0.0, f
    if kind == NONE:
        return ex, ey, evx, evy, h, NONE, -1, 0.0
    # safeguarded Newton on the re-integrated path, from `start`; the state is the one
    # at the last point evaluated (within FRACTION_TOLERANCE of the root)
    f, hi = start, 1.0
    sx, sy, svx, svy = cx, cy, vx, vy
    for _ in range(MAX_ITERATIONS):
        sx, sy, svx, svy = rk4(cx, cy, vx, vy, f * h, omega, drag)
        g = _event_value(kind, vane, side, sx, sy, reach, P, V)
        slope = h * _event_rate(kind, vane, side, sx, sy, svx, svy, V)
        lo, hi, f_next, converged = newton_step(lo, hi, f, g, slope)
        if converged:
            break
        f = f_next
    if kind == FACE:  # exactly on the face line: a rebound starts from it
        g = _event_value(kind, vane, side, sx, sy, reach, P, V)
        sx, sy = sx - g * side * V[vane, NX], sy - g * side * V[vane, NY]
    return sx, sy, svx, svy, f * h, kind, vane, side


@INLINED
def overlap(cx, cy, reach, V):
    """First vane the granule overlaps: (vane, side, outward normal x, y, depth) with
    side +1/-1 for the leading/trailing flat face, 0 for a rounded end; vane -1 if none."""
    for k in range(V.shape[0]):
        dx, dy = cx - V[k, PX], cy - V[k, PY]
        x = dx * V[k, UX] + dy * V[k, UY]
        d = dx * V[k, NX] + dy * V[k, NY]
        if 0.0 <= x <= V[k, LENGTH]:
            if abs(d) < reach:
                side = 1.0 if d >= 0.0 else -1.0
                return k, side, side * V[k, NX], side * V[k, NY], reach - abs(d)
            continue
        end = 0.0 if x < 0.0 else V[k, LENGTH]
        ox, oy = dx - end * V[k, UX], dy - end * V[k, UY]
        dist = math.sqrt(ox * ox + oy * oy)
        if dist < reach and dist > 0.0:
            return k, 0.0, ox / dist, oy / dist, reach - dist
    return -1, 0.0, 0.0, 0.0, 0.0
