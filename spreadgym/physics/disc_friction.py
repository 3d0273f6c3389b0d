"""Coulomb drag of the disc on the granules that touch it (vectorised).

The force opposes the velocity relative to the disc surface, v - omega x r. Within
one step it never reverses that relative velocity: the velocity change is the
smaller of mu * J_n (the Coulomb limit on the step's normal impulse per unit mass)
and |v_rel| itself, so a slow granule sticks instead of chattering.
"""

from __future__ import annotations

import numpy as np


def disc_surface_velocity(position_m: np.ndarray, omega_rad_s: float) -> np.ndarray:
    """Velocity (N, 2) of the disc surface under each position: omega z x r."""
    return omega_rad_s * np.stack([-position_m[:, 1], position_m[:, 0]], axis=1)


def friction_velocity_change(
    position_m: np.ndarray,
    velocity_m_s: np.ndarray,
    omega_rad_s: float,
    friction: float,
    normal_impulse_per_mass: np.ndarray,
    limit_to_sticking: bool = True,
) -> np.ndarray:
    """Velocity change (N, 2) the disc's friction gives each granule over one step.

    `limit_to_sticking=False` applies the full Coulomb impulse even when it exceeds
    the relative velocity: the unguarded form, kept to show its chatter in tests.
    """
    relative = velocity_m_s - disc_surface_velocity(position_m, omega_rad_s)
    speed = np.hypot(relative[:, 0], relative[:, 1])
    coulomb = friction * normal_impulse_per_mass
    change = np.minimum(coulomb, speed) if limit_to_sticking else coulomb
    scale = np.divide(change, speed, out=np.zeros_like(speed), where=speed > 0.0)
    return -relative * scale[:, None]
