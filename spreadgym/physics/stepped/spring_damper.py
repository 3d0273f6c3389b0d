"""The `spring-damper` spinner model: the seed paper's contact law for the vanes, in plan view.

The contact law (linear spring-dashpot normal force, Coulomb friction as an impulse
capped at sticking) is in `vane_contact`; this module steps it with the rest of the
pymunk model's physics.

Integration: semi-implicit (symplectic) Euler for all granules at once with numpy, in
the inertial frame (the vanes are turned to the spinner angle omega t every step and
their surface moves at omega z x r):

    v_{n+1} = v_n + dt a(x_n, v_n),    x_{n+1} = x_n + dt v_{n+1}.

The dashpot sees the velocity at the start of the step. For m x'' + c x' + k x = 0
this scheme is stable exactly for dt < (2 / omega_n)(sqrt(1 + zeta^2) - zeta) (the
amplification matrix has det 1 - 2 zeta omega_n dt and trace 2 - (omega_n dt)^2 -
2 zeta omega_n dt), which is `calibration.critical_time_step`. Its error is first
order in dt and depends on where in a step the contact begins (the entry phase).
For the paper's pair (e = 0.43), over all entry phases, the rebound ratio is off by
-5.8 ... +3.6 % (mean -1.7 %) at t_c / 20, -3.7 ... +2.3 % at t_c / 30 and
-2.2 ... +1.3 % (mean -0.7 %) at t_c / 50; the contact time by -2.1, -1.4 and -0.8 %.
The default step is therefore t_c / 50, the end of DEM practice's t_c/20 ... t_c/50
range (e = 0.351, compound on steel: -3.3 ... +1.1 %, mean -1.2 %, at t_c / 50).

Everything else is the `pymunk` model's: the exact drop/bounce of `vertical.py` (a
granule meets the vanes only below the vane tops, and the free fall above them is
solved in closed form), the disc's guarded Coulomb drag `friction_velocity_change`,
the vane geometry of `geometry.py`, the phase trick (every granule is run with the
spinner starting at angle 0 and turned back afterwards), the departure interpolated to
r = R and the outcome codes. One addition: a granule whose plan-view circle overlaps
a vane when it first gets below the vane tops (it came down on a vane's top edge, or
was released on one: about 10 % of the paper scene's granules) is put beside the
nearer face at once. Left overlapping, the spring would fire it out at up to
omega_n x overlap (~40 m/s); pymunk removes such overlaps gently by position correction.
"""


from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError
from spreadgym.physics.calibration import damping_ratio, spring_dashpot
from spreadgym.physics.constants import GRAVITY_M_S2
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import Departure
from spreadgym.physics.disc_friction import friction_velocity_change
from spreadgym.physics.geometry import machine_frame_tracks
from spreadgym.physics.granules import GranuleBatch
from spreadgym.physics.numerics import OMEGA_DT_MAX, TUNNEL_SAFETY, tunnelling_limit_s
from spreadgym.physics.stepped.finish import (
    MAX_SPINNER_TIME_S,
    DepartureRecord,
    Kinematics,
    held_by_disc,
    start_at_vane_tops,
)
from spreadgym.physics.stepped.vane_contact import (
    ContactStep,
    GranuleContactData,
    VaneContactLaw,
    contact_time_s,
    explicit_critical_step_s,
    push_out_of_vanes,
    vane_contact_change,
    vane_pair,
    vane_restitution,
    vanes_can_share_a_granule,
)
from spreadgym.physics.vertical import VerticalState

CONTACT_STEPS = 50  # default step: t_c / CONTACT_STEPS (see the module docstring)
CRITICAL_SAFETY = 0.5  # default step at most this fraction of the explicit stability limit
TRACK_SPACING_S = 1e-4  # recorded paths keep one point per this much time


@dataclass(frozen=True)
class SpringDamperStep:
    dt_s: float
    critical_s: float  # explicit stability limit of the contact
    contact_time_s: float
    tunnel_limit_s: float
    reason: str


def choose_spring_damper_step(
    scene: Scene,
    contacts: Contacts,
    min_granule_radius_m: float,
    dt_s: Optional[float] = None,
    unchecked: bool = False,
) -> SpringDamperStep:
    """The time step of the spring-damper model for this scene.

    A hand-set step (`dt_s`, else the scene's `sim.dt_s`) is refused with a ConfigError
    naming `sim.dt_s` when it is beyond the explicit critical step of the contact or the
    no-tunnelling limit; `unchecked=True` lets it through (stability map and tests only).
    Otherwise the step is the smallest of t_c / CONTACT_STEPS, CRITICAL_SAFETY x the
    critical step, and the pymunk model's tunnelling and slide-accuracy limits.
    """
    e = vane_restitution(scene, contacts)
    t_c = contact_time_s(scene, contacts)
    critical = explicit_critical_step_s(e, t_c)
    tunnel = tunnelling_limit_s(scene, min_granule_radius_m)
    hand = dt_s if dt_s is not None else scene.sim.dt_s
    if hand is not None:
        hand = float(hand)
        if not (math.isfinite(hand) and hand > 0.0):
            raise ConfigError("sim.dt_s", f"must be a positive number of seconds, got {hand}")
        if not unchecked and hand > critical:
            raise ConfigError(
                "sim.dt_s",
                f"{hand:.3g} s is beyond the explicit stability limit of the spring-damper "
                f"contact of {vane_pair(scene)}: (2/omega_n)(sqrt(1+zeta^2)-zeta) = {critical:.3g} s "
                f"(e = {e:g}, contact time {t_c:.3g} s); the contact would gain energy and blow "
                f"up. Use a step below {critical:.3g} s (default {t_c / CONTACT_STEPS:.3g} s) or "
                "leave sim.dt_s null",
            )
        if not unchecked and hand > tunnel:
            raise ConfigError(
                "sim.dt_s",
                f"{hand:.3g} s would let granules pass through the vanes: the no-tunnelling "
                f"limit of this scene is {tunnel:.3g} s; use a smaller step or leave sim.dt_s null",
            )
        steps = t_c / hand
        reason = f"set by hand ({steps:.1f} steps per contact, {hand / critical:.2f} x the critical step)"
        return SpringDamperStep(hand, critical, t_c, tunnel, reason)
    options = [
        (t_c / CONTACT_STEPS, f"contact time / {CONTACT_STEPS} ({t_c:.3g} s / {CONTACT_STEPS})"),
        (CRITICAL_SAFETY * critical, f"{CRITICAL_SAFETY:g} x critical step {critical:.3g} s"),
        (TUNNEL_SAFETY * tunnel, f"{TUNNEL_SAFETY:g} x no-tunnelling limit {tunnel:.3g} s"),
        (OMEGA_DT_MAX / abs(scene.spinner.omega_rad_s), f"|omega| dt = {OMEGA_DT_MAX:g} (slide accuracy)"),
    ]
    dt, reason = min(options, key=lambda option: option[0])
    return SpringDamperStep(dt, critical, t_c, tunnel, reason)


def impact_rebound(
    stiffness_n_per_m: float,
    damping_ns_per_m: float,
    mass_kg: float,
    dt_s: float,
    entry_fraction=0.5,
    speed_m_s: float = 1.0,
    max_steps: int = 1_000_000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normal impacts on a fixed wall with this model's scheme (1-D, no gravity).

    The granule approaches at `speed_m_s` and is first found overlapping the wall by
    `entry_fraction` of one step's travel (the phase of the step grid at entry; an
    array gives one impact per value). The force is the model's: k delta - c v_n,
    tension allowed, semi-implicit Euler with the dashpot on the start-of-step velocity.
    Returns arrays: rebound ratio v_out / v_in, contact duration (s, entry and exit
    interpolated within their steps), and the largest energy (kinetic + spring) during
    the contact over the initial kinetic energy. A contact whose energy grew 1e12-fold
    is stopped there and reports its current speed ratio: never NaN.
    """
    alpha = np.atleast_1d(np.asarray(entry_fraction, dtype=float))
    kn, cn = stiffness_n_per_m / mass_kg, damping_ns_per_m / mass_kg
    x = alpha * speed_m_s * dt_s  # overlap at the first step in contact
    v = np.full(alpha.shape, float(speed_m_s))  # velocity into the wall
    t_enter = (1.0 - alpha) * dt_s
    t_exit = np.zeros_like(alpha)
    ratio = np.zeros_like(alpha)
    peak = np.ones_like(alpha)
    energy0 = 0.5 * speed_m_s * speed_m_s
    going = np.ones(alpha.shape, dtype=bool)
    t = dt_s
    for _ in range(max_steps):
        v_new = v + dt_s * (-kn * x - cn * v)
        x_new = x + dt_s * v_new
        energy = (0.5 * v_new * v_new + 0.5 * kn * np.maximum(x_new, 0.0) ** 2) / energy0
        peak = np.where(going, np.maximum(peak, energy), peak)
        out = going & (x_new <= 0.0)
        if out.any():
            t_exit[out] = t + dt_s * x[out] / (x[out] - x_new[out])
            ratio[out] = -v_new[out] / speed_m_s
        blown = going & ~out & (energy > 1e12)
        if blown.any():
            t_exit[blown] = t + dt_s
            ratio[blown] = np.abs(v_new[blown]) / speed_m_s
        going &= ~(out | blown)
        if not going.any():
            break
        x, v, t = x_new, v_new, t + dt_s
    return ratio, t_exit - t_enter, peak


# --- the model ---------------------------------------------------------------------------


def _vertical_rows(vertical: VerticalState, rows: np.ndarray) -> VerticalState:
    """A VerticalState holding only `rows` of another (same restitution and step)."""
    part = VerticalState(0.0, rows.size, vertical.restitution, vertical.dt)
    part.z, part.vz, part.resting = vertical.z[rows], vertical.vz[rows], vertical.resting[rows]
    return part


def simulate_spring_damper(
    scene: Scene,
    granules: GranuleBatch,
    contacts: Contacts,
    progress: Optional[Callable[[float], None]] = None,
    disc_friction_guard: bool = True,
    track_count: int = 0,
    dt_s: Optional[float] = None,
    *,
    unchecked: bool = False,
) -> Departure:
    """Run every granule from release to the disc edge; return their departure states.

    Same arguments and result as `simulate_pymunk`; `dt_s` overrides `sim.dt_s` (both
    checked against the stability and tunnelling limits unless `unchecked`, which only
    the stability map and the tests use). `track_count` granules (the first ones) also
    have their paths recorded (one point per TRACK_SPACING_S) for plots.
    """
    omega = scene.spinner.omega_rad_s
    radius = scene.spinner.radius_m
    choice = choose_spring_damper_step(scene, contacts, float(granules.radius_m.min()), dt_s, unchecked)
    dt = choice.dt_s
    law = VaneContactLaw.for_scene(scene, contacts)
    shared = vanes_can_share_a_granule(law, float(granules.radius_m.max()))
    n = granules.count
    rows = GranuleContactData.build(granules.radius_m, law.half_thickness_m, scene.granule.rotation == "locked")

    # The run starts at the vane tops (see finish.py).
    vane_top = scene.vanes.height_m
    first = start_at_vane_tops(scene, granules)
    start = first.position_m
    vertical = VerticalState(first.height_m, n, contacts.disc_restitution, dt, first.vz_m_s)
    # Granules found below the vane tops for the first time are put beside a vane they
    # overlap (see push_out_of_vanes); that includes those released below them.
    was_below = np.zeros(n, dtype=bool)

    record = DepartureRecord(first)  # results per granule (global index)
    # The working set: granules `idx` still on the disc, positions and velocities as
    # (2, rows). Finished rows stay, masked by `live`, until enough are dropped at once.
    idx = np.arange(n)
    x, v, s = np.ascontiguousarray(start.T), np.zeros((2, n)), np.zeros(n)
    x_prev, v_prev, s_prev = x, v, s
    live = np.ones(n, dtype=bool)
    n_live = n
    r2_disc = radius * radius
    stuck_accel = contacts.disc_friction * GRAVITY_M_S2
    r_stuck2 = (stuck_accel / (omega * omega)) ** 2  # static disc friction can hold granules inside

    def finish(mask, position, velocity, spin):
        """Store the last state of granules that leave the working set retained."""
        record.keep(idx[mask], Kinematics(position.T, velocity.T, spin), vertical.z[mask], vertical.vz[mask])

    steps = int(math.ceil(MAX_SPINNER_TIME_S / dt))
    tracked = np.arange(min(track_count, n))
    track_stride = max(1, int(round(TRACK_SPACING_S / dt)))
    track_points = []
    deepest, pushed_out = 0.0, 0
    t = 0.0
    for step in range(steps + 1):
        t = step * dt
        r2 = x[0] * x[0]
        r2 += x[1] * x[1]
        # Departure: the centre crossed the disc radius during the last step.
        leaving = r2 >= r2_disc
        leaving &= live
        finished = None
        if leaving.any():
            li = idx[leaving]
            frac = record.depart(li, Kinematics(x_prev[:, leaving].T, v_prev[:, leaving].T, s_prev[leaving]),
                                 Kinematics(x[:, leaving].T, v[:, leaving].T, s[leaving]), radius, t, dt)
            record.height_m[li], record.vz_m_s[li] = vertical.at_fraction(np.flatnonzero(leaving), frac)
            finished = leaving
        # Stuck (see finish.held_by_disc); only granules inside the radius where static
        # disc friction can hold them are checked.
        slow = r2 < r_stuck2
        slow &= live
        if slow.any():
            slow &= vertical.resting
            slow[slow] = held_by_disc(x[:, slow].T, v[:, slow].T, omega, stuck_accel, dt)
            if slow.any():
                record.stuck(idx[slow])
                finish(slow, x[:, slow], v[:, slow], s[slow])
                finished = slow if finished is None else finished | slow
        if finished is not None:
            live &= ~finished
            n_live = int(np.count_nonzero(live))
        if tracked.size and step % track_stride == 0:
            point = np.full((tracked.size, 2), np.nan)
            on_disc = live & (idx < tracked.size)
            point[idx[on_disc]] = x[:, on_disc].T
            track_points.append(point)
        if n_live == 0 or step == steps:
            break
        if n_live < 0.8 * idx.size:  # drop finished granules from the working set
            keep = np.flatnonzero(live)
            idx, x, v, s, rows = idx[keep], x[:, keep], v[:, keep], s[keep], rows.take(keep)
            vertical = _vertical_rows(vertical, keep)
            was_below = was_below[keep]
            live = np.ones(idx.size, dtype=bool)

        normal_impulse = vertical.step()
        if normal_impulse.any():
            dv_disc = friction_velocity_change(x.T, v.T, omega, contacts.disc_friction, normal_impulse,
                                               disc_friction_guard).T
        else:
            dv_disc = np.zeros_like(v)
        below = vertical.z < vane_top
        entering = below & ~was_below
        if entering.any():
            moved = push_out_of_vanes(law, omega * t, x[:, entering], rows.take(entering))
            pushed_out += int(np.count_nonzero(np.any(moved != x[:, entering], axis=0) & live[entering]))
            x = x.copy()
            x[:, entering] = moved
        was_below = below
        dv_vane, dspin, depth = vane_contact_change(law, ContactStep(omega * t, omega, below, dv_disc, dt), x, v, s,
                                                    rows, shared)
        deepest = max(deepest, depth)
        x_prev, v_prev, s_prev = x, v, s
        v = v + dv_disc
        v += dv_vane
        s = s + dspin
        x = x + dt * v
        if progress is not None:
            progress(t)

    if live.any():  # time limit
        finish(live, x[:, live], v[:, live], s[live])
    tracks = machine_frame_tracks(track_points, record.position_m[tracked], first.spinner_angle_rad[tracked])
    zeta = damping_ratio(contacts.vane_restitution)
    median_mass = float(np.median(granules.mass_kg))
    contact = spring_dashpot(median_mass, contacts.vane_restitution, choice.contact_time_s)
    # Retained granules keep their last state; their time is the end of the run (as in pymunk).
    return record.departure(
        t, "spring-damper", dt,
        [
            f"time step {dt:.3g} s: {choice.reason}; {choice.contact_time_s / dt:.1f} steps per "
            f"vane contact, {dt / choice.critical_s:.2f} x the explicit critical step "
            f"{choice.critical_s:.3g} s",
            f"vane contact {vane_pair(scene)}: linear spring-dashpot, e = {contacts.vane_restitution:g}, "
            f"t_c = {choice.contact_time_s:.3g} s, zeta = {zeta:.3f}; median granule "
            f"{median_mass * 1e6:.1f} mg: k = {contact.stiffness_n_per_m:.4g} N/m, "
            f"c = {contact.damping_ns_per_m:.3g} N s/m; deepest overlap {deepest * 1e6:.1f} um",
            "semi-implicit Euler in the inertial frame; vane friction: Coulomb impulse capped at sticking",
            f"free fall above the vane tops solved exactly ({first.fall_s * 1e3:.1f} ms); {pushed_out} "
            "granules came down on a vane's top edge and were put beside its nearer face",
        ],
        tracks,
    )
