"""Compiled (numba) flight of granules, each granule on its own: the integrator behind
`spreadgym.spread.flight.fly`.

Each granule is an independent small problem: its velocity ODE (drag, wind, gravity and,
optionally, Magnus lift with the closed-form spin decay) is stepped with the Dormand-Prince
5(4) pair under per-step error control, or with classical RK4 at a fixed step, and the
landing instant is solved inside the step that crosses z = 0 (safeguarded Newton on the
step length, started from a cubic Hermite guess). Granules never share arithmetic, so a
granule's landing does not depend on which others fly with it, and a seed's bits do not
depend on the batch. A few granules (LANES) are stepped side by side so that their
independent arithmetic overlaps (and vectorises); each keeps its own step size. SI units;
positions in the ground frame (origin on the spinner axis at launch), velocities over the
ground, times since launch.
"""

from __future__ import annotations

import math

import numpy as np

from spreadgym.physics import magnus
from spreadgym.physics.compiled.options import INLINED, KERNEL

# The helpers are INLINED: they run per stage, and a call (with its array reference
# counting) cost about as much as their arithmetic.

MAX_FLIGHT_S = 600.0  # a granule still airborne after this is a bug, not physics
MAX_STEPS = 1_000_000  # per granule
_NEWTON_ITERATIONS = 50  # most landing iterations per granule
LANES = 16  # granules flown side by side
_EMPTY, _FREE, _LANDING = 0, 1, 2  # what a lane is doing

# Dormand-Prince 5(4) tableau (FSAL: the 7th stage is the next step's first).
_A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0],
    [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0],
    [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84],
])
_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])  # stage times as fractions of the step
_E = np.array([  # 5th minus 4th order weights: the error estimate
    35 / 384 - 5179 / 57600,
    0.0,
    500 / 1113 - 7571 / 16695,
    125 / 192 - 393 / 640,
    -2187 / 6784 + 92097 / 339200,
    11 / 84 - 187 / 2100,
    -1 / 40,
])


@INLINED
def _accel(vx, vy, vz, k, lift_factor, size2, inverse_spin, lift, wind_x, wind_y, g):
    """a = g - K |r| r (+ the Magnus lift, `magnus.lift_factor`) at velocity v; r = v - w.
    k: K (1/m); lift_factor, size2: the granule's rows 1 and 2 of `par`; inverse_spin:
    1/|omega| (s/rad) at the time of the stage (`_inverse_spins`)."""
    rx = vx - wind_x
    ry = vy - wind_y
    speed2 = rx * rx + ry * ry + vz * vz
    minus_ks = -k * math.sqrt(speed2)
    ax = minus_ks * rx
    ay = minus_ks * ry
    az = minus_ks * vz - g
    if lift:
        f = magnus.lift_factor(lift_factor, size2, inverse_spin, rx, ry, speed2)
        ax -= f * ry
        ay += f * rx
    return ax, ay, az


@INLINED
def _spin_bases(t, h, table, idx, lift, base):
    """Each lane's `magnus.step_spin_base` for its step (t, h), into base (3, L): one
    closed-form spin per lane and step instead of one per stage."""
    if lift:
        for q in range(LANES):
            base[0, q], base[1, q], base[2, q] = magnus.step_spin_base(t[q], h[q], table, idx[q])


@INLINED
def _inverse_spins(t, h, fraction, base, table, idx, lift, out):
    """1/|omega| (s/rad) of each lane's granule at time t + fraction * h, into out (L,),
    from the step's `base`; the closed form where the series does not serve (a loop of its
    own, rarely entered, so that the first one has no call in it)."""
    if lift:
        for q in range(LANES):
            out[q] = magnus.step_inverse_spin(base[0, q], base[1, q], max(base[2, q], 0.0), fraction)
        for q in range(LANES):
            if base[2, q] < 0.0:
                out[q] = magnus.inverse_spin_size(t[q] + fraction * h[q], table, idx[q])


@INLINED
def _dp_stages(x, v, a1, t, h, sv, sa, x_new, base, table, idx, kk, lf, cs, lift, wind_x, wind_y, g):
    """One Dormand-Prince step of length h[q] in every lane q from (x, v) (3, L) at time
    t (L,) with first stage a1: the stages go to sv, sa (7, 3, L) (row 6: the new velocity
    and its acceleration), the new position to x_new (3, L). kk (L,), lf (2, L): the lanes'
    drag and lift parameters; base, cs: work arrays of the spin (`_spin_bases`)."""
    _spin_bases(t, h, table, idx, lift, base)
    for c in range(3):
        for q in range(LANES):
            sv[0, c, q] = v[c, q]
            sa[0, c, q] = a1[c, q]
    for i in range(1, 7):
        for c in range(3):
            for q in range(LANES):
                s = 0.0
                for m in range(i):
                    s += _A[i, m] * sa[m, c, q]
                sv[i, c, q] = v[c, q] + h[q] * s
        _inverse_spins(t, h, _C[i], base, table, idx, lift, cs)
        for q in range(LANES):
            sa[i, 0, q], sa[i, 1, q], sa[i, 2, q] = _accel(
                sv[i, 0, q], sv[i, 1, q], sv[i, 2, q], kk[q], lf[0, q], lf[1, q], cs[q], lift, wind_x, wind_y, g)
    for c in range(3):
        for q in range(LANES):
            s = 0.0
            for m in range(6):
                s += _A[6, m] * sv[m, c, q]
            x_new[c, q] = x[c, q] + h[q] * s


@INLINED
def _rk4_stages(x, v, a1, t, h, sv, sa, x_new, base, table, idx, kk, lf, cs, lift, wind_x, wind_y, g):
    """Classical RK4 step in every lane, same interface as `_dp_stages` (stages 1-3 used,
    row 6 the result)."""
    _spin_bases(t, h, table, idx, lift, base)
    for i in range(1, 4):
        fraction = 1.0 if i == 3 else 0.5
        for q in range(LANES):
            for c in range(3):
                sv[i, c, q] = v[c, q] + (fraction * h[q]) * (a1[c, q] if i == 1 else sa[i - 1, c, q])
        _inverse_spins(t, h, fraction, base, table, idx, lift, cs)
        for q in range(LANES):
            sa[i, 0, q], sa[i, 1, q], sa[i, 2, q] = _accel(
                sv[i, 0, q], sv[i, 1, q], sv[i, 2, q], kk[q], lf[0, q], lf[1, q], cs[q], lift, wind_x, wind_y, g)
    for q in range(LANES):
        sixth = h[q] / 6.0
        for c in range(3):
            x_new[c, q] = x[c, q] + sixth * (v[c, q] + 2.0 * (sv[1, c, q] + sv[2, c, q]) + sv[3, c, q])
            sv[6, c, q] = v[c, q] + sixth * (a1[c, q] + 2.0 * (sa[1, c, q] + sa[2, c, q]) + sa[3, c, q])
    _inverse_spins(t, h, 1.0, base, table, idx, lift, cs)
    for q in range(LANES):
        sa[6, 0, q], sa[6, 1, q], sa[6, 2, q] = _accel(
            sv[6, 0, q], sv[6, 1, q], sv[6, 2, q], kk[q], lf[0, q], lf[1, q], cs[q], lift, wind_x, wind_y, g)


@INLINED
def _error_ratio(x, x_new, v, h, sv, sa, q, atol, rtol):
    """Largest |local error| / (atol + rtol * |state|) of lane q over positions and velocities."""
    ratio = 0.0
    for c in range(3):
        ex = 0.0
        ev = 0.0
        for m in range(7):
            ex += _E[m] * sv[m, c, q]
            ev += _E[m] * sa[m, c, q]
        ratio = max(ratio, abs(h * ex) / (atol + rtol * max(abs(x[c, q]), abs(x_new[c, q]))))
        ratio = max(ratio, abs(h * ev) / (atol + rtol * max(abs(v[c, q]), abs(sv[6, c, q]))))
    return ratio


@INLINED
def _hermite_guess(z0, v0, z1, v1, h):
    """Fraction s in [0, 1] where the cubic Hermite interpolant of z(t) over the step
    (values z0 > 0 >= z1, slopes v0, v1) crosses zero: a starting guess."""
    a = 2 * z0 + h * v0 - 2 * z1 + h * v1  # z(s) = a s^3 + b s^2 + c s + z0
    b = -3 * z0 - 2 * h * v0 + 3 * z1 - h * v1
    c = h * v0
    s = z0 / (z0 - z1)
    for _ in range(4):
        f = ((a * s + b) * s + c) * s + z0
        df = (3 * a * s + 2 * b) * s + c
        s = s - f / df
        if math.isnan(s):
            s = 0.5
        s = min(max(s, 0.0), 1.0)
    return s


@KERNEL
def fly_all(position, height, velocity, par, table, lift, wind_x, wind_y, g, dt, atol, rtol, out_xy, out_t):
    """Fly every granule j from (position[j], height[j]) with ground-frame velocity
    velocity[j] (m/s) to z = 0; landing points into out_xy (N, 2), times into out_t (N,).
    dt > 0: fixed-step RK4; dt = 0: adaptive Dormand-Prince 5(4) with local error
    tolerances atol, rtol. A granule at height <= 0 lands at once where it is.
    `par`, `table`: per-granule parameters (see `_accel`).

    LANES granules fly side by side, each on its own: every pass takes one step (or one
    landing iteration) in every lane, so the lanes' independent arithmetic overlaps
    instead of waiting on one granule's chain of stages; a lane whose granule has landed
    takes the next one. Returns the number of granules that failed to land (within
    MAX_FLIGHT_S, MAX_STEPS, or a step above 1e-12 s)."""
    adaptive = dt == 0.0
    x = np.zeros((3, LANES))
    v = np.zeros((3, LANES))
    a1 = np.zeros((3, LANES))
    x_new = np.zeros((3, LANES))
    sv = np.zeros((7, 3, LANES))
    sa = np.zeros((7, 3, LANES))
    t = np.zeros(LANES)
    h = np.zeros(LANES)  # the length of the lane's next step (while landing: the trial step length)
    h_full = np.zeros(LANES)  # while landing: the step that crossed the ground
    lo = np.zeros(LANES)
    hi = np.zeros(LANES)
    count = np.zeros(LANES, dtype=np.int64)  # steps taken, or landing iterations
    mode = np.full(LANES, _EMPTY, dtype=np.int64)
    idx = np.zeros(LANES, dtype=np.int64)
    kk = np.zeros(LANES)  # the lane's granule's K, its lift parameters and 1/|omega| (see `_accel`)
    lf = np.zeros((2, LANES))
    cs = np.zeros(LANES)
    base = np.zeros((3, LANES))  # the lane's spin at its step (`_spin_bases`)
    failed = 0
    next_j = 0
    active = 0
    for q in range(LANES):
        next_j = _take(next_j, q, position, height, velocity, par, table, lift, wind_x, wind_y, g, dt,
                       x, v, a1, t, h, count, mode, idx, kk, lf, out_xy, out_t)
        if mode[q] == _FREE:
            active += 1
    while active > 0:
        if adaptive:
            _dp_stages(x, v, a1, t, h, sv, sa, x_new, base, table, idx, kk, lf, cs, lift, wind_x, wind_y, g)
        else:
            _rk4_stages(x, v, a1, t, h, sv, sa, x_new, base, table, idx, kk, lf, cs, lift, wind_x, wind_y, g)
        for q in range(LANES):
            done = False
            if mode[q] == _FREE:
                accept = True
                factor = 1.0
                if adaptive:
                    ratio = _error_ratio(x, x_new, v, h[q], sv, sa, q, atol, rtol)
                    accept = ratio <= 1.0
                    factor = min(max(0.9 * max(ratio, 1e-10) ** -0.2, 0.2), 5.0)
                    if not accept:
                        factor = min(factor, 1.0)
                if accept and x_new[2, q] <= 0.0:  # crossed the ground: solve for the landing
                    h_full[q] = h[q]
                    lo[q] = 0.0
                    hi[q] = h[q]
                    h[q] = h[q] * _hermite_guess(x[2, q], v[2, q], x_new[2, q], sv[6, 2, q], h[q])
                    count[q] = 0
                    mode[q] = _LANDING
                    continue
                if accept:
                    for c in range(3):
                        x[c, q] = x_new[c, q]
                        v[c, q] = sv[6, c, q]
                        a1[c, q] = sa[6, c, q]
                    t[q] += h[q]
                h[q] *= factor
                count[q] += 1
                if t[q] > MAX_FLIGHT_S or h[q] < 1e-12 or count[q] >= MAX_STEPS:
                    failed += 1
                    done = True
            elif mode[q] == _LANDING:
                # safeguarded Newton on the step length tau (dz/dtau = v_z), within a bracket;
                # the step of length tau itself gives z, so the landing point has no
                # interpolation error
                tau = h[q]
                z = x_new[2, q]
                vz = sv[6, 2, q]
                if z > 0:
                    lo[q] = tau
                else:
                    hi[q] = tau
                newton = tau - z / vz
                tau_new = newton if (math.isfinite(newton) and lo[q] <= newton <= hi[q]) else 0.5 * (lo[q] + hi[q])
                count[q] += 1
                if abs(z) <= 1e-12 or abs(tau_new - tau) <= 1e-14 * h_full[q] or count[q] >= _NEWTON_ITERATIONS:
                    j = idx[q]
                    out_xy[j, 0] = x_new[0, q]
                    out_xy[j, 1] = x_new[1, q]
                    out_t[j] = t[q] + tau
                    done = True
                else:
                    h[q] = tau_new
            if done:
                next_j = _take(next_j, q, position, height, velocity, par, table, lift, wind_x, wind_y, g, dt,
                               x, v, a1, t, h, count, mode, idx, kk, lf, out_xy, out_t)
                if mode[q] != _FREE:
                    active -= 1
    return failed


@INLINED
def _take(next_j, q, position, height, velocity, par, table, lift, wind_x, wind_y, g, dt,
          x, v, a1, t, h, count, mode, idx, kk, lf, out_xy, out_t):
    """Put the next granule that is above the ground into lane q (those at height <= 0
    land at once where they are), or leave the lane empty (h = 0) when none is left.
    Returns the index after the one taken."""
    while next_j < position.shape[0]:
        j = next_j
        next_j += 1
        out_xy[j, 0] = position[j, 0]
        out_xy[j, 1] = position[j, 1]
        out_t[j] = 0.0
        if not height[j] > 0.0:
            continue
        x[0, q], x[1, q], x[2, q] = position[j, 0], position[j, 1], height[j]
        v[0, q], v[1, q], v[2, q] = velocity[j, 0], velocity[j, 1], velocity[j, 2]
        t[q] = 0.0
        kk[q] = par[0, j]
        lf[0, q] = par[1, j] if lift else 0.0
        lf[1, q] = par[2, j] if lift else 0.0
        w = magnus.inverse_spin_size(0.0, table, j) if lift else 0.0
        a1[0, q], a1[1, q], a1[2, q] = _accel(v[0, q], v[1, q], v[2, q], kk[q], lf[0, q], lf[1, q], w, lift,
                                              wind_x, wind_y, g)
        if dt > 0.0:
            h[q] = dt
        else:
            # first step: a small part of the drag time scale 1/(K |v - w|) and of the
            # time to fall the launch height from rest; error control does the rest
            rx, ry = v[0, q] - wind_x, v[1, q] - wind_y
            rel = math.sqrt(rx * rx + ry * ry + v[2, q] * v[2, q])
            h[q] = min(max(min(0.05 / (par[0, j] * rel + 1e-9), math.sqrt(2.0 * x[2, q] / g)), 1e-5), 0.05)
        count[q] = 0
        mode[q] = _FREE
        idx[q] = j
        return next_j
    mode[q] = _EMPTY
    h[q] = 0.0
    return next_j
