"""The vane contact of the `spring-damper` model, vectorised over granules (plan view).

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
The vane's rolling resistance mu_r follows the friction within the step, as in the
other models: an angular impulse of mu_r r max(F_n, 0) dt against the spin relative to
the vane, capped at stopping it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError, MaterialError
from spreadgym.physics.calibration import damping_ratio, spring_dashpot
from spreadgym.physics.constants import SPHERE_INERTIA_FACTOR
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.geometry import point_segment_distance, vane_segments


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


def vane_pair(scene: Scene) -> str:
    return f"{scene.fertilizer_name}/{scene.vane_material}"


def contact_time_s(scene: Scene, contacts: Contacts) -> float:
    if contacts.vane_contact_time_s is None:
        raise MaterialError(
            f"the spring-damper model needs the vane contact time of the pair {vane_pair(scene)}, "
            "which the material library does not give; the scene can set "
            "contact.vane_contact_time_s (seconds)"
        )
    return float(contacts.vane_contact_time_s)


def vane_restitution(scene: Scene, contacts: Contacts) -> float:
    e = float(contacts.vane_restitution)
    if not 0.0 < e <= 1.0:
        raise ConfigError(
            "contact.vane_restitution",
            f"{e:g} for {vane_pair(scene)}: the spring-damper model needs a restitution in (0, 1] "
            "(e = 0 would need infinite damping)",
        )
    return e


@dataclass(frozen=True)
class VaneContactLaw:
    """Everything the vane contact needs that does not change during a run."""

    stiffness_per_mass: float  # omega_n^2, 1/s^2
    damping_per_mass: float  # 2 zeta omega_n, 1/s
    friction: float  # mu_v
    rolling_resistance: float  # mu_r
    inner_m: np.ndarray  # (K, 2) vane inner ends at spinner angle 0
    direction: np.ndarray  # (K, 2) unit vectors along the vanes
    length_m: np.ndarray  # (K,)
    half_thickness_m: float

    @classmethod
    def for_scene(cls, scene: Scene, contacts: Contacts) -> "VaneContactLaw":
        kn, cn = contact_rates(vane_restitution(scene, contacts), contact_time_s(scene, contacts))
        inner, outer = vane_segments(scene)
        along = outer - inner
        length = np.hypot(along[:, 0], along[:, 1])
        return cls(kn, cn, float(contacts.vane_friction), float(contacts.vane_rolling_resistance), inner,
                   along / length[:, None], length, 0.5 * scene.vanes.thickness_m)

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
            ratio = np.full_like(r, SPHERE_INERTIA_FACTOR / (1.0 + SPHERE_INERTIA_FACTOR))
            gain = 1.0 / (SPHERE_INERTIA_FACTOR * r)
        reach = r + half_thickness_m
        return cls(r, reach, reach * reach, ratio, gain)

    def take(self, rows: np.ndarray) -> "GranuleContactData":
        return GranuleContactData(*(getattr(self, f)[rows] for f in self.__dataclass_fields__))


def _segment_gap(a0, a1, b0, b1) -> float:
    """Distance between two non-crossing plane segments (min over end point distances)."""
    return float(min(point_segment_distance(a0, b0, b1), point_segment_distance(a1, b0, b1),
                     point_segment_distance(b0, a0, a1), point_segment_distance(b1, a0, a1)))


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


@dataclass(frozen=True)
class ContactStep:
    """One step of the vane contact, besides the granules' own state.

    Spinner at `angle_rad`, turning at `omega_rad_s`; `can_touch` (n,) masks the
    granules below the vane tops; `other_dv` (2, n) is the velocity change of the step
    from other forces (disc friction): the friction cap predicts the slip with it.
    """

    angle_rad: float
    omega_rad_s: float
    can_touch: np.ndarray
    other_dv: np.ndarray
    dt_s: float


def vane_contact_change(
    law: VaneContactLaw,
    step: ContactStep,
    position_m: np.ndarray,
    velocity_m_s: np.ndarray,
    spin_rad_s: np.ndarray,
    granule: GranuleContactData,
    shared: bool = True,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Velocity change (2, n), spin change (n,) from the vanes over one step; deepest overlap (m).

    Positions and velocities are (2, n) (x row, y row). `shared=False` promises that no
    granule can touch two vanes at once (`vanes_can_share_a_granule`).
    """
    angle_rad, omega_rad_s, can_touch, other_dv, dt_s = (
        step.angle_rad, step.omega_rad_s, step.can_touch, step.other_dv, step.dt_s)
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
    if law.rolling_resistance > 0.0:  # then the rolling resistance, against the spin relative to the vane
        relative_spin = spin_rad_s[gi] + spin_change - omega_rad_s
        most = (law.rolling_resistance * dt_s) * np.maximum(an, 0.0) * granule.spin_gain[gi]
        spin_change -= np.sign(relative_spin) * np.minimum(most, np.abs(relative_spin))
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
