"""Exact motion of a granule along one straight vane, in the frame turning with the disc:
the phase machine. The closed forms of each phase are in `motions`, their events'
roots in `roots`, the flights off the face in `vane_flight`.

Plan view. The disc turns at omega (signed about +z); Omega = |omega|. A vane is a
straight plate; `u` is the unit vector along it (outwards) and `n` the unit normal on
its leading side (the face that pushes). The granule's centre sits on the line

    c = x u + w n,    x = c.u (varies),    w = c.n (constant on one face),

with w = p.n + h for a vane whose inner end is p and h = half the vane thickness plus
the granule radius. Every quantity below is written in (u, n) components; in those
components the equations do not depend on the sense of rotation (cw is the mirror
image of ccw), so this module only ever sees Omega > 0.

Forces per unit mass, rotating frame, granule on the leading face:
    centrifugal  Omega^2 c,   Coriolis  -2 omega z x (x' u) = -2 Omega x' n,
    vane normal  N n,   vane friction  f u,   disc friction  -mu_d g sgn(x') u.
The n-component fixes the normal force, and the u-component is the equation of motion:

    N   = 2 Omega x' - Omega^2 w                       (contact holds while N >= 0)
    x'' = Omega^2 x - mu_d g sgn(x') + f.

Spin about the vertical axis. Let phi' be the granule's spin relative to the disc
(inertial spin minus omega) and Phi = sgn(omega) r phi' (a speed). The contact point
of the granule slips along the face at

    slip = x' + Phi,        Phi' = f / kappa,   kappa = I / (m r^2) = 2/5 for a sphere.

Phi = -r Omega is a granule that does not turn in the machine frame (the frame's own
rotation enters the no-slip condition here). A "locked" granule keeps that value
(kappa -> infinity); a "free" granule starts with it (no spin at the catch).

Rolling resistance (type A of Ai et al. 2011): the vane resists the granule's spin
relative to it with a torque of magnitude mu_r r N, directed against phi' (so against
Phi), which holds phi' = 0 when it can:  Phi' = (f - rho mu_r N) / kappa, rho = sgn(Phi).

Phases (each a linear ODE with constant coefficients, so each has a closed form):
  * slide:  f = -eps mu_v N, eps = sgn(slip):
        x'' + 2 eps mu_v Omega x' - Omega^2 x = -sgn(x') mu_d g + eps mu_v Omega^2 w
    roots Omega(-eps mu_v +- sqrt(1 + mu_v^2)); for eps = sgn(x') = +1 this is the
    classic sliding equation.
        Phi(t) = Phi0 - ((eps mu_v + rho mu_r) / kappa)(2 Omega (x - x0) - Omega^2 w t),
    until Phi reaches 0: there the resistance holds it ("held", rho = 0, Phi stays 0: the
    granule turns with the vane) if mu_r >= mu_v, else the friction turns it on through 0
    (rho = -eps). With mu_r >= mu_v a sliding granule therefore ends as the classic
    sliding point mass (slip = x'): the sliding limit.
  * stick (no slip at the vane; "rolling" for a free sphere):
        x'' (1 + kappa) = Omega^2 x - sgn(x') (mu_d g + mu_r N),
        f = -(kappa G + sgn(x') mu_r N) / (1 + kappa),
    with G = Omega^2 x - sgn(x') mu_d g; it holds while |f| <= mu_v N. With mu_r = 0 this
    is the loss-free roller (the departure then does not depend on mu_v once mu_v is
    large enough to hold the roll). For a locked granule (kappa -> inf) sticking means
    x' = r Omega held by static friction f = -G, and mu_r does nothing (no rotation).
  * flight: N would be negative, or the granule rebounds from an impact, so it is off
    the face. It then moves in a straight line in the machine frame, plus the disc's
    drag to first order if asked (flight_drag; closed form along the line: `vane_flight`),
    until the face catches it again (an impact, below), it crosses the disc rim, or the
    drag has used up its velocity relative to the disc (it then lies on the disc: held
    there if Omega^2 |c| <= mu_d g, else a new flight from rest).

Impacts (the catch when CatchState.approach_speed0 > 0, every re-catch): the relative normal
velocity -a (towards the face) becomes e a (restitution e); with impact_friction a
tangential impulse of at most mu_v (1 + e) a (per unit mass) acts against the slip of
the contact point and stops it at most (slip changes by the impulse times 1 + 1/kappa,
times 1 when locked), Phi changes by impulse / kappa; then the rolling resistance's
angular impulse takes at most mu_r (1 + e) a / kappa off |Phi| (never reversing it). A rebound e a above
rebound_stop Omega x starts a flight; a slower one ends the bouncing: plastic. The
rebounds fall by about e per impact, so that takes log(rebound_stop) / log(e) impacts
(8 for e = 0.43 and the default 1e-3). With e = 0 and no impact friction (the
defaults) a re-catch is plastic and frictionless, the model before restitution.

Events end a phase: the centre reaches the rim (|c| = R) or the contact point the vane
tip, x' = 0 (exact: ratio of exponentials), N = 0, slip = 0, the friction limit while
sticking, the inner end of the vane while moving inwards, landing on the disc (a
granule caught while still falling has no disc friction before that). Each event function has the
form  b0 + b1 t + g1 expm1(l1 t) + g2 expm1(l2 t); its first root is found exactly up
to rounding (`roots`).

Static checks (x' = 0, or stopped at the inner end): the granule stays (RETAINED_STUCK)
when the outward pull cannot beat static disc friction,
    Omega^2 x - sgn(slip) mu_v N <= mu_d g,   N = -Omega^2 w,
where the vane term is the kinetic friction of a contact point that still slips (a
locked granule always slips inwards there, slip = -r Omega, so the vane pushes it out).
Otherwise it starts outwards from rest. (With w > 0 the face does not press on a granule
at rest: the pull is then Omega^2 |c|, and if it wins the granule leaves in a flight.)
When N falls to 0 in a contact phase (only a granule that disc friction is slowing
down), the face lets go; it is then taken to stop on the disc beside the face at once
(its remaining x' = Omega w / 2 is dropped) and the static check decides.

Approximations (everything else is exact): disc friction during flights off the face
is neglected (flight_drag False) or first order (True: the drag direction is that of
the velocity relative to the disc along the straight line); it is neglected after the
vane tip; bouncing ends below rebound_stop; the separation at N = 0 above; a granule
that slides inwards past the inner end of the vane is stopped there (a hub); spin
friction at the disc contact (drilling) and rolling on the disc are ignored (spin only
about the vertical axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from spreadgym.physics.analytic.motions import Face
from spreadgym.physics.analytic.vane_phases import PhaseMachine
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR

# A rebound off the face slower than this fraction of the face's own speed there (Omega x)
# ends the bouncing: the impact is then taken as plastic (see run_along_vane).
REBOUND_STOP = 1e-3


@dataclass(frozen=True)
class CatchState:
    """Each granule just after (or, with an impact, just before) the catch; broadcasts to (n,).

    x0, v0: position and velocity along the face (x = c.u); granule_radius (m);
    spin_offset0: Phi at the catch (default -r Omega: no spin in the machine frame);
    approach_speed0: speed towards the face just before the catch (relative, normal to
    the face, >= 0): with it the catch is an impact (module docstring) and v0,
    spin_offset0 are the values just before it; default 0: v0 is kept, as in a plastic
    frictionless catch. disc_contact_from_s: time after the catch from which the
    granule lies on the disc (a granule caught while still falling feels no disc
    friction before it lands). time_limit_s: time budget from the catch.
    """

    x0: object
    v0: object
    granule_radius: object
    spin_offset0: object = None
    approach_speed0: object = 0.0
    disc_contact_from_s: object = 0.0
    time_limit_s: object = 3.0


@dataclass(frozen=True)
class FaceFriction:
    """Vane friction mu_v, disc friction mu_d, the restitution e of impacts on the face and
    the vane's rolling resistance mu_r (a torque mu_r r N against the spin relative to the vane)."""

    mu_v: object
    mu_d: object
    restitution: object = 0.0
    mu_r: object = 0.0


@dataclass(frozen=True)
class VaneOptions:
    """How the run is modelled. rotation "free" or "locked"; kappa = I / (m r^2).

    impact_friction: Coulomb friction impulse at impacts; rebound_stop: a rebound slower
    than rebound_stop * Omega * x ends the bouncing (that impact is taken as plastic);
    flight_drag: disc friction during flights off the face, to first order (tip flights
    stay straight). The defaults (no impact friction, no drag in flight) with e = 0 are
    the model before restitution: a plastic, frictionless re-catch after a hop.
    """

    rotation: str = "free"
    kappa: float = SPHERE_INERTIA_FACTOR
    g: float = GRAVITY_M_S2
    max_rounds: int = 200
    impact_friction: bool = False
    rebound_stop: float = REBOUND_STOP
    flight_drag: bool = False


@dataclass
class VaneRun:
    """Result of `run_along_vane` (arrays of length n, SI units).

    Positions and velocities are (u, n) components in the axes of the disc at the
    final time `t_s` (time since the catch): `pos_u`, `pos_n` of the granule centre
    and `vel_u`, `vel_n` of its velocity in the machine (inertial) frame.
    `spin_offset` is Phi = sgn(omega) r (spin - omega); the inertial spin is
    omega + sgn(omega) Phi / r.
    """

    outcome: np.ndarray
    t_s: np.ndarray
    pos_u: np.ndarray
    pos_n: np.ndarray
    vel_u: np.ndarray
    vel_n: np.ndarray
    spin_offset: np.ndarray
    hops: np.ndarray  # flights off the face (N < 0, not rebounds) that ended in a re-catch
    bounces: np.ndarray  # rebounds off the face (impacts with e v_n above the stop threshold)
    flight_stops: np.ndarray  # times disc drag brought a flight to rest on the disc
    separations: np.ndarray  # times N reached 0 (or was negative at a catch)
    stuck_at_hub: np.ndarray  # stopped at the inner end while sliding inwards
    stick_time_s: np.ndarray  # time spent without slip at the face (rolling, free)
    stick_breaks: np.ndarray  # times the friction limit ended a no-slip phase
    left_at_tip: np.ndarray  # left the vane at its tip before the centre reached R
    min_normal_force: np.ndarray  # smallest N met during contact phases (per unit mass)
    rounds: int = 0
    notes: list = field(default_factory=list)


def run_along_vane(face: Face, start: CatchState, friction: FaceFriction,
                   options: VaneOptions = VaneOptions()) -> VaneRun:
    """Follow granules caught on a vane's leading face until they leave the disc.

    Element-wise over granules: every array of `face`, `start` and `friction`
    broadcasts to shape (n,).
    """
    if options.rotation not in ("free", "locked"):
        raise ValueError(f"rotation must be 'free' or 'locked', got {options.rotation!r}")
    state, tally, rounds, notes = PhaseMachine(face, start, friction, options).run()
    return VaneRun(
        outcome=tally.outcome, t_s=state.t, pos_u=tally.pu, pos_n=tally.pn, vel_u=tally.vu, vel_n=tally.vn,
        spin_offset=state.Phi, hops=tally.hops, bounces=tally.bounces, flight_stops=tally.stops,
        separations=tally.seps, stuck_at_hub=tally.hub, stick_time_s=tally.stick_time, stick_breaks=tally.breaks,
        left_at_tip=tally.at_tip, min_normal_force=tally.min_N, rounds=rounds, notes=notes,
    )
