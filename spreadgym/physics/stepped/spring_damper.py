"""The `spring-damper` spinner model: the seed paper's contact law for the vanes, in plan view.

Vane contacts are soft: a granule overlapping a vane (a capsule: the centre-line
segment plus half the vane thickness) by delta feels the linear spring-dashpot normal
force of the paper (Eqs. 8-10),

    F_n = k delta - c v_n,        k = pi^2 m / ((1 - zeta^2) t_c^2),  c = 2 zeta sqrt(k m),

with zeta from the pair's restitution e and t_c its measured contact time
(`calibration.spring_dashpot`). v_n is the normal velocity of the granule's contact
point relative to the vane surface (positive when separating). The force may pull
(tension) at the very end of a contact: that is the model whose half damped period
is t_c and whose rebound ratio is exactly e, as in the paper's derivation. k and c
are proportional to the mass, so per unit mass the stiffness omega_n^2 and the
damping 2 zeta omega_n are the same for every granule.

Vane friction is Coulomb's law applied as an impulse capped at sticking: within one
step the tangential velocity change of the contact point is the smaller of
mu_v |F_n| dt / m_eff and what stops the slip (the slip predicted for the end of the
step, disc friction included), m_eff = m / (1 + m r^2 / I). It is exact Coulomb while
sliding, holds a rolling or sticking contact without chatter, adds no stiffness
(so no extra step limit), and cannot reverse the slip. It is the same guard as the
disc friction's (`disc_friction.py`). The friction torque spins a `free` granule
(sphere, I = 2/5 m r^2, spin about z); a `locked` one has I = inf and no spin.

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
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError, MaterialError
from spreadgym.physics.calibration import damping_ratio, spring_dashpot
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, RETAINED_TIMEOUT, Departure
from spreadgym.physics.disc_friction import disc_surface_velocity, friction_velocity_change
from spreadgym.physics.geometry import crossing_fraction, machine_frame_tracks, vane_segments
from spreadgym.physics.granules import GranuleBatch, rotate
from spreadgym.physics.numerics import OMEGA_DT_MAX, TUNNEL_SAFETY, tunnelling_limit_s
from spreadgym.physics.vertical import GRAVITY_M_S2, VerticalState, free_fall_to

CONTACT_STEPS = 50  # default step: t_c / CONTACT_STEPS (see the module docstring)
CRITICAL_SAFETY = 0.5  # default step at most this fraction of the explicit stability limit
MAX_SPINNER_TIME_S = 3.0
STUCK_SPEED_M_S = 1e-4
KAPPA_SPHERE = 0.4  # I / (m r^2) of a solid sphere
TRACK_SPACING_S = 1e-4  # recorded paths keep one point per this much time


# --- contact law and time step ------------------------------------------------------------


def contact_rates(restitution: float, contact_time_s: float) -> tuple[float, float]:
    """(omega_n^2, 2 zeta omega_n) in 1/s^2 and 1/s: the spring and dashpot per unit mass.

    k / m and c / m of `spring_dashpot` for any mass (both scale with m).
    """
    contact = spring_dashpot(1.0, restitution, contact_time_s)
    return contact.stiffness_n_per_m, contact.damping_ns_per_m


def explicit_critical_step_s(restitution: float, contact_time_s: float) -> float:
    """(2 / omega_n)(sqrt(1 + zeta^2) - zeta) for the pair: the largest stable step (s).

    Equals `calibration.critical_time_step(m, k, c)` with k, c from `spring_dashpot`
    for any mass m.
    """
    zeta = damping_ratio(restitution)
    omega_n = math.pi / (contact_time_s * math.sqrt(1.0 - zeta * zeta))
    return (2.0 / omega_n) * (math.sqrt(1.0 + zeta * zeta) - zeta)


@dataclass(frozen=True)
class SpringDamperStep:
    dt_s: float
    critical_s: float  # explicit stability limit of the contact
    contact_time_s: float
    tunnel_limit_s: float
    reason: str


def _vane_pair(scene: Scene) -> str:
    return f"{scene.fertilizer}/{scene.vane_material}"


def _contact_time(scene: Scene, contacts: Contacts) -> float:
    if contacts.vane_contact_time_s is None:
        raise MaterialError(
            f"the spring-damper model needs the vane contact time of the pair {_vane_pair(scene)}, "
            "which the material library does not give; the scene can set "
            "contact.vane_contact_time_s (seconds)"
        )
    return float(contacts.vane_contact_time_s)


def _restitution(scene: Scene, contacts: Contacts) -> float:
    e = float(contacts.vane_restitution)
    if not 0.0 < e <= 1.0:
        raise ConfigError(
            "contact.vane_restitution",
            f"{e:g} for {_vane_pair(scene)}: the spring-damper model needs a restitution in (0, 1] "
            "(e = 0 would need infinite damping)",
        )
    return e


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
    e = _restitution(scene, contacts)
    t_c = _contact_time(scene, contacts)
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
                f"contact of {_vane_pair(scene)}: (2/omega_n)(sqrt(1+zeta^2)-zeta) = {critical:.3g} s "
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


# --- the vane contact, vectorised --------------------------------------------------------


@dataclass(frozen=True)
class VaneContactLaw:
    """Everything the vane contact needs that does not change during a run."""

    stiffness_per_mass: float  # omega_n^2, 1/s^2
    damping_per_mass: float  # 2 zeta omega_n, 1/s
    friction: float  # mu_v
    inner_m: np.ndarray  # (K, 2) vane inner ends at spinner angle 0
    direction: np.ndarray  # (K, 2) unit vectors along the vanes
    length_m: np.ndarray  # (K,)
    half_thickness_m: float

    @classmethod
    def for_scene(cls, scene: Scene, contacts: Contacts) -> "VaneContactLaw":
        kn, cn = contact_rates(_restitution(scene, contacts), _contact_time(scene, contacts))
        inner, outer = vane_segments(scene)
        along = outer - inner
        length = np.hypot(along[:, 0], along[:, 1])
        return cls(kn, cn, float(contacts.vane_friction), inner, along / length[:, None], length,
                   0.5 * scene.vanes.thickness_m)

    inner_complex: np.ndarray = field(init=False, repr=False)  # (K, 1) complex forms of the
    direction_complex: np.ndarray = field(init=False, repr=False)  # vanes: turned in two products
    length_column: np.ndarray = field(init=False, repr=False)  # (K, 1)

    def __post_init__(self):
        object.__setattr__(self, "inner_complex", (self.inner_m[:, 0] + 1j * self.inner_m[:, 1])[:, None])
        object.__setattr__(self, "direction_complex",
                           (self.direction[:, 0] + 1j * self.direction[:, 1])[:, None])
        object.__setattr__(self, "length_column", self.length_m[:, None])

    def at_angle(self, angle_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Inner ends (x, y) and directions (x, y), as (K, 1) columns, at spinner angle `angle_rad`."""
        turn = complex(math.cos(angle_rad), math.sin(angle_rad))
        a = self.inner_complex * turn
        u = self.direction_complex * turn
        return a.real, a.imag, u.real, u.imag


@dataclass
class GranuleContactData:
    """Per-granule constants of the vane contact (rows of the working set)."""

    radius_m: np.ndarray
    reach_m: np.ndarray  # granule radius + half vane thickness
    reach2_m2: np.ndarray
    slip_mass_ratio: np.ndarray  # m_eff / m = kappa / (1 + kappa) (1 when locked)
    spin_gain: np.ndarray  # 1 / (kappa r) (0 when locked): spin change per tangential dv

    @classmethod
    def build(cls, radius_m: np.ndarray, half_thickness_m: float, locked: bool) -> "GranuleContactData":
        r = np.array(radius_m, dtype=float)
        if locked:
            ratio, gain = np.ones_like(r), np.zeros_like(r)
        else:
            ratio = np.full_like(r, KAPPA_SPHERE / (1.0 + KAPPA_SPHERE))
            gain = 1.0 / (KAPPA_SPHERE * r)
        reach = r + half_thickness_m
        return cls(r, reach, reach * reach, ratio, gain)

    def take(self, rows: np.ndarray) -> "GranuleContactData":
        return GranuleContactData(*(getattr(self, f)[rows] for f in self.__dataclass_fields__))


def _segment_gap(a0, a1, b0, b1) -> float:
    """Distance between two non-crossing plane segments (min over end point distances)."""

    def point_to_segment(p, q0, q1):
        d = q1 - q0
        t = np.clip(np.dot(p - q0, d) / max(np.dot(d, d), 1e-300), 0.0, 1.0)
        return float(np.hypot(*(p - q0 - t * d)))

    return min(point_to_segment(a0, b0, b1), point_to_segment(a1, b0, b1),
               point_to_segment(b0, a0, a1), point_to_segment(b1, a0, a1))


def vanes_can_share_a_granule(law: VaneContactLaw, max_radius_m: float) -> bool:
    """True when two vanes come close enough for one granule to touch both."""
    inner, outer = law.inner_m, law.inner_m + law.length_m[:, None] * law.direction
    limit = 2.0 * (max_radius_m + law.half_thickness_m)
    k = inner.shape[0]
    return any(_segment_gap(inner[i], outer[i], inner[j], outer[j]) < limit
               for i in range(k) for j in range(i + 1, k))


def _vane_offsets(law: VaneContactLaw, angle_rad: float, px: np.ndarray, py: np.ndarray):
    """Offsets (dx, dy) (K, n) of each granule centre from the nearest point of each
    vane's centre line, their squares summed (K, n), and the vane directions (K,)."""
    ax, ay, uxc, uyc = law.at_angle(angle_rad)
    rx = px - ax
    ry = py - ay
    along = rx * uxc
    along += ry * uyc
    np.maximum(along, 0.0, out=along)
    np.minimum(along, law.length_column, out=along)
    rx -= along * uxc
    ry -= along * uyc
    d2 = rx * rx
    d2 += ry * ry
    return rx, ry, d2, uxc[:, 0], uyc[:, 0]


def vane_overlap(law: VaneContactLaw, angle_rad: float, position_m: np.ndarray, reach_m: np.ndarray) -> np.ndarray:
    """Signed overlap (n,) of each granule with its nearest vane: reach - distance (m).

    Positive while touching, negative (the gap) otherwise; positions are (2, n).
    """
    _, _, d2, _, _ = _vane_offsets(law, angle_rad, position_m[0], position_m[1])
    return reach_m - np.sqrt(d2.min(axis=0))


def vane_contact_change(
    law: VaneContactLaw,
    angle_rad: float,
    omega_rad_s: float,
    position_m: np.ndarray,
    velocity_m_s: np.ndarray,
    spin_rad_s: np.ndarray,
    granule: GranuleContactData,
    can_touch: np.ndarray,
    other_dv: np.ndarray,
    dt_s: float,
    shared: bool = True,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Velocity change (2, n), spin change (n,) from the vanes over one step; deepest overlap (m).

    Positions, velocities and `other_dv` are (2, n) (x row, y row). Spinner at
    `angle_rad`, turning at `omega_rad_s`. `can_touch` masks the granules below the
    vane tops. `other_dv` is the velocity change of the step from other forces (disc
    friction): the friction cap predicts the slip with it. `shared=False` promises
    that no granule can touch two vanes at once (`vanes_can_share_a_granule`).
    """
    n = position_m.shape[1]
    dv, dspin = np.zeros((2, n)), np.zeros(n)
    dx, dy, d2, ux, uy = _vane_offsets(law, angle_rad, position_m[0], position_m[1])
    touching = d2 < granule.reach2_m2
    touching &= can_touch
    pairs = np.flatnonzero(touching)
    if pairs.size == 0:
        return dv, dspin, 0.0
    vk, gi = np.divmod(pairs, n)
    nx, ny, dist = dx.ravel()[pairs], dy.ravel()[pairs], np.sqrt(d2.ravel()[pairs])
    on_line = dist == 0.0
    if on_line.any():  # centre on the centre line: push along the vane's normal
        nx[on_line], ny[on_line], dist[on_line] = -uy[vk[on_line]], ux[vk[on_line]], 1.0
        nx /= dist
        ny /= dist
        dist[on_line] = 0.0
    else:
        nx /= dist
        ny /= dist
    r = granule.radius_m[gi]
    overlap = granule.reach_m[gi] - dist
    # Contact point on the granule, c - r n; the vane surface there moves at omega z x p.
    px = position_m[0, gi] - r * nx
    py = position_m[1, gi] - r * ny
    # Velocity of the granule's contact point: v + spin z x (-r n) = v - spin r t, t = z x n.
    sr = spin_rad_s[gi] * r
    relx = velocity_m_s[0, gi] + sr * ny + omega_rad_s * py
    rely = velocity_m_s[1, gi] - sr * nx - omega_rad_s * px
    vn = relx * nx + rely * ny
    slip = rely * nx - relx * ny
    # Spring-dashpot per unit mass (tension allowed: the paper's linear model).
    an = law.stiffness_per_mass * overlap - law.damping_per_mass * vn
    # Coulomb friction as an impulse capped at sticking (velocity change along t).
    predicted = slip + other_dv[1, gi] * nx - other_dv[0, gi] * ny
    cap = (law.friction * dt_s) * np.maximum(an, 0.0)
    ft = -predicted * granule.slip_mass_ratio[gi]
    np.clip(ft, -cap, cap, out=ft)
    jn = an * dt_s
    change_x = jn * nx - ft * ny
    change_y = jn * ny + ft * nx
    # Torque (-r n) x (f t) = -r f: spin change -ft / (kappa r).
    spin_change = -ft * granule.spin_gain[gi]
    if shared:
        dv[0] = np.bincount(gi, change_x, minlength=n)
        dv[1] = np.bincount(gi, change_y, minlength=n)
        dspin = np.bincount(gi, spin_change, minlength=n)
    else:
        dv[0, gi], dv[1, gi], dspin[gi] = change_x, change_y, spin_change
    return dv, dspin, float(overlap.max())


def push_out_of_vanes(
    law: VaneContactLaw, angle_rad: float, position_m: np.ndarray, granule: GranuleContactData
) -> np.ndarray:
    """Positions (2, n) moved along the contact normal until they overlap no vane.

    Used when a granule falls below the vane tops while its plan-view circle overlaps
    a vane (it came down on the vane's top edge): it is put beside the nearer face
    instead of being shot out by the compressed spring.
    """
    out = position_m.copy()
    n = out.shape[1]
    for _ in range(3):  # further passes only for a granule wedged between two vanes
        dx, dy, d2, ux, uy = _vane_offsets(law, angle_rad, out[0], out[1])
        pairs = np.flatnonzero(d2 < granule.reach2_m2 * (1.0 - 1e-12))
        if pairs.size == 0:
            break
        vk, gi = np.divmod(pairs, n)
        dist = np.sqrt(d2.ravel()[pairs])
        safe = np.maximum(dist, 1e-300)
        nx = np.where(dist > 0.0, dx.ravel()[pairs] / safe, -uy[vk])
        ny = np.where(dist > 0.0, dy.ravel()[pairs] / safe, ux[vk])
        move = granule.reach_m[gi] - dist
        out[0] += np.bincount(gi, move * nx, minlength=n)
        out[1] += np.bincount(gi, move * ny, minlength=n)
    return out


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


def amplification_per_step(stiffness_n_per_m: float, damping_ns_per_m: float, mass_kg: float,
                           dt_s: float) -> float:
    """Spectral radius of one step of the scheme for a sustained contact (m x'' + c x' + k x = 0).

    Below 1 the contact oscillation decays; above 1 it grows every step (energy grows
    as its square). It crosses 1 exactly at the explicit critical step.
    """
    w2h2 = stiffness_n_per_m / mass_kg * dt_s * dt_s
    ch = damping_ns_per_m / mass_kg * dt_s
    matrix = np.array([[1.0 - w2h2, dt_s * (1.0 - ch)], [-w2h2 / dt_s, 1.0 - ch]])
    return float(np.max(np.abs(np.linalg.eigvals(matrix))))


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

    # Above the vane tops a granule only falls: the run starts when it reaches them,
    # with the spinner turned on by omega * t_fall (the phase trick of granules.py).
    vane_top = scene.vanes.height_m
    t_fall, vz_fall = free_fall_to(vane_top, scene.feed.drop_height_m)
    spinner_angle = granules.phase_rad + omega * t_fall
    start = rotate(granules.release_xy_m, -spinner_angle)
    vertical = VerticalState(min(scene.feed.drop_height_m, vane_top), n, contacts.disc_restitution, dt, vz_fall)
    # Granules found below the vane tops for the first time are put beside a vane they
    # overlap (see push_out_of_vanes); that includes those released below them.
    was_below = np.zeros(n, dtype=bool)

    # Results per granule (global index).
    out_position, out_velocity = start.copy(), np.zeros((n, 2))
    out_spin, out_height, out_vz, out_time = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    outcome = np.full(n, RETAINED_TIMEOUT, dtype=np.int8)
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
        kept = idx[mask]
        out_position[kept], out_velocity[kept], out_spin[kept] = position.T, velocity.T, spin
        out_height[kept], out_vz[kept] = vertical.z[mask], vertical.vz[mask]

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
            frac = crossing_fraction(x_prev[:, leaving].T, x[:, leaving].T, radius)
            out_position[li] = (x_prev[:, leaving] + frac * (x[:, leaving] - x_prev[:, leaving])).T
            out_velocity[li] = (v_prev[:, leaving] + frac * (v[:, leaving] - v_prev[:, leaving])).T
            out_spin[li] = s_prev[leaving] + frac * (s[leaving] - s_prev[leaving])
            out_height[li], out_vz[li] = vertical.at_fraction(np.flatnonzero(leaving), frac)
            out_time[li] = t - (1.0 - frac) * dt
            outcome[li] = DEPARTED
            finished = leaving
        # Stuck (as in the pymunk model): resting, carried along with the disc to within
        # the drift one step of centripetal motion leaves, and the centrifugal pull
        # below what static disc friction holds.
        slow = r2 < r_stuck2
        slow &= live
        if slow.any():
            slow &= vertical.resting
            rel = v.T - disc_surface_velocity(x.T, omega)
            pull = omega * omega * np.sqrt(r2)
            slow &= np.hypot(rel[:, 0], rel[:, 1]) < STUCK_SPEED_M_S + 2.0 * pull * dt
            if slow.any():
                outcome[idx[slow]] = RETAINED_STUCK
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
        dv_vane, dspin, depth = vane_contact_change(law, omega * t, omega, x, v, s, rows, below, dv_disc,
                                                    dt, shared)
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
    # Retained granules keep their last state; their time is the end of the run (as in pymunk).
    out_time[outcome != DEPARTED] = t
    tracks = machine_frame_tracks(track_points, out_position[tracked], spinner_angle[tracked])
    zeta = damping_ratio(contacts.vane_restitution)
    median_mass = float(np.median(granules.mass_kg))
    contact = spring_dashpot(median_mass, contacts.vane_restitution, choice.contact_time_s)
    return Departure(
        position_m=rotate(out_position, spinner_angle),
        velocity_m_s=rotate(out_velocity, spinner_angle),
        spin_rad_s=out_spin,
        height_m=out_height,
        vertical_velocity_m_s=out_vz,
        time_s=out_time + t_fall,
        outcome=outcome,
        model="spring-damper",
        dt_s=dt,
        notes=[
            f"time step {dt:.3g} s: {choice.reason}; {choice.contact_time_s / dt:.1f} steps per "
            f"vane contact, {dt / choice.critical_s:.2f} x the explicit critical step "
            f"{choice.critical_s:.3g} s",
            f"vane contact {_vane_pair(scene)}: linear spring-dashpot, e = {contacts.vane_restitution:g}, "
            f"t_c = {choice.contact_time_s:.3g} s, zeta = {zeta:.3f}; median granule "
            f"{median_mass * 1e6:.1f} mg: k = {contact.stiffness_n_per_m:.4g} N/m, "
            f"c = {contact.damping_ns_per_m:.3g} N s/m; deepest overlap {deepest * 1e6:.1f} um",
            "semi-implicit Euler in the inertial frame; vane friction: Coulomb impulse capped at sticking",
            f"free fall above the vane tops solved exactly ({t_fall * 1e3:.1f} ms); {pushed_out} "
            "granules came down on a vane's top edge and were put beside its nearer face",
        ],
        tracks=tracks,
    )
