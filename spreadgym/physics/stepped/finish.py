"""What the stepped spinner models share: the start at the vane tops, the statuses and
the departure record.

Above the vane tops a granule only falls (nothing touches it), so a run starts when it
reaches them, with the spinner turned on by omega t_fall (the phase trick of
`granules.py`: every granule is run with the spinner at angle 0 at release and turned
back at the end). A granule departs when its centre crosses the disc radius R during a
step; its state is interpolated to the crossing. It is retained stuck when it rests on
the disc, is carried along with it, and static disc friction beats the centrifugal
pull; retained granules keep their last state and the time of the end of the run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, RETAINED_TIMEOUT, Departure
from spreadgym.physics.disc_friction import disc_surface_velocity
from spreadgym.physics.geometry import crossing_fraction
from spreadgym.physics.granules import GranuleBatch, rotate
from spreadgym.physics.vertical import free_fall_to

MAX_SPINNER_TIME_S = 3.0
"""Time limit of a run (s): granules still on the disc then are retained (timeout)."""
STUCK_SPEED_M_S = 1e-4
"""Speed relative to the disc (m/s) below which a resting granule counts as carried along."""


@dataclass(frozen=True)
class VaneTopStart:
    """Where the stepped run of each granule starts: when it reaches the vane tops."""

    fall_s: float  # free fall from the feed to the vane tops (0 if released below them)
    vz_m_s: float  # vertical velocity then
    height_m: float  # height of the granule's base then: min(drop, vane height)
    spinner_angle_rad: np.ndarray  # (N,) spinner angle then, per granule (phase + omega t_fall)
    position_m: np.ndarray  # (N, 2) release points in the frame of the spinner at angle 0


def start_at_vane_tops(scene: Scene, granules: GranuleBatch) -> VaneTopStart:
    """The exact free fall above the vane tops, and the start of the stepped run."""
    vane_top = scene.vanes.height_m
    t_fall, vz_fall = free_fall_to(vane_top, scene.feed.drop_height_m)
    spinner_angle = granules.phase_rad + scene.spinner.omega_rad_s * t_fall
    start = rotate(granules.release_xy_m, -spinner_angle)
    return VaneTopStart(t_fall, vz_fall, min(scene.feed.drop_height_m, vane_top), spinner_angle, start)


def held_by_disc(position_m: np.ndarray, velocity_m_s: np.ndarray, omega_rad_s: float, hold_m_s2: float,
                 dt_s: float) -> np.ndarray:
    """Stuck, for granules resting on the disc: carried along with it (to within the drift
    one step of centripetal motion leaves) and the centrifugal pull below what static disc
    friction holds (`hold_m_s2` = mu_d g). Positions and velocities (k, 2)."""
    r = np.hypot(position_m[:, 0], position_m[:, 1])
    rel = velocity_m_s - disc_surface_velocity(position_m, omega_rad_s)
    pull = omega_rad_s * omega_rad_s * r
    return (np.hypot(rel[:, 0], rel[:, 1]) < STUCK_SPEED_M_S + 2.0 * pull * dt_s) & (pull < hold_m_s2)


@dataclass(frozen=True)
class Kinematics:
    """Plan-view state of some granules: positions, velocities (k, 2) and spins (k,)."""

    position_m: np.ndarray
    velocity_m_s: np.ndarray
    spin_rad_s: np.ndarray


class DepartureRecord:
    """The final state of every granule, filled as they depart or are retained (spinner frame)."""

    def __init__(self, start: VaneTopStart):
        n = start.position_m.shape[0]
        self.start = start
        self.position_m, self.velocity_m_s = start.position_m.copy(), np.zeros((n, 2))
        self.spin_rad_s, self.height_m, self.vz_m_s = np.zeros(n), np.zeros(n), np.zeros(n)
        self.time_s = np.zeros(n)
        self.outcome = np.full(n, RETAINED_TIMEOUT, dtype=np.int8)

    def depart(self, rows: np.ndarray, before: Kinematics, after: Kinematics, radius_m: float,
               step_end_s: float, dt_s: float) -> np.ndarray:
        """Granules `rows` crossed r = R during the step ending at `step_end_s`: record the
        state interpolated to the crossing. Returns the fraction of the step (the caller
        sets the height and vertical velocity there)."""
        frac = crossing_fraction(before.position_m, after.position_m, radius_m)
        self.position_m[rows] = before.position_m + frac[:, None] * (after.position_m - before.position_m)
        self.velocity_m_s[rows] = before.velocity_m_s + frac[:, None] * (after.velocity_m_s - before.velocity_m_s)
        self.spin_rad_s[rows] = before.spin_rad_s + frac * (after.spin_rad_s - before.spin_rad_s)
        self.time_s[rows] = step_end_s - (1.0 - frac) * dt_s
        self.outcome[rows] = DEPARTED
        return frac

    def stuck(self, rows: np.ndarray) -> None:
        self.outcome[rows] = RETAINED_STUCK

    def keep(self, rows: np.ndarray, state: Kinematics, height_m: np.ndarray, vz_m_s: np.ndarray) -> None:
        """Last state of retained granules `rows`."""
        self.position_m[rows], self.velocity_m_s[rows], self.spin_rad_s[rows] = (
            state.position_m, state.velocity_m_s, state.spin_rad_s)
        self.height_m[rows], self.vz_m_s[rows] = height_m, vz_m_s

    def departure(self, end_s: float, model: str, dt_s: float, notes: list, tracks: list) -> Departure:
        """The machine-frame Departure; retained granules get the end of the run as their time."""
        angle = self.start.spinner_angle_rad
        self.time_s[self.outcome != DEPARTED] = end_s
        return Departure(
            position_m=rotate(self.position_m, angle),
            velocity_m_s=rotate(self.velocity_m_s, angle),
            spin_rad_s=self.spin_rad_s,
            height_m=self.height_m,
            vertical_velocity_m_s=self.vz_m_s,
            time_s=self.time_s + self.start.fall_s,
            outcome=self.outcome,
            model=model,
            dt_s=dt_s,
            notes=notes,
            tracks=tracks,
        )
