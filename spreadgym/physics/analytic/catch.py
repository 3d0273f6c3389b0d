"""Stages 1 and 2 of the `analytic` model (see `spinner`): drop, wait on the disc, catch.

The granule falls straight down; vanes can strike it once it is below the vane tops;
lying on the disc it drifts with the disc's drag to first order; the leading face of
the first vane to reach it catches it. All vectorised over granules, SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.physics.analytic.roots import solve_increasing
from spreadgym.physics.constants import GRAVITY_M_S2
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.granules import GranuleBatch, rotate

DRIFT_CAP = 0.5  # first-order disc drag: drift speed capped at this fraction of the disc speed
TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class VaneGeometry:
    """Leading-face lines of every vane at spinner angle 0 (K vanes, n granules)."""

    u: np.ndarray  # (K, 2) along each vane, outwards
    n: np.ndarray  # (K, 2) leading-face normal (towards the direction of rotation)
    p_u: np.ndarray  # (K,) p.u of the inner end: x of the face line's inner end
    p_n: np.ndarray  # (K,) p.n of the inner end (negative for a tip leaning forwards)
    x_tip: np.ndarray  # (K,) x where the face ends (centre line reaches the outer radius)
    w: np.ndarray  # (n, K) offset c.n of the granule-centre line on the leading face
    w_trail: np.ndarray  # (n, K) the same on the trailing face


def vane_geometry(scene: Scene, granule_radius_m: np.ndarray) -> VaneGeometry:
    """Face lines of the scene's vanes for granules of the given radii."""
    count = scene.vanes.count
    sense = math.copysign(1.0, scene.spinner.omega_rad_s)
    theta = TWO_PI * np.arange(count) / count
    pitch = np.asarray(scene.vanes.pitches_rad(), dtype=float)
    ang = theta + sense * pitch
    u = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    n = sense * np.stack([-u[:, 1], u[:, 0]], axis=1)
    r_in, r_out = np.asarray(scene.vanes.inner_radii_m()), scene.vane_outer_radius_m
    p_u = r_in * np.cos(pitch)
    p_n = -r_in * np.sin(pitch)
    x_tip = np.sqrt(np.maximum(r_out * r_out - p_n * p_n, p_u * p_u))
    h = 0.5 * scene.vanes.thickness_m + np.asarray(granule_radius_m, dtype=float)[:, None]
    return VaneGeometry(u=u, n=n, p_u=p_u, p_n=p_n, x_tip=x_tip, w=p_n[None, :] + h, w_trail=p_n[None, :] - h)


@dataclass(frozen=True)
class Catch:
    """Where and when each granule is caught (spinner frame at the catch)."""

    vane: np.ndarray  # (n,) index of the catching vane
    time_s: np.ndarray  # (n,) time from release to the catch
    x_m: np.ndarray  # (n,) position along the face line, c.u
    w_m: np.ndarray  # (n,) c.n
    speed_along_m_s: np.ndarray  # (n,) relative velocity along the face just before the impact
    approach_m_s: np.ndarray  # (n,) relative speed towards the face (normal) just before the impact
    moved_in: np.ndarray  # (n,) release point moved radially onto the face's reach
    snapped: np.ndarray  # (n,) landed overlapping the vane, pushed onto the leading face
    drift_capped: np.ndarray  # (n,) first-order drift reached its cap


def _drift(tau, tau_land, a, cap_time, rho):
    """Drift of a granule lying on the disc, expanded in the disc's drag a = mu_d g.

    Polar coordinates in the machine frame about the axis, from rest at radius rho:
    the drag acts along the disc's motion to first order, so the arc length is
    D = a s^2 / 2 and the azimuthal speed D' = a s (s: time on the disc); lacking the
    centripetal force for that speed, the radius grows as r'' = D'^2 / rho, i.e.
    dr = a^2 s^4 / (12 rho). D' is capped at cap_time (see DRIFT_CAP).
    Returns (D, D', dr, r').
    """
    s = np.maximum(tau - tau_land, 0.0)
    sc = np.minimum(s, cap_time)
    ex = s - sc
    D = 0.5 * a * sc * sc + a * sc * ex
    k = a * a / rho
    r_dot = k * (sc**3 / 3.0 + sc * sc * ex)
    dr = k * (sc**4 / 12.0 + sc**3 * ex / 3.0 + 0.5 * sc * sc * ex * ex)
    return D, a * sc, dr, r_dot


def catch_granules(scene: Scene, granules: GranuleBatch, contacts: Contacts,
                   gravity_m_s2: float = GRAVITY_M_S2) -> Catch:
    """Stages 1 and 2 of the model docstring: drop, wait with first-order drag, catch."""
    omega = scene.spinner.omega_rad_s
    Om = abs(omega)
    sense = math.copysign(1.0, omega)
    r = granules.radius_m
    geo = vane_geometry(scene, r)
    n = granules.count
    drop = scene.feed.drop_height_m
    t_top = math.sqrt(2.0 * max(drop - scene.vanes.height_m, 0.0) / gravity_m_s2)
    t_land = math.sqrt(2.0 * drop / gravity_m_s2)
    q = rotate(granules.release_in_spinner_frame(), np.full(n, -omega * t_top))
    rho0 = np.hypot(q[:, 0], q[:, 1])
    ang_q = sense * np.arctan2(q[:, 1], q[:, 0])  # angles measured in the sense of rotation
    ang_u = sense * np.arctan2(geo.u[:, 1], geo.u[:, 0])
    w = geo.w
    rho_in = np.hypot(geo.p_u[None, :], w)
    rho_tip = np.hypot(geo.x_tip[None, :], w)
    rho_c = np.clip(rho0[:, None], rho_in, rho_tip)
    ang_face = ang_u[None, :] + np.arcsin(w / rho_c)
    delta = np.mod(ang_q[:, None] - ang_face, TWO_PI)
    # overlap with the vane body: between the trailing and the leading face lines
    wt = geo.w_trail
    ang_trail = ang_u[None, :] + np.arcsin(np.clip(wt / rho_c, -1.0, 1.0))
    width = np.mod(ang_face - ang_trail, TWO_PI)
    snap = delta > TWO_PI - 0.5 * width
    delta = np.where(snap, 0.0, delta)
    k = np.argmin(delta, axis=1)
    rows = np.arange(n)
    d0 = delta[rows, k]
    wk, rc = w[rows, k], rho_c[rows, k]
    moved = (rho0 < rho_in[rows, k]) | (rho0 > rho_tip[rows, k])
    # wait: H(tau) = d0 + atan(D/rho_c) - Omega tau - asin(w/rho(tau)) + asin(w/rho_c) = 0
    a = contacts.disc_friction * gravity_m_s2
    tau_land = max(t_land - t_top, 0.0)
    cap_time = DRIFT_CAP * Om * rc / a if a > 0 else np.full(n, np.inf)
    asin_c = np.arcsin(wk / rc)

    tau = np.zeros(n)
    wait = np.nonzero(d0 > 0.0)[0]
    if wait.size and a > 0:
        d0w, rcw, wkw, capw, asw = d0[wait], rc[wait], wk[wait], cap_time[wait], asin_c[wait]

        def minus_H(tau, i):
            D, Dp, dr, r_dot = _drift(tau, tau_land, a, capw[i], rcw[i])
            rho = rcw[i] + dr
            H = d0w[i] + D / rcw[i] - Om * tau - np.arcsin(wkw[i] / rho) + asw[i]
            root = np.sqrt(np.maximum(rho**2 - wkw[i] ** 2, 1e-300))
            dH = Dp / rcw[i] - Om + wkw[i] * r_dot / (rho * root)
            return -H, -dH

        hi = tau_land + (d0w + math.pi) / ((1.0 - DRIFT_CAP) * Om)
        tau[wait] = solve_increasing(minus_H, np.zeros(wait.size), hi)
    elif wait.size:
        tau[wait] = d0[wait] / Om
    D, Dp, dr, r_dot = _drift(tau, tau_land, a, cap_time, rc)
    rho = rc + dr
    x = np.sqrt(np.maximum(rho * rho - wk * wk, 0.0))
    # machine-frame velocity r' e_r + D' e_phi seen along the face: e_r.u = x/rho, e_phi.u = -w/rho
    v_along = Om * wk + (r_dot * x - Dp * wk) / rho
    # and normal to it (e_r.n = w/rho, e_phi.n = x/rho): the face comes at Omega x
    xc = np.clip(x, geo.p_u[k], geo.x_tip[k])
    approach = np.maximum(Om * xc - (r_dot * wk + Dp * x) / rho, 0.0)
    return Catch(
        vane=k, time_s=t_top + tau, x_m=xc, w_m=wk, speed_along_m_s=v_along, approach_m_s=approach, moved_in=moved,
        snapped=snap[rows, k], drift_capped=(np.maximum(tau - tau_land, 0.0) > cap_time),
    )
