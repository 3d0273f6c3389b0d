"""Flight of granules from the spinner to the ground.

Each granule is a sphere of diameter d and density rho_p flying through still or
moving air (wind w over the ground) under gravity and quadratic drag:

    dv/dt = g - K |v - w| (v - w),     K = 3 rho_air C_D / (4 rho_p d)

(C_D = 0.44, Newton regime: Re = rho_air |v - w| d / mu is about 4000-8000 for a
3 mm granule at 20-40 m/s, roughly 2700-10700 over 2-4 mm, where a sphere's C_D is
nearly constant). Positions are in the ground frame with the origin on
the spinner axis at the moment the granule leaves the disc; the machine drives along
+y at `flight.forward_speed_m_s`, so the ground-frame launch velocity is the
machine-frame one plus (0, forward, 0).

Method (default, `dt_s=None`): an embedded Dormand-Prince 5(4) Runge-Kutta pair,
vectorised over granules, with its own step size per granule chosen by error control
(a granule with little drag takes a few long steps; without drag the method is exact
and lands in one or two steps). Granules drop out of the working arrays as they land.
The landing instant is found inside the last step by a safeguarded Newton iteration
on the Runge-Kutta step length (started from a cubic Hermite guess), so the landing
point carries no interpolation error. `dt_s=<float>` runs the classical fixed-step
RK4 instead (kept for comparisons and benchmarks). `reference_landing` solves the
same model one granule at a time with scipy's DOP853 at tight tolerance.

With `flight.magnus` on, a granule keeps its departure spin about the vertical axis
and meets a horizontal Magnus lift sideways to its velocity; the spin decays by air
torque (`spreadgym.physics.magnus`: the law, its sources and ranges). The spin has a
closed form in time, so the Runge-Kutta stages still carry velocities only and the
acceleration is evaluated at each stage's time. With it off (the default) the
arithmetic is exactly that of the drag-only model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp

from spreadgym.config.scene import Flight
from spreadgym.errors import ConfigError
from spreadgym.physics import magnus
from spreadgym.physics.constants import GRAVITY_M_S2

# Local error tolerance of the adaptive method, per step and per granule: absolute
# (m on positions, m/s on velocities) plus relative. Chosen so the landing point
# stays within ~0.01 mm of a tight-tolerance solve (see docs/flight-and-pattern.md).
DEFAULT_ATOL = 2e-6
DEFAULT_RTOL = 1e-7
_MAX_FLIGHT_S = 600.0  # a granule still airborne after this is a bug, not physics
_MAX_ITERATIONS = 1_000_000

# Dormand-Prince 5(4) tableau (FSAL: the 7th stage is the next step's first).
_DP_A = [
    np.array([]),
    np.array([1 / 5]),
    np.array([3 / 40, 9 / 40]),
    np.array([44 / 45, -56 / 15, 32 / 9]),
    np.array([19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729]),
    np.array([9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656]),
    np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]),
]
_DP_C = [0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0]  # stage times as fractions of the step
_DP_B = _DP_A[6]  # 5th-order weights (= last row: FSAL)
_DP_E = np.array(  # 5th minus 4th order weights: the error estimate
    [
        35 / 384 - 5179 / 57600,
        0.0,
        500 / 1113 - 7571 / 16695,
        125 / 192 - 393 / 640,
        -2187 / 6784 + 92097 / 339200,
        11 / 84 - 187 / 2100,
        -1 / 40,
    ]
)


@dataclass(frozen=True)
class Landing:
    """Where and when each granule reaches the ground (z = 0)."""

    position_m: np.ndarray  # (N, 2) landing point (x, y), ground frame, origin: spinner axis at launch
    time_s: np.ndarray  # (N,) flight time


def drag_constant(diameter_m, density_kg_m3, flight: Flight) -> np.ndarray:
    """K = 3 rho_air C_D / (4 rho_p d) in 1/m, per granule."""
    d = np.asarray(diameter_m, dtype=float)
    rho = np.asarray(density_kg_m3, dtype=float)
    return 3.0 * flight.air_density_kg_m3 * flight.drag_coefficient / (4.0 * rho * d)


def terminal_speed_m_s(diameter_m, density_kg_m3, flight: Flight, gravity_m_s2: float = GRAVITY_M_S2):
    """Terminal fall speed sqrt(g / K) in still air (inf without drag)."""
    k = np.asarray(drag_constant(diameter_m, density_kg_m3, flight), dtype=float)
    with np.errstate(divide="ignore"):
        return np.sqrt(gravity_m_s2 / k)


def _check_inputs(position_m, height_m, velocity_m_s, diameter_m, density_kg_m3, gravity_m_s2, spin_rad_s=None):
    pos = np.asarray(position_m, dtype=float)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise ConfigError("position_m", f"expected shape (N, 2), got {pos.shape}")
    n = pos.shape[0]
    vel = np.asarray(velocity_m_s, dtype=float)
    if vel.shape != (n, 3):
        raise ConfigError("velocity_m_s", f"expected shape ({n}, 3), got {vel.shape}")
    height = np.broadcast_to(np.asarray(height_m, dtype=float), (n,)).copy()
    diameter = np.broadcast_to(np.asarray(diameter_m, dtype=float), (n,)).copy()
    density = np.broadcast_to(np.asarray(density_kg_m3, dtype=float), (n,)).copy()
    spin = np.zeros(n) if spin_rad_s is None else np.asarray(spin_rad_s, dtype=float)
    if spin.shape != (n,):
        raise ConfigError("spin_rad_s", f"expected shape ({n},), got {spin.shape}")
    for key, arr in (("position_m", pos), ("velocity_m_s", vel), ("spinner.height_m", height), ("spin_rad_s", spin)):
        if not np.all(np.isfinite(arr)):
            raise ConfigError(key, "must be finite (got NaN or inf)")
    if np.any(height < 0):
        raise ConfigError("spinner.height_m", f"launch height must be >= 0 m, got min {height.min()}")
    if not (np.all(np.isfinite(diameter)) and np.all(diameter > 0)):
        raise ConfigError("granule.diameter_m", "diameters must be finite and > 0 m")
    if not (np.all(np.isfinite(density)) and np.all(density > 0)):
        raise ConfigError("fertilizer.density_kg_m3", "particle densities must be finite and > 0 kg/m3")
    if not (np.isfinite(gravity_m_s2) and gravity_m_s2 > 0):
        raise ConfigError("gravity_m_s2", f"must be > 0, got {gravity_m_s2}")
    return pos, height, vel, diameter, density, spin


class _Model:
    """Acceleration of the granules; it depends on the velocity only (not on the
    position), so Runge-Kutta stages need the velocity stages only and positions
    follow as x + h * sum(b_i V_i). `k`: the per-granule drag constant K (n,)."""

    uses_time = False  # the acceleration does not depend on the time since launch

    def __init__(self, gravity: float, wind_xy: tuple[float, float]):
        self.g = float(gravity)
        self.wind = np.array([float(wind_xy[0]), float(wind_xy[1]), 0.0])[:, None]

    def accel(self, v: np.ndarray, k: np.ndarray, out: np.ndarray, t=None) -> np.ndarray:
        """a = g - K |v - w| (v - w) for velocities v (3, n); written into out (3, n)."""
        r = v - self.wind
        minus_ks = np.sqrt(np.einsum("ij,ij->j", r, r))
        minus_ks *= -k
        np.multiply(r, minus_ks, out=out)
        out[2] -= self.g
        return out


class _MagnusModel(_Model):
    """Drag plus the Magnus lift of a granule spinning about the vertical axis, whose
    spin decays in closed form: the acceleration depends on v and the time t since
    launch. `k` (10, n): K, signed lift factor sign(omega) (3/8)(rho/rho_p) C_max / r,
    r / S_sat, and the spin table of `magnus.spin_table` (7 rows)."""

    uses_time = True

    def accel(self, v: np.ndarray, k: np.ndarray, out: np.ndarray, t=None) -> np.ndarray:
        """Drag and gravity as `_Model` plus the Magnus lift (`_magnus_accel`), into out (3, n)."""
        _magnus_accel(v, k, t, self.wind[0, 0], self.wind[1, 0], self.g, out)
        return out


@njit(cache=True, error_model="numpy")
def _magnus_accel(v, k, t, wind_x, wind_y, g, out):
    """a = g - K |r| r + lift C_L(S) |r|^2 (omega x r)/|omega x r| per granule (r = v - w,
    r_h its horizontal part; compiled, as the lift adds ~20 array operations).
    With omega vertical, S = c r_h / |r|^2 for c = r |omega| / S_sat, so
    C_L |r|^2 / r_h = C_max c / (1 + x^4)^(1/4), x = S / S_sat: no division by r_h, and
    the force fades smoothly as the flight turns vertical."""
    n = v.shape[1]
    table = k[3:]
    c = np.empty(n)
    for j in range(n):  # the spin (a libm call): kept out of the loop below so that it vectorises
        c[j] = k[2, j] * magnus.spin_size(t[j], table, j)
    for j in range(n):
        rx, ry, rz = v[0, j] - wind_x, v[1, j] - wind_y, v[2, j]
        speed2 = rx * rx + ry * ry + rz * rz
        minus_ks = -k[0, j] * math.sqrt(speed2)
        x = c[j] * math.sqrt(rx * rx + ry * ry) / max(speed2, 1e-300)  # r = 0 (at rest in the wind): no lift
        x *= x
        f = k[1, j] * c[j] / math.sqrt(math.sqrt(1.0 + x * x))
        out[0, j] = minus_ks * rx - f * ry
        out[1, j] = minus_ks * ry + f * rx
        out[2, j] = minus_ks * rz - g


def _magnus_parameters(k_drag, diameter, density, spin, flight: Flight) -> np.ndarray:
    """The (10, n) per-granule parameters of `_MagnusModel`."""
    radius = 0.5 * diameter
    lift = 0.375 * flight.air_density_kg_m3 * flight.lift_coefficient_max / (density * radius) * np.sign(spin)
    table = magnus.spin_table(spin, diameter, density, flight.air_density_kg_m3, flight.air_viscosity_pa_s)
    return np.vstack([k_drag, lift, radius / flight.lift_saturation_spin_parameter, table])


def _lift_acts(flight: Flight, spin: np.ndarray) -> bool:
    """Whether the Magnus lift can move a landing point (else the drag-only model is exact)."""
    return bool(flight.magnus and flight.air_density_kg_m3 > 0 and flight.lift_coefficient_max > 0
                and np.any(spin != 0))


def _stage_times(model: _Model, t, h, fraction: float):
    """Times of a Runge-Kutta stage (n,), or None for a model that does not use them."""
    return t + fraction * h if model.uses_time else None


def _dp_step(model: _Model, x, v, k, h, a1, t):
    """One Dormand-Prince 5(4) step of length h (n,) from position x, velocity v
    (3, n) at time t (n,) with first stage a1 = accel(v, t).

    Returns (x_new, v_new, a_new, err_x, err_v); a_new = accel(v_new) (FSAL)."""
    n = v.shape[1]
    vel = np.empty((7, 3 * n))  # velocity stages, flattened (3n) for one matmul
    acc = np.empty((7, 3 * n))
    vel[0] = v.reshape(-1)
    acc[0] = a1.reshape(-1)
    h3 = np.tile(h, 3)
    for i in range(1, 7):
        vel[i] = vel[0] + h3 * (_DP_A[i] @ acc[:i])
        model.accel(vel[i].reshape(3, n), k, acc[i].reshape(3, n), _stage_times(model, t, h, _DP_C[i]))
    x_new = x + (h3 * (_DP_B @ vel[:6])).reshape(3, n)
    err_x = (h3 * (_DP_E @ vel)).reshape(3, n)
    err_v = (h3 * (_DP_E @ acc)).reshape(3, n)
    return x_new, vel[6].reshape(3, n).copy(), acc[6].reshape(3, n).copy(), err_x, err_v


def _rk4_step(model: _Model, x, v, k, h, a1, t):
    """Classical RK4 step (same stage structure); no error estimate."""
    half, end = _stage_times(model, t, h, 0.5), _stage_times(model, t, h, 1.0)
    v2 = v + (0.5 * h) * a1
    a2 = model.accel(v2, k, np.empty_like(v), half)
    v3 = v + (0.5 * h) * a2
    a3 = model.accel(v3, k, np.empty_like(v), half)
    v4 = v + h * a3
    a4 = model.accel(v4, k, np.empty_like(v), end)
    x_new = x + (h / 6.0) * (v + 2.0 * (v2 + v3) + v4)
    v_new = v + (h / 6.0) * (a1 + 2.0 * (a2 + a3) + a4)
    return x_new, v_new, model.accel(v_new, k, np.empty_like(v), end), None, None


def _hermite_guess(z0, v0, z1, v1, h):
    """Fraction s in [0, 1] where the cubic Hermite interpolant of z(t) over the
    step (values z0 > 0 >= z1, slopes v0, v1) crosses zero: a starting guess."""
    a = 2 * z0 + h * v0 - 2 * z1 + h * v1  # z(s) = a s^3 + b s^2 + c s + z0
    b = -3 * z0 - 2 * h * v0 + 3 * z1 - h * v1
    c = h * v0
    s = z0 / (z0 - z1)
    for _ in range(4):
        f = ((a * s + b) * s + c) * s + z0
        df = (3 * a * s + 2 * b) * s + c
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.clip(s - f / df, 0.0, 1.0)
        s = np.where(np.isfinite(s), s, 0.5)
    return s


def _land(model, step, x0, v0, k, h, a1, z1, vz1, t0):
    """Landing inside a step: solve z(tau) = 0 for the step length tau in (0, h],
    where z(tau) is the Runge-Kutta step itself (so the landing point carries no
    interpolation error). Safeguarded Newton (dz/dtau = vz) with a bracket.

    x0, v0 (3, m): state at the start of the step (z > 0), at time t0 (m,); h (m,): the step that
    ended at z1 <= 0 with vertical velocity vz1. Returns (tau, x_land)."""
    lo = np.zeros_like(h)
    hi = h.copy()
    tau = h * _hermite_guess(x0[2], v0[2], z1, vz1, h)
    x_tau = x0
    for _ in range(50):
        x_tau, v_tau, _, _, _ = step(model, x0, v0, k, tau, a1, t0)
        z, vz = x_tau[2], v_tau[2]
        above = z > 0
        lo = np.where(above, tau, lo)
        hi = np.where(above, hi, tau)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = tau - z / vz
        ok = np.isfinite(newton) & (newton >= lo) & (newton <= hi)
        tau_new = np.where(ok, newton, 0.5 * (lo + hi))
        if np.all((np.abs(z) <= 1e-12) | (np.abs(tau_new - tau) <= 1e-14 * h)):
            break
        tau = tau_new
    return tau, x_tau


def fly(
    position_m,
    height_m,
    velocity_m_s,
    diameter_m,
    density_kg_m3,
    flight: Flight,
    gravity_m_s2: float = GRAVITY_M_S2,
    dt_s: Optional[float] = None,
    *,
    atol: float = DEFAULT_ATOL,
    rtol: float = DEFAULT_RTOL,
    spin_rad_s=None,
) -> Landing:
    """Fly N granules from their launch state to the ground.

    position_m (N, 2): launch point in the machine frame; height_m (N,) or scalar:
    launch height above the ground (>= 0); velocity_m_s (N, 3): launch velocity
    relative to the machine; diameter_m, density_kg_m3: (N,) or scalars;
    spin_rad_s (N,): spin about the vertical axis (ccw +), used with `flight.magnus`
    (None: no spin). dt_s None: adaptive Dormand-Prince 5(4) with per-granule steps
    (local error tolerances atol, rtol); a number: fixed-step RK4 with that step.
    Granules launched at height 0 land at once (time 0, launch point).
    """
    pos, height, vel, diameter, density, spin = _check_inputs(
        position_m, height_m, velocity_m_s, diameter_m, density_kg_m3, gravity_m_s2, spin_rad_s
    )
    if dt_s is not None and not (np.isfinite(dt_s) and dt_s > 0):
        raise ConfigError("sim.dt_s", f"flight time step must be > 0 s, got {dt_s}")
    if not (atol > 0 and rtol >= 0):
        raise ConfigError("flight.atol", f"tolerances must be atol > 0, rtol >= 0; got {atol}, {rtol}")
    n = pos.shape[0]
    landing_xy = pos.copy()
    landing_t = np.zeros(n)

    idx = np.flatnonzero(height > 0)  # height 0: landed at launch
    if idx.size == 0:
        return Landing(landing_xy, landing_t)
    k = drag_constant(diameter, density, flight)[idx]
    if _lift_acts(flight, spin[idx]):
        model = _MagnusModel(gravity_m_s2, flight.wind_m_s)
        k = _magnus_parameters(k, diameter[idx], density[idx], spin[idx], flight)
    else:
        model = _Model(gravity_m_s2, flight.wind_m_s)
    k_drag = np.atleast_2d(k)[0]
    # ground-frame state, origin on the spinner axis at launch
    x = np.stack([pos[idx, 0], pos[idx, 1], height[idx]])
    v = np.ascontiguousarray(vel[idx].T)
    v[1] += flight.forward_speed_m_s
    t = np.zeros(idx.size)
    a1 = model.accel(v, k, np.empty_like(v), t)
    alive = np.ones(idx.size, dtype=bool)

    adaptive = dt_s is None
    step = _dp_step if adaptive else _rk4_step
    if adaptive:
        # first step: a small part of the drag time scale 1/(K |v - w|) and of the
        # time to fall the launch height from rest; error control does the rest
        rel = np.sqrt(np.einsum("ij,ij->j", v - model.wind, v - model.wind))
        h = np.minimum(0.05 / (k_drag * rel + 1e-9), np.sqrt(2.0 * x[2] / model.g))
        h = np.clip(h, 1e-5, 0.05)
    else:
        h = np.full(idx.size, float(dt_s))

    for _ in range(_MAX_ITERATIONS):
        x_new, v_new, a_new, err_x, err_v = step(model, x, v, k, h, a1, t)
        if adaptive:
            ratio = np.maximum(
                np.max(np.abs(err_x) / (atol + rtol * np.maximum(np.abs(x), np.abs(x_new))), axis=0),
                np.max(np.abs(err_v) / (atol + rtol * np.maximum(np.abs(v), np.abs(v_new))), axis=0),
            )
            accept = ratio <= 1.0
            factor = np.clip(0.9 * np.maximum(ratio, 1e-10) ** -0.2, 0.2, 5.0)
            factor[~accept] = np.minimum(factor[~accept], 1.0)
            move = accept & alive
        else:
            move = alive
        landed = move & (x_new[2] <= 0.0)
        if landed.any():
            tau, x_land = _land(model, step, x[:, landed], v[:, landed], k[..., landed], h[landed],
                                a1[:, landed], x_new[2, landed], v_new[2, landed], t[landed])
            landing_xy[idx[landed]] = x_land[0:2].T
            landing_t[idx[landed]] = t[landed] + tau
            alive &= ~landed
            move &= ~landed
        if move.all():
            x, v, a1 = x_new, v_new, a_new
            t += h
        else:
            x = np.where(move, x_new, x)
            v = np.where(move, v_new, v)
            a1 = np.where(move, a_new, a1)
            t = np.where(move, t + h, t)
        if adaptive:
            h = h * factor
        if landed.any():
            n_alive = int(alive.sum())
            if n_alive == 0:
                break
            if n_alive < 0.85 * alive.size:  # compact the working arrays
                idx, x, v, a1, k, t, h = (idx[alive], x[:, alive], v[:, alive], a1[:, alive],
                                          k[..., alive], t[alive], h[alive])
                alive = np.ones(idx.size, dtype=bool)
            else:
                h = np.where(alive, h, 0.0)  # park the landed ones until the next compaction
        if t.max() > _MAX_FLIGHT_S or h[alive].min() < 1e-12:
            raise RuntimeError("flight integration failed: a granule did not land")  # pragma: no cover
    return Landing(landing_xy, landing_t)


def reference_landing(
    position_m,
    height_m,
    velocity_m_s,
    diameter_m,
    density_kg_m3,
    flight: Flight,
    gravity_m_s2: float = GRAVITY_M_S2,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    spin_rad_s=None,
) -> Landing:
    """The same model solved one granule at a time with scipy's DOP853 and a
    terminal event at z = 0: slow, for tests and benchmarks. With Magnus lift the
    spin is a seventh state, integrated from the torque law (not the closed form),
    and the lift is built literally: C_L(S) |r|^2 along omega x r / |omega x r|."""

    pos, height, vel, diameter, density, spin = _check_inputs(
        position_m, height_m, velocity_m_s, diameter_m, density_kg_m3, gravity_m_s2, spin_rad_s
    )
    n = pos.shape[0]
    k_all = drag_constant(diameter, density, flight)
    wx, wy = flight.wind_m_s
    g = gravity_m_s2
    out_xy = pos.copy()
    out_t = np.zeros(n)

    def ground(_t, s, *_args):
        return s[2]

    ground.terminal = True
    ground.direction = -1

    def rhs(_t, s, kk):
        rx, ry, rz = s[3] - wx, s[4] - wy, s[5]
        ks = kk * np.sqrt(rx * rx + ry * ry + rz * rz)
        return [s[3], s[4], s[5], -ks * rx, -ks * ry, -g - ks * rz]

    rho_air, mu = flight.air_density_kg_m3, flight.air_viscosity_pa_s

    def rhs_magnus(t, s, kk, d, rho_p):
        ds = rhs(t, s, kk)
        rx, ry, rz, w = s[3] - wx, s[4] - wy, s[5], s[6]
        speed2 = rx * rx + ry * ry + rz * rz
        cross = np.array([-w * ry, w * rx])  # omega x r, omega = (0, 0, w)
        cross_norm = float(np.hypot(*cross))
        if cross_norm > 0.0:
            r_p = 0.5 * d
            c_l = magnus.lift_coefficient(r_p * cross_norm / speed2, flight.lift_coefficient_max,
                                          flight.lift_saturation_spin_parameter)
            lift = 0.375 * (rho_air / rho_p) * c_l * speed2 / r_p / cross_norm
            ds[3] += lift * cross[0]
            ds[4] += lift * cross[1]
        return ds + [float(magnus.spin_rate(w, d, rho_p, rho_air, mu))]

    lifting = _lift_acts(flight, spin)
    for i in range(n):
        if height[i] <= 0:
            continue
        s0 = [pos[i, 0], pos[i, 1], height[i], vel[i, 0], vel[i, 1] + flight.forward_speed_m_s, vel[i, 2]]
        if lifting:
            sol = solve_ivp(rhs_magnus, (0.0, _MAX_FLIGHT_S), s0 + [spin[i]], method="DOP853", rtol=rtol,
                            atol=atol, events=ground, args=(k_all[i], diameter[i], density[i]))
        else:
            sol = solve_ivp(rhs, (0.0, _MAX_FLIGHT_S), s0, method="DOP853", rtol=rtol, atol=atol,
                            events=ground, args=(k_all[i],))
        if sol.status != 1 or len(sol.t_events[0]) == 0:
            raise RuntimeError(f"reference solve failed for granule {i}: {sol.message}")  # pragma: no cover
        out_t[i] = sol.t_events[0][0]
        out_xy[i] = sol.y_events[0][0][0:2]
    return Landing(out_xy, out_t)
