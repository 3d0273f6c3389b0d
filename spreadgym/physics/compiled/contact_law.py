"""Contact laws shared by the compiled phases (per unit mass, frame turning with the disc).

Forces: centrifugal omega^2 c and Coriolis -2 omega z x v; the disc's Coulomb drag
mu_d g against the velocity relative to the disc (the rotating-frame velocity) while
the granule rests on it; at a vane the normal force and Coulomb friction on the slip
of the contact point. A granule spins about the vertical axis at s (inertial, rad/s);
the vane is fixed in this frame, so its contact point slips at v.t - r (s - omega)
with t = z x n. `inv_kappa` = m r^2 / I (0: locked rotation).
"""

from __future__ import annotations

import math

from spreadgym.physics.compiled.options import INLINED

SPEED_FLOOR_M_S = 1e-12
"""Below this relative speed the disc drag is static (it balances the other forces up to mu_d g)."""


@INLINED
def frame_acceleration(cx, cy, vx, vy, omega):
    """Centrifugal plus Coriolis acceleration (m/s^2) at position c, rotating-frame velocity v."""
    om2 = omega * omega
    return om2 * cx + 2.0 * omega * vy, om2 * cy - 2.0 * omega * vx


@INLINED
def free_acceleration(cx, cy, vx, vy, omega, drag):
    """Acceleration off the vanes; `drag` = mu_d g on the disc, 0 in the air."""
    ax, ay = frame_acceleration(cx, cy, vx, vy, omega)
    if drag > 0.0:
        speed = math.sqrt(vx * vx + vy * vy)
        if speed > SPEED_FLOOR_M_S:
            ax -= drag * vx / speed
            ay -= drag * vy / speed
        else:
            pull = math.sqrt(ax * ax + ay * ay)
            if pull <= drag:
                return 0.0, 0.0
            ax -= drag * ax / pull
            ay -= drag * ay / pull
    return ax, ay


@INLINED
def impact(vx, vy, s, nx, ny, radius, omega, restitution, mu, inv_kappa):
    """Impact on a surface of outward normal n: restitution on the approach speed and a
    Coulomb tangential impulse (at most mu times the normal impulse) that stops the slip
    of the contact point at most. Returns (vx, vy, s, approach speed); no impact if the
    granule does not approach (approach 0)."""
    vn = vx * nx + vy * ny
    if vn >= 0.0:
        return vx, vy, s, 0.0
    approach = -vn
    jn = (1.0 + restitution) * approach
    vx += jn * nx
    vy += jn * ny
    tx, ty = -ny, nx
    slip = vx * tx + vy * ty - radius * (s - omega)
    jt = -slip / (1.0 + inv_kappa)
    limit = mu * jn
    jt = min(max(jt, -limit), limit)
    vx += jt * tx
    vy += jt * ty
    s -= jt * inv_kappa / radius
    return vx, vy, s, approach


@INLINED
def disc_drag_impulse(vx, vy, impulse):
    """Velocity after a disc impact's friction impulse (per mass, mu J_n), never reversing v."""
    speed = math.sqrt(vx * vx + vy * vy)
    if speed <= impulse:
        return 0.0, 0.0
    scale = 1.0 - impulse / speed
    return vx * scale, vy * scale
