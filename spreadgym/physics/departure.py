"""What every spinner model returns: the state of each granule as it leaves the disc."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

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
        gone = self.departed
        pos, vel = self.position_m[gone], self.velocity_m_s[gone]
        radial_dir = pos / np.hypot(pos[:, 0], pos[:, 1])[:, None]
        tangent_dir = np.copysign(1.0, omega_rad_s) * np.stack([-radial_dir[:, 1], radial_dir[:, 0]], axis=1)
        return np.sum(vel * radial_dir, axis=1), np.sum(vel * tangent_dir, axis=1)

    def outcome_counts(self) -> dict[str, int]:
        return {name: int(np.sum(self.outcome == code)) for code, name in enumerate(OUTCOMES)}


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
