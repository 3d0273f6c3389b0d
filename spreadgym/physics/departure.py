"""What every spinner model returns: the state of each granule as it leaves the disc."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from spreadgym.physics.compiled.options import INLINED, KERNEL

# Outcome codes per granule. Every granule ends with exactly one.
DEPARTED = 0
RETAINED_TIMEOUT = 1  # still on the disc when the time limit ran out
RETAINED_STUCK = 2  # held against the disc (friction beats the centrifugal pull)
OUTCOMES = ("departed", "retained: time limit", "retained: stuck on the disc")


@dataclass
class Departure:
    """Per-granule arrays (length N) in the machine frame, SI units.

    For departed granules the state is interpolated to the moment the centre
    crosses the disc radius R. Retained granules keep their last state (finite),
    and `outcome` says why; use `departed` to select.
    """

    position_m: np.ndarray  # (N, 2)
    velocity_m_s: np.ndarray  # (N, 2) horizontal velocity
    spin_rad_s: np.ndarray  # (N,) spin about the vertical axis
    height_m: np.ndarray  # (N,) height of the granule's base above the disc plane
    vertical_velocity_m_s: np.ndarray  # (N,)
    time_s: np.ndarray  # (N,) time from release to departure
    outcome: np.ndarray  # (N,) int8 codes above
    model: str
    dt_s: float  # time step the model used (0.0 for closed forms)
    notes: list[str] = field(default_factory=list)  # what the model decided and why
    # Paths over the disc (machine frame, (T, 2) each) of the first few granules, for pictures.
    tracks: list[np.ndarray] = field(default_factory=list)

    @property
    def departed(self) -> np.ndarray:
        return self.outcome == DEPARTED

    @property
    def speed_m_s(self) -> np.ndarray:
        return np.hypot(self.velocity_m_s[:, 0], self.velocity_m_s[:, 1])

    def radial_tangential_m_s(self, omega_rad_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Outward radial and tangential (direction of rotation) velocity of the departed granules."""
        return _radial_tangential(self.position_m, self.velocity_m_s, self.departed, math.copysign(1.0, omega_rad_s))

    def means(self, omega_rad_s: float) -> tuple[int, float, float, float, float, float]:
        """(departed count, mean speed, its s.d. (ddof 1; 0 for one granule), mean spin,
        mean angle from the tangent (deg: 0 tangential, 90 radial, `radial_tangential_m_s`),
        mean time on the spinner) over the departed granules, in one compiled pass (NaN
        means where none departed)."""
        return means_of(self.position_m, self.velocity_m_s, self.spin_rad_s, self.time_s, self.departed,
                      math.copysign(1.0, omega_rad_s))

    def outcome_counts(self) -> dict[str, int]:
        counts = np.bincount(self.outcome, minlength=len(OUTCOMES))
        return {name: int(counts[code]) for code, name in enumerate(OUTCOMES)}


def tilted_by_cone(departure: Departure, cone_rad: float) -> Departure:
    """The departures of a disc whose surface rises outward at `cone_rad` (a dished disc):
    each departed granule leaves along the surface, so the outward radial part v_r of its
    rim velocity turns upward by the cone angle (v_r cos a stays horizontal, v_r sin a is
    added to the vertical velocity); the tangential part and the speed are unchanged.

    Assumption: the motion on the disc is that of a flat disc. For a frictionless granule
    on a radial vane of a cone the flat disc's radial rim speed is exactly its speed along
    the surface, up to gravity along the slope (relative error ~ g sin a / (w^2 (R - r0)),
    0.4 % at 10 deg, 500 rpm, R 0.3 m); what it misses is the time on the vane, longer on
    the cone by 1/cos a (1.5 % at 10 deg), which turns the departure azimuth later by that
    share of the angle swept on the vane (tests/physics/test_cone.py).
    A cone of 0 returns `departure` itself.
    """
    if cone_rad == 0.0:
        return departure
    gone = departure.departed
    pos, vel = departure.position_m[gone], departure.velocity_m_s[gone]
    radial_dir = pos / np.hypot(pos[:, 0], pos[:, 1])[:, None]
    v_r = np.sum(vel * radial_dir, axis=1)
    velocity, vertical = departure.velocity_m_s.copy(), departure.vertical_velocity_m_s.copy()
    velocity[gone] = vel - (v_r * (1.0 - np.cos(cone_rad)))[:, None] * radial_dir
    vertical[gone] = vertical[gone] + v_r * np.sin(cone_rad)
    return replace(departure, velocity_m_s=velocity, vertical_velocity_m_s=vertical,
                   notes=[*departure.notes, f"departures tilted up along a {np.degrees(cone_rad):g} deg cone"])


@INLINED
def _radial_tangential_of(px, py, vx, vy, sign):
    """Outward radial and tangential (sign +1: counter-clockwise) parts of (vx, vy) at (px, py)."""
    r = math.hypot(px, py)
    ux, uy = px / r, py / r
    return vx * ux + vy * uy, vx * (sign * -uy) + vy * (sign * ux)


@KERNEL
def _radial_tangential(position, velocity, departed, sign):
    count = 0
    for i in range(departed.size):
        count += departed[i]
    radial, tangential = np.empty(count), np.empty(count)
    k = 0
    for i in range(departed.size):
        if departed[i]:
            radial[k], tangential[k] = _radial_tangential_of(position[i, 0], position[i, 1], velocity[i, 0],
                                                             velocity[i, 1], sign)
            k += 1
    return radial, tangential


@KERNEL
def means_of(position, velocity, spin, time, departed, sign):
    n = 0
    speed = spin_sum = angle = time_sum = 0.0
    for i in range(departed.size):
        if departed[i]:
            n += 1
            speed += math.hypot(velocity[i, 0], velocity[i, 1])
            spin_sum += spin[i]
            radial, tangential = _radial_tangential_of(position[i, 0], position[i, 1], velocity[i, 0],
                                                       velocity[i, 1], sign)
            angle += math.degrees(math.atan2(radial, tangential))
            time_sum += time[i]
    if n == 0:
        return 0, math.nan, math.nan, math.nan, math.nan, math.nan
    mean = speed / n
    spread = 0.0
    for i in range(departed.size):
        if departed[i]:
            spread += (math.hypot(velocity[i, 0], velocity[i, 1]) - mean) ** 2
    return n, mean, math.sqrt(spread / (n - 1)) if n > 1 else 0.0, spin_sum / n, angle / n, time_sum / n
