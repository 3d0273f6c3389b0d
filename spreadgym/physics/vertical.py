"""1-D vertical motion of granules above the disc: the drop from the feed and the bounces.

Plan view leaves height out of pymunk, so each granule carries (z, vz) here: z is the
height of its lowest point above the disc. A granule falls freely, hits the disc,
rebounds with the fertilizer-disc restitution e, and comes to rest once a rebound
would last less than one time step. The disc can drag a granule only while touching
it, and the drag is limited by Coulomb's law on the normal impulse: during a step
the friction impulse per unit mass is at most mu * J_n, where J_n is the normal
impulse per unit mass of that step (g*dt at rest, (1 + e)*v_impact at a bounce).
"""

from __future__ import annotations

import math

import numpy as np

from spreadgym.physics.constants import GRAVITY_M_S2


def free_fall_to(height_m: float, drop_height_m: float) -> tuple[float, float]:
    """Time (s) and vertical velocity (m/s) of a granule dropped from rest at
    `drop_height_m` when it reaches `height_m` (zero time if it starts below)."""
    fall = max(drop_height_m - height_m, 0.0)
    return math.sqrt(2.0 * fall / GRAVITY_M_S2), -math.sqrt(2.0 * GRAVITY_M_S2 * fall)


class VerticalState:
    """Heights and vertical velocities of N granules, advanced exactly step by step."""

    def __init__(
        self, height_m: float, count: int, restitution: float, dt_s: float, vz_m_s: float = 0.0
    ):
        self.z = np.full(count, float(height_m))
        self.vz = np.full(count, float(vz_m_s))
        self.restitution = float(restitution)
        self.dt = float(dt_s)
        self.resting = self.z <= 0.0
        # A rebound slower than this lasts less than one step: the granule settles.
        self._settle_speed = 0.5 * GRAVITY_M_S2 * self.dt

    def step(self) -> np.ndarray:
        """Advance one step; return the normal impulse per unit mass (m/s) of the step."""
        g, dt, e = GRAVITY_M_S2, self.dt, self.restitution
        impulse = np.where(self.resting, g * dt, 0.0)
        flying = ~self.resting
        if not flying.any():
            return impulse
        z, vz = self.z[flying], self.vz[flying]
        z_end = z + vz * dt - 0.5 * g * dt * dt
        hits = z_end <= 0.0
        # Exact time of impact within the step for the granules that reach the disc.
        zh, vh = z[hits], vz[hits]
        t_hit = (vh + np.sqrt(vh * vh + 2.0 * g * zh)) / g
        v_impact = np.sqrt(vh * vh + 2.0 * g * zh)
        v_up = e * v_impact
        t_left = np.maximum(dt - t_hit, 0.0)
        settles = v_up <= self._settle_speed
        z_hit_end = np.where(settles, 0.0, np.maximum(v_up * t_left - 0.5 * g * t_left**2, 0.0))
        vz_hit_end = np.where(settles, 0.0, v_up - g * t_left)

        z_new, vz_new = z_end.copy(), vz - g * dt
        z_new[hits], vz_new[hits] = z_hit_end, vz_hit_end
        fly_impulse = np.zeros(z.shape)
        fly_impulse[hits] = np.where(settles, v_impact + g * t_left, (1.0 + e) * v_impact)
        self.z[flying], self.vz[flying] = z_new, vz_new
        newly_resting = np.zeros(z.shape, dtype=bool)
        newly_resting[hits] = settles
        self.resting[flying] = newly_resting
        impulse[flying] = fly_impulse
        return impulse

    def at_fraction(self, index: np.ndarray, fraction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Height and vertical velocity a fraction of the *last* step back from its end.

        Used to interpolate the departure state; exact for free flight, and exact for
        resting granules (z = vz = 0).
        """
        back = (1.0 - fraction) * self.dt
        vz_end, z_end = self.vz[index], self.z[index]
        vz = vz_end + GRAVITY_M_S2 * back
        z = np.maximum(z_end - vz_end * back - 0.5 * GRAVITY_M_S2 * back**2, 0.0)
        resting = self.resting[index]
        return np.where(resting, 0.0, z), np.where(resting, 0.0, vz)
