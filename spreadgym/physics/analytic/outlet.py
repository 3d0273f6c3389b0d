"""Closed forms of a granule's outlet direction on a flat disc with straight radial vanes.

Plan view, frame turning with the disc at Omega; x is the distance along the vane, the
outlet angle is measured from the tangent: tan(theta) = x' / (Omega x) at the rim.

Far out along the vane (feed radius / disc radius -> 0; drag of the disc and the vane's
thickness neglected) the motion is x ~ exp(lambda t) and tan(theta) -> t = lambda / Omega:
  * sliding with friction mu (the classic point mass):  t_s(mu) = sqrt(1 + mu^2) - mu;
  * rolling (no slip at the vane) with rolling resistance mu_r, a sphere of I = kappa m r^2:
    (1 + kappa) t^2 + 2 mu_r t - 1 = 0,  t_r(mu_r) = (sqrt(mu_r^2 + 1 + kappa) - mu_r) / (1 + kappa),
    which needs the friction f = kappa x'' + mu_r N to stay within mu_v N (N = 2 Omega x'):
    the granule rolls iff mu_v >= mu_star(mu_r) = kappa t_r / 2 + mu_r, and slides otherwise.
At mu_v = mu_star the two angles agree (t_s(mu_star) = t_r(mu_r)), so the outlet angle is
the sliding angle of one coefficient,

    EFC(mu_v, mu_r) = min(mu_v, mu_star(mu_r)),

the "equivalent friction coefficient" a sliding model infers from the angle (Villette et
al. 2010). A free sphere shows at least mu_star(0) = kappa / (2 sqrt(1 + kappa)) (0.169 for
kappa = 2/5): a smaller EFC says the granule slides and is its sliding friction. An EFC
above it fixes mu_r (given mu_v >= EFC), or mu_v (given mu_r >= mu_star^-1(EFC)).

`point_slider_outlet_angle_deg` is the finite-disc form of the sliding point (the model
such EFCs are inverted through): x'' + 2 mu Omega x' - Omega^2 x = -mu g, from rest at r0.
"""

from __future__ import annotations

import math

from spreadgym.physics.analytic.motions import LinearMotion, slide_coefficients
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR


def sliding_tangent(mu: float) -> float:
    """t_s = tan(theta) of a sliding point far out along a radial vane."""
    return math.sqrt(1.0 + mu * mu) - mu


def rolling_tangent(mu_r: float, kappa: float = SPHERE_INERTIA_FACTOR) -> float:
    """t_r = tan(theta) of a sphere rolling with rolling resistance mu_r far out along a radial vane."""
    return (math.sqrt(mu_r * mu_r + 1.0 + kappa) - mu_r) / (1.0 + kappa)


def rolling_friction_limit(mu_r: float, kappa: float = SPHERE_INERTIA_FACTOR) -> float:
    """mu_star: the least vane friction that holds the roll; also the EFC of that roll."""
    return 0.5 * kappa * rolling_tangent(mu_r, kappa) + mu_r


def equivalent_friction(mu_v: float, mu_r: float, kappa: float = SPHERE_INERTIA_FACTOR) -> float:
    """The sliding coefficient whose outlet angle the granule shows far out: min(mu_v, mu_star(mu_r))."""
    return min(mu_v, rolling_friction_limit(mu_r, kappa))


def outlet_angle_deg(mu_v: float, mu_r: float, kappa: float = SPHERE_INERTIA_FACTOR) -> float:
    """Asymptotic outlet angle (deg from the tangent) of a free sphere (vane friction mu_v,
    rolling resistance mu_r); `kappa` = inf gives the locked point mass (sliding at mu_v)."""
    efc = mu_v if math.isinf(kappa) else equivalent_friction(mu_v, mu_r, kappa)
    return math.degrees(math.atan(sliding_tangent(efc)))


def rolling_resistance_for(efc: float, kappa: float = SPHERE_INERTIA_FACTOR) -> float | None:
    """The mu_r whose roll shows the equivalent friction `efc` (with mu_v >= efc), or None
    when no mu_r >= 0 does: efc below mu_star(0), a granule that must slide."""
    if efc < rolling_friction_limit(0.0, kappa):
        return None
    t = sliding_tangent(efc)
    return (1.0 - (1.0 + kappa) * t * t) / (2.0 * t)


def point_slider_outlet_angle_deg(mu: float, omega_abs: float, feed_radius_m: float, disc_radius_m: float,
                                  disc_friction: float | None = None, g: float = GRAVITY_M_S2) -> float:
    """Outlet angle (deg from the tangent) of a point sliding along a radial vane from rest
    at `feed_radius_m` to the rim: vane friction mu, disc friction mu (or `disc_friction`)."""
    mu_d = mu if disc_friction is None else disc_friction
    motion = LinearMotion.solve(*slide_coefficients(omega_abs, mu, mu_d, 0.0, g=g), feed_radius_m, 0.0)
    t = motion.time_to_reach(disc_radius_m)
    return math.degrees(math.atan(float(motion.v(t)) / (omega_abs * disc_radius_m)))
