"""Aerodynamics of a spinning granule in flight: Magnus lift and spin decay by air torque.

A granule is a smooth sphere of radius r, diameter d, density rho_p, spinning at omega
(rad/s) about the vertical axis, moving at v_rel relative to the air (rho, mu).

Lift (per unit mass), along omega x v_rel:

    a_L = rho C_L(S) pi r^2 |v_rel|^2 / (2 m) = (3/8) (rho / rho_p) C_L(S) |v_rel|^2 / r
    S   = r |omega x v_rel| / |v_rel|^2      (= r |omega| / |v_rel| when the spin is
                                               perpendicular to v_rel: horizontal flight)
    C_L = C_max x / (1 + x^4)^(1/4),   x = S / S_sat,   C_max = 0.37, S_sat = 0.34

Source: Zhou, Zhang & Xu (2022), "Experiments on drag and lift coefficients of a
spinning sphere", Water (MDPI, 2022): smooth spheres, 610 < Re < 3472, 0.149 < Rr < 3.471
(Rr = d |omega| / |v_rel| = 2 S). C_L falls as Re grows up to a critical Re and is
independent of Re above it; that limit value is 0.37 for 1 < Rr < 12 and rises with Rr
below Rr = 1. The curve above is our reading of it: a linear rise C_max S / S_sat joined
smoothly to the plateau (a corner would cost the adaptive integrator rejected steps at
every crossing), S_sat = 0.34 putting C_L within 5 % of 0.37 from Rr = 1 on. Its
initial slope, C_L = 0.54 Rr, stays below the Stokes-flow lift C_L = Rr (Rubinow &
Keller 1961, J. Fluid Mech. 11:447), as the fall with Re implies. Spreader granules
launch at S 0.4-0.65 (Rr 0.8-1.3) and Re ~1000-8000: Re above 3500 extrapolates the
Re-independent plateau; the drag crisis (Re ~2e5, where the lift can reverse: Kim et
al. 2014, J. Fluid Mech. 754:R2) is far away. Using the transverse spin
|omega x v_rel| / |v_rel| in S makes the force vanish smoothly as v_rel turns vertical.

Spin decay, I d omega/dt = -T with I = kappa m r^2 and the torque on a sphere rotating
in still air (Dennis, Singh & Ingham 1980, J. Fluid Mech. 101:257; the fit as used in
particle-laden flow codes, e.g. Crowe, Schwarzkopf, Sommerfeld & Tsuji 2012,
"Multiphase Flows with Droplets and Particles", 2nd ed.):

    T   = (rho / 2) r^5 C_R |omega| omega,   Re_R = rho d^2 |omega| / mu
    C_R = 64 pi / Re_R                       for Re_R < 32 (the Stokes torque 8 pi mu r^3 omega)
    C_R = 12.9 / sqrt(Re_R) + 128.4 / Re_R   for 32 <= Re_R (fit for 32 < Re_R < 1000)

Spreader granules leave at Re_R ~ 1e3-1e4: above 1000 the laminar boundary-layer term
12.9/sqrt(Re_R) is extrapolated. The torque ignores the translational flow past the
granule. With C_R of this form the spin ODE has a closed form (`spin_at`): with
u = 1/sqrt(|omega|), du/dt = q u + p on the upper branch, and |omega| decays
exponentially (rate lambda) on the Stokes branch. A 3 mm granule (1734 kg/m3) at
5000 (12000) rad/s keeps 76 % (68 %) of its spin after 1 s (flights last 0.4-1 s).
"""

from __future__ import annotations

import math

import numpy as np

from spreadgym.physics.compiled.options import INLINED, KERNEL
from spreadgym.physics.constants import SPHERE_INERTIA_FACTOR

STOKES_TORQUE_RE_R = 32.0  # Re_R where C_R switches from 64 pi / Re_R to the Dennis et al. fit
TORQUE_FIT_A = 12.9
TORQUE_FIT_B = 128.4

# rows of the per-granule spin table `spin_table` returns
_SIGN, _W0, _SLOPE, _Q, _T_STAR, _OMEGA_LOW, _LAMBDA = range(7)


def lift_coefficient(spin_parameter, lift_coefficient_max: float, saturation_spin_parameter: float) -> np.ndarray:
    """C_L(S) = C_max x / (1 + x^4)^(1/4), x = S / S_sat (dimensionless; S >= 0)."""
    x = np.asarray(spin_parameter, dtype=float) / saturation_spin_parameter
    return lift_coefficient_max * x / (1.0 + x**4) ** 0.25


def torque_coefficient(re_r) -> np.ndarray:
    """C_R(Re_R) of a sphere rotating in still fluid (Dennis et al. 1980); 0 at Re_R = 0."""
    re = np.asarray(re_r, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        upper = TORQUE_FIT_A / np.sqrt(re) + TORQUE_FIT_B / re
        stokes = 64.0 * np.pi / re
    return np.where(re <= 0.0, 0.0, np.where(re < STOKES_TORQUE_RE_R, stokes, upper))


def spin_rate(spin_rad_s, diameter_m, density_kg_m3, air_density_kg_m3: float, air_viscosity_pa_s: float):
    """d omega / dt = -T / I (rad/s^2) for spins omega (signed, rad/s): the ODE `spin_at` solves."""
    omega = np.asarray(spin_rad_s, dtype=float)
    d = np.asarray(diameter_m, dtype=float)
    re_r = air_density_kg_m3 * d * d * np.abs(omega) / air_viscosity_pa_s
    kappa = 3.0 * air_density_kg_m3 / (8.0 * np.pi * SPHERE_INERTIA_FACTOR * np.asarray(density_kg_m3, dtype=float))
    return -kappa * torque_coefficient(re_r) * np.abs(omega) * omega


def spin_table(spin_rad_s, diameter_m, density_kg_m3, air_density_kg_m3: float,
               air_viscosity_pa_s: float) -> np.ndarray:
    """Per-granule constants (7, N) of the closed-form spin history, for `spin_at`."""
    omega0 = np.asarray(spin_rad_s, dtype=float)
    d = np.broadcast_to(np.asarray(diameter_m, dtype=float), omega0.shape)
    rho_p = np.broadcast_to(np.asarray(density_kg_m3, dtype=float), omega0.shape)
    mu, rho = air_viscosity_pa_s, air_density_kg_m3
    f = SPHERE_INERTIA_FACTOR
    # upper branch: d|w|/dt = -kappa (A |w|^1.5 + B |w|), kappa = 3 rho / (8 pi f rho_p),
    # A = 12.9 sqrt(mu / (rho d^2)), B = 128.4 mu / (rho d^2); for u = |w|^-1/2: du/dt = q u + p
    q = 3.0 * TORQUE_FIT_B * mu / (16.0 * np.pi * f * rho_p * d * d)
    p = 3.0 * TORQUE_FIT_A * np.sqrt(rho * mu) / (16.0 * np.pi * f * rho_p * d)
    lam = 24.0 * mu / (f * rho_p * d * d)  # Stokes branch: d|w|/dt = -lam |w|
    with np.errstate(divide="ignore"):
        omega_star = STOKES_TORQUE_RE_R * mu / (rho * d * d)  # |w| at Re_R = 32 (inf without air)
    size = np.abs(omega0)
    upper = size > omega_star
    w0 = 1.0 / np.sqrt(np.where(upper, size, 1.0))
    w_star = 1.0 / np.sqrt(np.where(upper, omega_star, 1.0))
    slope = w0 + p / q  # u(t) = w0 + (w0 + p/q) expm1(q t)
    t_star = np.where(upper, np.log((w_star + p / q) / slope) / q, 0.0)  # when |w| reaches omega_star
    t_star[omega0 == 0.0] = np.inf  # no spin: nothing to decay
    omega_low = np.where(upper, omega_star, size)
    return np.stack([np.sign(omega0), w0, slope, q, t_star, omega_low, lam])


# The per-step helpers below are INLINED into the flight kernel, which calls them per
# granule and stage.

STEP_SERIES_LIMIT = 1e-2
"""Largest q h for which `step_spin_base` lets a step's stages use the series of
expm1(q f h) (five terms: relative error below (q h)^5 / 720 < 2e-13) instead of the
closed form; q h is about 1e-3 in spreader flights (q ~ 0.02 /s, h <= 0.05 s)."""


@INLINED
def inverse_spin_size(t: float, table: np.ndarray, j: int) -> float:
    """1 / |omega| (s/rad) of granule j of `spin_table` at time t (s) after launch. On the
    upper branch it is u^2 (u = |omega|^-1/2 is the closed form's variable), with no
    division. Finite for a granule with no spin (whose lift factor is 0)."""
    if t >= table[_T_STAR, j]:  # Stokes branch
        return math.exp(table[_LAMBDA, j] * (t - table[_T_STAR, j])) / table[_OMEGA_LOW, j]
    u = table[_W0, j] + table[_SLOPE, j] * math.expm1(table[_Q, j] * t)
    return u * u


@INLINED
def spin_size(t: float, table: np.ndarray, j: int) -> float:
    """|omega| (rad/s) of granule j of `spin_table` at time t (s) after launch."""
    return 1.0 / inverse_spin_size(t, table, j)


@INLINED
def step_spin_base(t: float, h: float, table: np.ndarray, j: int) -> tuple[float, float, float]:
    """(u(t), u(t) + p/q, q h) for the stages of a step from t of length h (s): on the
    upper branch u(t + f h) = u(t) + (u(t) + p/q) expm1(q f h), so one expm1 per step
    serves every stage (`step_inverse_spin`). q h is returned as -1 when the step reaches
    the Stokes branch or q h exceeds STEP_SERIES_LIMIT: use `inverse_spin_size` then."""
    rate = table[_Q, j]
    if not (t + h < table[_T_STAR, j] and rate * h <= STEP_SERIES_LIMIT):
        return 0.0, 0.0, -1.0
    e = math.expm1(rate * t)
    return table[_W0, j] + table[_SLOPE, j] * e, table[_SLOPE, j] * (e + 1.0), rate * h


@INLINED
def step_inverse_spin(u: float, growth: float, qh: float, fraction: float) -> float:
    """1 / |omega| (s/rad) at t + fraction h from `step_spin_base`'s (u, growth, qh >= 0)."""
    y = qh * fraction
    u = u + growth * (y * (1.0 + y * (0.5 + y * (1.0 / 6.0 + y * (1.0 / 24.0 + y * (1.0 / 120.0))))))
    return u * u


@INLINED
def lift_factor(lift: float, size2: float, inverse_spin: float, rx: float, ry: float, speed2: float) -> float:
    """f (1/s) with the lift acceleration f (-r_y, r_x) (m/s^2) of a granule moving at r
    relative to the air (speed2 = |r|^2, m^2/s^2), for lift = sign(omega) (3/8)(rho/rho_p)
    C_max / S_sat (dimensionless), size2 = (r / S_sat)^2 (m^2) and inverse_spin = 1/|omega|
    (s/rad). With omega vertical, x = S / S_sat = c r_h / |r|^2 with c = r |omega| / S_sat
    and r_h the horizontal part of r, and C_L |r|^2 / r_h = C_max c / (1 + x^4)^(1/4);
    multiplied through by 1/|omega| this is
        f = lift |r|^2 / Y^(1/4),   Y = (|r|^2 / |omega|)^4 + (size2 r_h^2)^2,
    with one division, no division by r_h, and a force that fades smoothly as the flight
    turns vertical. r = 0 (at rest in the wind): f = 0."""
    a = inverse_spin * speed2
    a2 = a * a
    b = size2 * (rx * rx + ry * ry)
    return lift * speed2 / math.sqrt(math.sqrt(max(a2 * a2 + b * b, 1e-300)))


@KERNEL
def _spin_sizes(t: np.ndarray, table: np.ndarray, out: np.ndarray) -> None:
    for j in range(t.size):
        out[j] = spin_size(t[j], table, j)


def spin_size_at(time_s, table: np.ndarray) -> np.ndarray:
    """|omega| (rad/s) at times time_s (N,) after launch, from `spin_table` (7, N)."""
    t = np.ascontiguousarray(np.broadcast_to(np.asarray(time_s, dtype=float), table.shape[1:]))
    out = np.empty(t.size)
    _spin_sizes(t, np.ascontiguousarray(table), out)
    return out


def spin_sign(table: np.ndarray) -> np.ndarray:
    """Sense of each granule's spin (+1 ccw, -1 cw, 0 none): air torque never reverses it."""
    return table[_SIGN]


def spin_at(time_s, table: np.ndarray) -> np.ndarray:
    """Signed spin (rad/s) at times time_s (N,) after launch, from `spin_table` (7, N)."""
    return spin_sign(table) * spin_size_at(time_s, table)
