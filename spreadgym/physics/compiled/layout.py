"""Scene and contact numbers packed into flat float arrays for the compiled kernels.

Numba kernels take a few arrays instead of many arguments: `P` holds the scalars
(index names below), `V` one row per vane. All SI units, spinner frame at angle 0.
"""

from __future__ import annotations

import math

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.geometry import vane_segments
from spreadgym.physics.numerics import collision_bias_for

# Indices into P.
OMEGA = 0  # signed spinner angular velocity, rad/s
DISC_RADIUS = 1  # departure when the granule centre reaches it, m
VANE_TOP = 2  # vane height: a granule whose base is at or above it passes over the vanes, m
MU_DISC = 3
E_DISC = 4
MU_VANE = 5
E_VANE = 6
GRAVITY = 7  # m/s^2
STEP = 8  # integration step, s
SETTLE_SPEED = 9  # a rebound off the disc slower than this ends the bouncing, m/s
TIME_LIMIT = 10  # s on the spinner before a granule counts as retained
HALF_THICKNESS = 11  # half the vane thickness, m
INV_KAPPA = 12  # m r^2 / I of a granule: 1/0.4 for a free sphere, 0 for locked rotation
STUCK_SPEED = 13  # m/s: slower than this (and held by static friction) counts as stuck
REBOUND_FLIGHT = 14  # s: a rebound off a vane whose flight would be shorter ends the bouncing
OVERLAP_RATE = 15  # 1/s: the full model's overlap correction, (1 - bias**dt) / dt of its pymunk spaces
MU_ROLL = 16  # rolling resistance at the vanes: torque mu_r r N against the spin relative to the vane
P_SIZE = 17

# Columns of V (one row per vane): inner end p, unit vector u along the vane,
# leading-face normal n (towards the direction of rotation), length of the centre line.
PX, PY, UX, UY, NX, NY, LENGTH = range(7)
V_SIZE = 7

OMEGA_STEP = 0.1
"""|omega| * step. Measured against 0.0125 (4096 granules, events located to 1e-10 of a
step): departure speed within 5e-5 (paper) and 1.5e-4 m/s (field), azimuth within 1e-3
deg, for 90 % of granules; the 1-2 % whose path branches (a bounce more or less) shift
the mean speed by 0.007 / 0.020 m/s (0.07 %). Against 0.05 on the reference family
(16 x 4096 granules, same granules): CV within 0.21 pp, azimuth total variation <= 0.0024,
median time on the spinner within 2e-4; 1.3-1.5x faster (docs/performance.md)."""


def pack_parameters(scene: Scene, contacts: Contacts, resolved_s: float, time_limit_s: float,
                    stuck_speed_m_s: float) -> np.ndarray:
    """The scalar array P of the kernels. `resolved_s`: the shortest bounce (off the disc
    or a vane) that is still followed; shorter ones end the bouncing."""
    omega = scene.spinner.omega_rad_s
    p = np.zeros(P_SIZE)
    p[OMEGA] = omega
    p[DISC_RADIUS] = scene.spinner.radius_m
    p[VANE_TOP] = scene.vanes.height_m
    p[MU_DISC], p[E_DISC] = contacts.disc_friction, contacts.disc_restitution
    p[MU_VANE], p[E_VANE] = contacts.vane_friction, contacts.vane_restitution
    p[MU_ROLL] = contacts.vane_rolling_resistance
    p[GRAVITY] = GRAVITY_M_S2
    p[STEP] = OMEGA_STEP / abs(omega)
    p[SETTLE_SPEED] = 0.5 * GRAVITY_M_S2 * resolved_s
    p[REBOUND_FLIGHT] = resolved_s
    p[OVERLAP_RATE] = (1.0 - collision_bias_for(resolved_s) ** resolved_s) / resolved_s
    p[TIME_LIMIT] = time_limit_s
    p[HALF_THICKNESS] = 0.5 * scene.vanes.thickness_m
    p[INV_KAPPA] = 0.0 if scene.granule.rotation == "locked" else 1.0 / SPHERE_INERTIA_FACTOR
    p[STUCK_SPEED] = stuck_speed_m_s
    return p


def pack_vanes(scene: Scene) -> np.ndarray:
    """The vane array V (K, V_SIZE) from the shared vane geometry."""
    inner, outer = vane_segments(scene)
    along = outer - inner
    length = np.hypot(along[:, 0], along[:, 1])
    u = along / length[:, None]
    sense = math.copysign(1.0, scene.spinner.omega_rad_s)
    n = sense * np.stack([-u[:, 1], u[:, 0]], axis=1)
    return np.ascontiguousarray(np.column_stack([inner, u, n, length]))
