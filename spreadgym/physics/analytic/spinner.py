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

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.physics.analytic.catch import catch_granules, vane_geometry
from spreadgym.physics.analytic.motions import Face
from spreadgym.physics.analytic.vane_slide import REBOUND_STOP, CatchState, FaceFriction, VaneOptions, run_along_vane
from spreadgym.physics.constants import GRAVITY_M_S2
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, RETAINED_TIMEOUT, Departure
from spreadgym.physics.granules import GranuleBatch, rotate

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
        Face(Om, catch.w_m, geo.p_u[k], geo.x_tip[k], scene.spinner.radius_m),
        CatchState(catch.x_m, catch.speed_along_m_s, r, approach_speed0=catch.approach_m_s,
                   disc_contact_from_s=np.maximum(t_land - catch.time_s, 0.0),
                   time_limit_s=np.maximum(time_limit_s - catch.time_s, 0.0)),
        FaceFriction(contacts.vane_friction, contacts.disc_friction, contacts.vane_restitution,
                     contacts.vane_rolling_resistance),
        VaneOptions(rotation=rotation, g=gravity_m_s2, impact_friction=impact_friction, flight_drag=flight_drag,
                    rebound_stop=rebound_stop),
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
