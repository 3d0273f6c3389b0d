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

Method (default, `dt_s=None`): an embedded Dormand-Prince 5(4) Runge-Kutta pair with
its own step size per granule chosen by error control (a granule with little drag takes
a few long steps; without drag the method is exact and lands in one or two steps). The
landing instant is found inside the last step by a safeguarded Newton iteration on the
Runge-Kutta step length (started from a cubic Hermite guess), so the landing point
carries no interpolation error. `dt_s=<float>` runs the classical fixed-step RK4
instead (kept for comparisons and benchmarks). Both run compiled, each granule on its
own (`spreadgym.spread.flight_kernel`): each granule is an independent small problem,
and a granule's landing does not depend on the others in the batch.
`reference_landing` solves the same model one granule at a time with scipy's DOP853
at tight tolerance.

With `flight.magnus` on, a granule keeps its departure spin about the vertical axis
and meets a horizontal Magnus lift sideways to its velocity; the spin decays by air
torque (`spreadgym.physics.magnus`: the law, its sources and ranges). The spin has a
closed form in time, so the Runge-Kutta stages still carry velocities only and the
acceleration is evaluated at each stage's time. With it off (the default) the
arithmetic is exactly that of the drag-only model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from spreadgym.config.scene import Flight
from spreadgym.errors import ConfigError
from spreadgym.physics import magnus
from spreadgym.physics.constants import GRAVITY_M_S2
from spreadgym.spread import flight_kernel

# Local error tolerance of the adaptive method, per step and per granule: absolute
# (m on positions, m/s on velocities) plus relative. Chosen so the landing point
# stays within ~0.01 mm of a tight-tolerance solve (see docs/flight-and-pattern.md).
DEFAULT_ATOL = 2e-6
DEFAULT_RTOL = 1e-7


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


def _magnus_parameters(k_drag, diameter, density, spin, flight: Flight) -> tuple[np.ndarray, np.ndarray]:
    """Per-granule parameters of the compiled flight with lift: (3, n) rows K (1/m), the
    signed lift factor sign(omega) (3/8)(rho/rho_p) C_max / S_sat (dimensionless) and
    (r / S_sat)^2 (m^2) (see `magnus.lift_factor`); and the (7, n) spin table of
    `magnus.spin_table`."""
    size = 0.5 * diameter / flight.lift_saturation_spin_parameter
    lift = (0.375 * flight.air_density_kg_m3 * flight.lift_coefficient_max / flight.lift_saturation_spin_parameter
            / density * np.sign(spin))
    table = magnus.spin_table(spin, diameter, density, flight.air_density_kg_m3, flight.air_viscosity_pa_s)
    return np.stack([k_drag, lift, size * size]), np.ascontiguousarray(table)


def lift_acts(flight: Flight, spin: np.ndarray) -> bool:
    """Whether the Magnus lift can move a landing point (else the drag-only model is exact)."""
    return bool(flight.magnus and flight.air_density_kg_m3 > 0 and flight.lift_coefficient_max > 0
                and np.any(spin != 0))


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
    lift: Optional[bool] = None,
) -> Landing:
    """Fly N granules from their launch state to the ground.

    position_m (N, 2): launch point in the machine frame; height_m (N,) or scalar:
    launch height above the ground (>= 0); velocity_m_s (N, 3): launch velocity
    relative to the machine; diameter_m, density_kg_m3: (N,) or scalars;
    spin_rad_s (N,): spin about the vertical axis (ccw +), used with `flight.magnus`
    (None: no spin). dt_s None: adaptive Dormand-Prince 5(4) with per-granule steps
    (local error tolerances atol, rtol); a number: fixed-step RK4 with that step.
    Granules launched at height 0 land at once (time 0, launch point). `lift`: whether
    the Magnus lift acts (None: `lift_acts` of these granules); a batch that flies a
    run's granules in parts gives every part the run's own answer, so that each granule
    lands as it does in the whole run.
    """
    pos, height, vel, diameter, density, spin = _check_inputs(
        position_m, height_m, velocity_m_s, diameter_m, density_kg_m3, gravity_m_s2, spin_rad_s
    )
    if dt_s is not None and not (np.isfinite(dt_s) and dt_s > 0):
        raise ConfigError("sim.dt_s", f"flight time step must be > 0 s, got {dt_s}")
    if not (atol > 0 and rtol >= 0):
        raise ConfigError("flight.atol", f"tolerances must be atol > 0, rtol >= 0; got {atol}, {rtol}")
    k = drag_constant(diameter, density, flight)
    lift = lift_acts(flight, spin) if lift is None else bool(lift)
    if lift:
        par, table = _magnus_parameters(k, diameter, density, spin, flight)
    else:
        par, table = k[None, :], np.empty((7, 0))
    ground_velocity = vel.copy()  # ground frame: the machine's forward speed added
    ground_velocity[:, 1] += flight.forward_speed_m_s
    landing_xy = np.empty((pos.shape[0], 2))  # C order whatever the input's: one compiled signature
    landing_t = np.empty(pos.shape[0])
    failed = flight_kernel.fly_all(
        np.ascontiguousarray(pos), height, ground_velocity, par, table, lift,
        float(flight.wind_m_s[0]), float(flight.wind_m_s[1]), float(gravity_m_s2),
        0.0 if dt_s is None else float(dt_s), float(atol), float(rtol), landing_xy, landing_t,
    )
    if failed:
        raise RuntimeError(f"flight integration failed: {failed} granules did not land")  # pragma: no cover
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

    from scipy.integrate import solve_ivp  # here: a reference for tests, not worth ~0.1 s of every start-up

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

    lifting = lift_acts(flight, spin)
    for i in range(n):
        if height[i] <= 0:
            continue
        s0 = [pos[i, 0], pos[i, 1], height[i], vel[i, 0], vel[i, 1] + flight.forward_speed_m_s, vel[i, 2]]
        if lifting:
            sol = solve_ivp(rhs_magnus, (0.0, flight_kernel.MAX_FLIGHT_S), s0 + [spin[i]], method="DOP853", rtol=rtol,
                            atol=atol, events=ground, args=(k_all[i], diameter[i], density[i]))
        else:
            sol = solve_ivp(rhs, (0.0, flight_kernel.MAX_FLIGHT_S), s0, method="DOP853", rtol=rtol, atol=atol,
                            events=ground, args=(k_all[i],))
        if sol.status != 1 or len(sol.t_events[0]) == 0:
            raise RuntimeError(f"reference solve failed for granule {i}: {sol.message}")  # pragma: no cover
        out_t[i] = sol.t_events[0][0]
        out_xy[i] = sol.y_events[0][0][0:2]
    return Landing(out_xy, out_t)
