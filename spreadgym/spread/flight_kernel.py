"""Compiled (numba) flight of granules, one granule at a time: the integrator behind
`spreadgym.spread.flight.fly`.

Each granule is an independent small problem: its velocity ODE (drag, wind, gravity and,
optionally, Magnus lift with the closed-form spin decay) is stepped with the Dormand-Prince
5(4) pair under per-step error control, or with classical RK4 at a fixed step, and the
landing instant is solved inside the step that crosses z = 0 (safeguarded Newton on the
step length, started from a cubic Hermite guess). Granules never share arithmetic, so a
granule's landing does not depend on which others fly with it, and a seed's bits do not
depend on the batch. SI units; positions in the ground frame (origin on the spinner axis
at launch), velocities over the ground, times since launch.
"""

from __future__ import annotations

import math

import numpy as np

from spreadgym.physics import magnus
from numba import njit

from spreadgym.physics.compiled.layout import KERNEL

_INLINE = njit(cache=True, error_model="numpy", inline="always")
"""KERNEL's options, inlined into the caller at compile time: the helpers run per stage
and a call (with its array reference counting) cost about as much as their arithmetic."""

MAX_FLIGHT_S = 600.0  # a granule still airborne after this is a bug, not physics
MAX_STEPS = 1_000_000  # per granule
_NEWTON_ITERATIONS = 50

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


@_INLINE
def _accel(vx, vy, vz, t, par, table, j, lift, wind_x, wind_y, g):
    """a = g - K |r| r (+ the Magnus lift, `magnus.lift_factor`) for granule j at
    velocity v and time t since launch; r = v - w. `par` rows: K (1/m), the signed lift
    factor (1/m), r / S_sat (m); `table`: the granule's spin history (`magnus.spin_table`)."""
    rx = vx - wind_x
    ry = vy - wind_y
    speed2 = rx * rx + ry * ry + vz * vz
    minus_ks = -par[0, j] * math.sqrt(speed2)
    ax = minus_ks * rx
    ay = minus_ks * ry
    az = minus_ks * vz - g
    if lift:
        f = magnus.lift_factor(par[1, j], par[2, j] * magnus.spin_size(t, table, j), rx, ry, speed2)
        ax -= f * ry
        ay += f * rx
    return ax, ay, az


@_INLINE
def _dp_step(x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g):
    """One Dormand-Prince step of length h from (x, v) at time t with first stage a1:
    the stages go to stage_v, stage_a (7, 3) (row 6: the new velocity and its
    acceleration), the new position to x_new (3,)."""
    for c in range(3):
        stage_v[0, c] = v[c]
        stage_a[0, c] = a1[c]
    for i in range(1, 7):
        for c in range(3):
            s = 0.0
            for m in range(i):
                s += _A[i, m] * stage_a[m, c]
            stage_v[i, c] = v[c] + h * s
        stage_a[i, 0], stage_a[i, 1], stage_a[i, 2] = _accel(
            stage_v[i, 0], stage_v[i, 1], stage_v[i, 2], t + _C[i] * h, par, table, j, lift, wind_x, wind_y, g)
    for c in range(3):
        s = 0.0
        for m in range(6):
            s += _A[6, m] * stage_v[m, c]
        x_new[c] = x[c] + h * s


@_INLINE
def _rk4_step(x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g):
    """Classical RK4 step, same interface as `_dp_step` (stages 1-3 used, row 6 the result)."""
    for i in range(1, 4):
        w = h if i == 3 else 0.5 * h
        for c in range(3):
            stage_v[i, c] = v[c] + w * (a1[c] if i == 1 else stage_a[i - 1, c])
        stage_a[i, 0], stage_a[i, 1], stage_a[i, 2] = _accel(
            stage_v[i, 0], stage_v[i, 1], stage_v[i, 2], t + (h if i == 3 else 0.5 * h),
            par, table, j, lift, wind_x, wind_y, g)
    sixth = h / 6.0
    for c in range(3):
        x_new[c] = x[c] + sixth * (v[c] + 2.0 * (stage_v[1, c] + stage_v[2, c]) + stage_v[3, c])
        stage_v[6, c] = v[c] + sixth * (a1[c] + 2.0 * (stage_a[1, c] + stage_a[2, c]) + stage_a[3, c])
    stage_a[6, 0], stage_a[6, 1], stage_a[6, 2] = _accel(
        stage_v[6, 0], stage_v[6, 1], stage_v[6, 2], t + h, par, table, j, lift, wind_x, wind_y, g)


@_INLINE
def _step(adaptive, x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g):
    if adaptive:
        _dp_step(x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g)
    else:
        _rk4_step(x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g)


@_INLINE
def _error_ratio(x, x_new, v, h, stage_v, stage_a, atol, rtol):
    """Largest |local error| / (atol + rtol * |state|) over positions and velocities."""
    ratio = 0.0
    for c in range(3):
        ex = 0.0
        ev = 0.0
        for m in range(7):
            ex += _E[m] * stage_v[m, c]
            ev += _E[m] * stage_a[m, c]
        ratio = max(ratio, abs(h * ex) / (atol + rtol * max(abs(x[c]), abs(x_new[c]))))
        ratio = max(ratio, abs(h * ev) / (atol + rtol * max(abs(v[c]), abs(stage_v[6, c]))))
    return ratio


@_INLINE
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


@_INLINE
def _land(adaptive, x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g):
    """Step length tau in (0, h] with z(tau) = 0, where z(tau) is the step itself (no
    interpolation error); the landing point is left in x_new. Entered with the step of
    length h that ended at z <= 0 in x_new, stage_v."""
    lo = 0.0
    hi = h
    tau = h * _hermite_guess(x[2], v[2], x_new[2], stage_v[6, 2], h)
    for _ in range(_NEWTON_ITERATIONS):
        _step(adaptive, x, v, a1, t, tau, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g)
        z = x_new[2]
        vz = stage_v[6, 2]
        if z > 0:
            lo = tau
        else:
            hi = tau
        newton = tau - z / vz
        tau_new = newton if (math.isfinite(newton) and lo <= newton <= hi) else 0.5 * (lo + hi)
        if abs(z) <= 1e-12 or abs(tau_new - tau) <= 1e-14 * h:
            break
        tau = tau_new
    return tau


@KERNEL
def fly_all(position, height, velocity, par, table, lift, wind_x, wind_y, g, dt, atol, rtol, out_xy, out_t):
    """Fly every granule j from (position[j], height[j]) with ground-frame velocity
    velocity[j] (m/s) to z = 0; landing points into out_xy (N, 2), times into out_t (N,).
    dt > 0: fixed-step RK4; dt = 0: adaptive Dormand-Prince 5(4) with local error
    tolerances atol, rtol. A granule at height <= 0 lands at once where it is.
    Returns the number of granules that failed to land (within MAX_FLIGHT_S, MAX_STEPS
    or a step above 1e-12 s)."""
    adaptive = dt == 0.0
    x = np.empty(3)
    v = np.empty(3)
    a1 = np.empty(3)
    x_new = np.empty(3)
    stage_v = np.empty((7, 3))
    stage_a = np.empty((7, 3))
    failed = 0
    for j in range(position.shape[0]):
        out_xy[j, 0] = position[j, 0]
        out_xy[j, 1] = position[j, 1]
        out_t[j] = 0.0
        if not height[j] > 0.0:
            continue
        x[0], x[1], x[2] = position[j, 0], position[j, 1], height[j]
        v[0], v[1], v[2] = velocity[j, 0], velocity[j, 1], velocity[j, 2]
        t = 0.0
        a1[0], a1[1], a1[2] = _accel(v[0], v[1], v[2], t, par, table, j, lift, wind_x, wind_y, g)
        if adaptive:
            # first step: a small part of the drag time scale 1/(K |v - w|) and of the
            # time to fall the launch height from rest; error control does the rest
            rx, ry = v[0] - wind_x, v[1] - wind_y
            rel = math.sqrt(rx * rx + ry * ry + v[2] * v[2])
            h = min(0.05 / (par[0, j] * rel + 1e-9), math.sqrt(2.0 * x[2] / g))
            h = min(max(h, 1e-5), 0.05)
        else:
            h = dt
        landed = False
        for _ in range(MAX_STEPS):
            _step(adaptive, x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift, wind_x, wind_y, g)
            accept = True
            factor = 1.0
            if adaptive:
                ratio = _error_ratio(x, x_new, v, h, stage_v, stage_a, atol, rtol)
                accept = ratio <= 1.0
                factor = min(max(0.9 * max(ratio, 1e-10) ** -0.2, 0.2), 5.0)
                if not accept:
                    factor = min(factor, 1.0)
            if accept:
                if x_new[2] <= 0.0:
                    tau = _land(adaptive, x, v, a1, t, h, stage_v, stage_a, x_new, par, table, j, lift,
                                wind_x, wind_y, g)
                    out_xy[j, 0] = x_new[0]
                    out_xy[j, 1] = x_new[1]
                    out_t[j] = t + tau
                    landed = True
                    break
                for c in range(3):
                    x[c] = x_new[c]
                    v[c] = stage_v[6, c]
                    a1[c] = stage_a[6, c]
                t += h
            h *= factor
            if t > MAX_FLIGHT_S or h < 1e-12:
                break
        if not landed:
            failed += 1
    return failed
