"""What every spinner model returns: the state of each granule as it leaves the disc."""

from __future__ import annotations

from dataclasses import dataclass, field

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
