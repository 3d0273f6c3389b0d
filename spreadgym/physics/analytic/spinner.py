"""The `analytic` spinner model: closed-form catch, slide and roll along straight vanes.

Every granule is followed in three stages, all vectorised over granules:

1. Drop and wait. The granule falls straight down from its release point (plan-view
   position unchanged). Vanes can strike it from the moment it is below the vane
   tops (t_top = sqrt(2 max(H - h_vane, 0) / g), the convention of the pymunk model);
   it touches the disc at t_land = sqrt(2 H / g). Bounces are ignored: the vertical
   velocity at landing is lost and the disc takes no friction impulse from the impact.
   While it lies on the disc, the disc slides under it and drags it forwards. This is
   taken to first order: a constant acceleration mu_d g along the disc's direction of
   motion at the landing point (exact for mu_d = 0; valid while the drift speed is
   small against the disc speed; capped at half the disc speed, so the granule never
   outruns the vanes; notes count the granules that reach the cap).
2. Catch. The leading face of the first vane to reach the granule strikes it at the
   relative normal speed a (Omega x for a granule at rest). The impact reverses the
   normal relative velocity with the pair's restitution e (contacts.vane_restitution)
   and applies Coulomb friction: a tangential impulse of at most mu_v (1 + e) a that
   stops the slip of the contact point but never reverses it (for rotation "free" it
   spins the granule up: the slip changes by the impulse times 1 + 1/kappa). The
   granule then flies ahead of the face (a straight line in the machine frame with
   the disc's drag to first order) until the face catches it again, which is the next
   impact, and so on; once a rebound is slower than REBOUND_STOP * Omega x the impact
   is plastic and the granule stays on the face. e = 0: one plastic impact (still
   with its friction impulse). A release point closer to the axis than the face's
   inner end is moved radially out to it (the vane's inner end sweeps it up); one
   beyond the face's reach is moved in to the tip. A granule that lands overlapping a
   vane (plan view) is pushed to the nearer face: the leading face catches it at once,
   from the trailing face it waits for the next vane.
3. Along the vane: `spreadgym.physics.analytic.vane_slide.run_along_vane` (exact closed forms:
   slide; for rotation "free" slide, then roll without slip once friction can hold it;
   hops off the face when the normal force would be negative, flights after rebounds,
   impacts at every re-catch; see that module). Departure when the centre reaches the
   disc radius R; if the contact point reaches the vane tip first (vanes shorter than
   R, or pitched forwards), the granule flies on in a straight line in the machine
   frame to R (disc friction neglected there).

Departure state: position on the circle |c| = R, horizontal velocity in the machine
frame, spin about z (machine frame; 0 when locked), height 0, vertical velocity 0,
time from release. Everything is computed with the spinner at angle 0 at release and
turned by the granule's phase at the end (spreadgym.physics.granules).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.physics.analytic.vane_slide import KAPPA_SPHERE, REBOUND_STOP, run_along_vane, solve_increasing
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, RETAINED_TIMEOUT, Departure
from spreadgym.physics.granules import GranuleBatch, rotate

GRAVITY_M_S2 = 9.81
DRIFT_CAP = 0.5  # first-order disc drag: drift speed capped at this fraction of the disc speed
TWO_PI = 2.0 * math.pi

ASSUMPTIONS = (
    "analytic: plan view, closed forms; no bounces on the disc (drop: fall time only, vertical speed lost at landing)",
    "analytic: vanes can catch a falling granule once it is below the vane tops; disc drag only once it has landed",
    "analytic: disc drag before the catch taken to first order (constant mu_d g along the disc motion)",
    "analytic: catch and re-catches are impacts with the vane restitution and a Coulomb friction impulse; "
    "bouncing ends (plastic) once a rebound is below %g Omega x" % REBOUND_STOP,
    "analytic: spin about the vertical axis only, sphere I = 2/5 m r^2; no drilling or rolling on the disc",
    "analytic: disc drag to first order during flights off the face (closed form along the straight line); "
    "neglected after leaving a vane tip",
)


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
    r_in, r_out = scene.vanes.inner_radius_m, scene.vane_outer_radius_m
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


def simulate_analytic(
    scene: Scene,
    granules: GranuleBatch,
    contacts: Contacts,
    *,
    gravity_m_s2: float = GRAVITY_M_S2,
    time_limit_s: float = 3.0,
    impact_friction: bool = True,
    flight_drag: bool = True,
    rebound_stop: float = REBOUND_STOP,
) -> Departure:
    """Departure states of `granules` by the closed-form model (see the module docstring).

    impact_friction: Coulomb friction impulse at the catch and re-catches (False: the
    tangential relative velocity is kept); flight_drag: first-order disc drag during
    flights off the face; rebound_stop: rebounds below rebound_stop * Omega x end the
    bouncing. The defaults are the model; the switches are for studies and tests.
    """
    omega = scene.spinner.omega_rad_s
    Om = abs(omega)
    sense = math.copysign(1.0, omega)
    rotation = scene.granule.rotation
    n = granules.count
    r = granules.radius_m
    geo = vane_geometry(scene, r)
    catch = catch_granules(scene, granules, contacts, gravity_m_s2)
    k = catch.vane
    drop = scene.feed.drop_height_m
    t_land = math.sqrt(2.0 * drop / gravity_m_s2)
    run = run_along_vane(
        Om, catch.x_m, catch.speed_along_m_s, catch.w_m, geo.p_u[k], geo.x_tip[k], scene.spinner.radius_m,
        contacts.vane_friction, contacts.disc_friction, r, rotation=rotation, kappa=KAPPA_SPHERE,
        g=gravity_m_s2, time_limit_s=np.maximum(time_limit_s - catch.time_s, 0.0),
        disc_contact_from_s=np.maximum(t_land - catch.time_s, 0.0),
        approach_speed0=catch.approach_m_s, restitution=contacts.vane_restitution,
        impact_friction=impact_friction, flight_drag=flight_drag, rebound_stop=rebound_stop,
    )
    t = catch.time_s + run.t_s
    u, nn = geo.u[k], geo.n[k]
    pos = run.pos_u[:, None] * u + run.pos_n[:, None] * nn
    vel = run.vel_u[:, None] * u + run.vel_n[:, None] * nn
    turn = omega * t + granules.phase_rad
    pos = rotate(pos, turn)
    vel = rotate(vel, turn)
    if rotation == "locked":
        spin = np.zeros(n)
    else:
        spin = omega + sense * run.spin_offset / r
    outcome = run.outcome.astype(np.int8)
    # still falling when it leaves (high drop, fast disc): height and vertical speed of the fall
    airborne = t < t_land
    height = np.where(airborne, drop - 0.5 * gravity_m_s2 * t * t, 0.0)
    vz = np.where(airborne, -gravity_m_s2 * t, 0.0)
    notes = list(ASSUMPTIONS)
    notes.append(
        "analytic: departure at |c| = R = %.4g m; %d departed, %d stuck, %d timed out"
        % (scene.spinner.radius_m, int(np.sum(outcome == DEPARTED)), int(np.sum(outcome == RETAINED_STUCK)),
           int(np.sum(outcome == RETAINED_TIMEOUT)))
    )
    counts = {
        "release point moved onto the face's reach": int(catch.moved_in.sum()),
        "landed overlapping a vane, caught at once": int(catch.snapped.sum()),
        "first-order disc drag reached its cap": int(catch.drift_capped.sum()),
        "bounced off the face (restitution %g)" % contacts.vane_restitution: int(np.sum(run.bounces > 0)),
        "hopped off the face (normal force < 0) and were caught again": int(np.sum(run.hops > 0)),
        "came to rest on the disc during a flight (disc drag)": int(np.sum(run.flight_stops > 0)),
        "rolled on the face (no slip) for part of the way": int(np.sum(run.stick_time_s > 0)),
        "rolling broke into sliding": int(np.sum(run.stick_breaks > 0)),
        "left at the vane tip before reaching R": int(run.left_at_tip.sum()),
        "were caught before landing (no disc drag until they land)": int(np.sum(catch.time_s < t_land)),
        "left the disc before landing on it": int(np.sum(airborne & (outcome == DEPARTED))),
        "stopped at the inner end of the vane": int(run.stuck_at_hub.sum()),
    }
    for what, c in counts.items():
        if c:
            notes.append(f"analytic: {c} granule(s) {what}")
    notes.extend(run.notes)
    return Departure(
        position_m=pos,
        velocity_m_s=vel,
        spin_rad_s=spin,
        height_m=height,
        vertical_velocity_m_s=vz,
        time_s=t,
        outcome=outcome,
        model="analytic",
        dt_s=0.0,
        notes=notes,
    )
