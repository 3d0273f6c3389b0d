"""Closed-form motions of a granule along a vane face: x'' = A x' + B x + C per phase.

Plan view, in the frame turning with the disc, in the face's (u, n) components (see
`vane_slide` for the derivation): sliding and sticking (rolling without slip) phases
are linear ODEs with constant coefficients; `LinearMotion` is their exact solution,
and its event functions (`roots.EventFunction`) locate the ends of a phase.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spreadgym.physics.analytic.roots import EXP_MAX, EventFunction
from spreadgym.physics.constants import GRAVITY_M_S2, SPHERE_INERTIA_FACTOR


@dataclass(frozen=True)
class Face:
    """The leading face each granule is on: arrays (n,), the face's (u, n) components, SI.

    omega_abs: Omega = |omega| (rad/s); w = c.n of the granule-centre line on the face;
    x_in, x_tip: x = c.u at the inner end and at the tip of the face; disc_radius: the
    granule departs when |c| = R.
    """

    omega_abs: np.ndarray
    w: np.ndarray
    x_in: np.ndarray
    x_tip: np.ndarray
    disc_radius: np.ndarray

    def take(self, idx) -> "Face":
        """The faces of the granules `idx` only."""
        return Face(self.omega_abs[idx], self.w[idx], self.x_in[idx], self.x_tip[idx], self.disc_radius[idx])


def normal_force(omega_abs, v, w):
    """Vane normal force per unit mass on the granule, N = 2 Omega x' - Omega^2 w."""
    om = np.asarray(omega_abs, dtype=float)
    return 2.0 * om * np.asarray(v, dtype=float) - om * om * np.asarray(w, dtype=float)


def slide_coefficients(omega_abs, mu_v, mu_d, w, slip_sign=1.0, motion_sign=1.0, g=GRAVITY_M_S2):
    """(A, B, C) of x'' = A x' + B x + C while sliding on the face.

    slip_sign = sgn(slip) sets the direction of vane friction, motion_sign = sgn(x')
    that of disc friction. With both +1 this is
    x'' + 2 mu_v Omega x' - Omega^2 x = -mu_d g + mu_v Omega^2 w.
    """
    om = np.asarray(omega_abs, dtype=float)
    emu = np.asarray(mu_v, dtype=float) * slip_sign
    A = -2.0 * emu * om
    B = om * om
    C = -motion_sign * np.asarray(mu_d, dtype=float) * g + emu * om * om * np.asarray(w, dtype=float)
    return A, B, C


def stick_coefficients(omega_abs, mu_d, motion_sign=1.0, kappa=SPHERE_INERTIA_FACTOR, g=GRAVITY_M_S2, mu_r=0.0,
                       w=0.0):
    """(A, B, C) while the contact point does not slip (kappa=inf: locked, x'' = 0).

    Rolling with the vane's rolling resistance mu_r (a torque mu_r r N against the spin
    relative to the vane, so against the rolling):
        (1 + kappa) x'' = Omega^2 x - sgn(x') (mu_d g + mu_r N),   N = 2 Omega x' - Omega^2 w.
    """
    om = np.asarray(omega_abs, dtype=float)
    shape = np.broadcast(om, np.asarray(mu_d), np.asarray(motion_sign), np.asarray(kappa), np.asarray(mu_r),
                         np.asarray(w)).shape
    kappa = np.broadcast_to(np.asarray(kappa, dtype=float), shape)
    finite = np.isfinite(kappa)
    scale = np.where(finite, 1.0 / (1.0 + np.where(finite, kappa, 0.0)), 0.0)
    A = np.zeros(shape)
    B = np.broadcast_to(om * om * scale, shape).copy()
    C = np.broadcast_to(-motion_sign * np.asarray(mu_d, dtype=float) * g * scale, shape).copy()
    mu_r = np.broadcast_to(np.asarray(mu_r, dtype=float), shape)
    resisted = mu_r > 0.0  # only there: mu_r = 0 keeps the loss-free roller's coefficients to the bit
    if np.any(resisted):
        rolling = np.broadcast_to(motion_sign * mu_r * scale, shape)
        A = np.where(resisted, -2.0 * rolling * om, A)
        C = np.where(resisted, C + rolling * om * om * np.asarray(w, dtype=float), C)
    return A, B, C


@dataclass(frozen=True)
class LinearMotion:
    """Closed form of x'' = A x' + B x + C from (x0, v0) at t = 0, element-wise.

    B > 0 gives x = p + a1 e^{l1 t} + a2 e^{l2 t} with l1 > 0 > l2; A = B = C = 0 gives
    x = x0 + v0 t (a locked granule sticking to the face). Written as increments
    x(t) - x0 = p1 t + a1 expm1(l1 t) + a2 expm1(l2 t) so that short times stay exact.
    """

    x0: np.ndarray
    v0: np.ndarray
    l1: np.ndarray
    l2: np.ndarray
    a1: np.ndarray
    a2: np.ndarray
    p1: np.ndarray  # constant velocity part (only the degenerate B = 0 case)

    @classmethod
    def solve(cls, A, B, C, x0, v0) -> "LinearMotion":
        A, B, C, x0, v0 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (A, B, C, x0, v0)))
        exp = B > 0.0
        if np.any(~exp & ((A != 0.0) | (C != 0.0))):
            raise ValueError("LinearMotion: B = 0 is supported only with A = C = 0")
        Bs = np.where(exp, B, 1.0)
        disc = np.sqrt(A * A + 4.0 * Bs)
        l1 = np.where(exp, 0.5 * (A + disc), 0.0)
        l2 = np.where(exp, 0.5 * (A - disc), 0.0)
        # l1 - l2 = disc, and -B / l1 avoids cancellation in l2 when A > 0
        l2 = np.where(exp & (A > 0.0), -Bs / np.where(l1 > 0, l1, 1.0), l2)
        l1 = np.where(exp & (A < 0.0), -Bs / np.where(l2 < 0, l2, -1.0), l1)
        p = np.where(exp, -C / Bs, 0.0)
        d = x0 - p
        span = np.where(exp, l1 - l2, 1.0)
        a1 = np.where(exp, (v0 - l2 * d) / span, 0.0)
        a2 = np.where(exp, (l1 * d - v0) / span, 0.0)
        p1 = np.where(exp, 0.0, v0)
        return cls(x0, v0, l1, l2, a1, a2, p1)

    def _e(self, t):
        t = np.asarray(t, dtype=float)
        return (
            np.exp(np.minimum(self.l1 * t, EXP_MAX)),
            np.exp(np.minimum(self.l2 * t, EXP_MAX)),
            np.expm1(np.minimum(self.l1 * t, EXP_MAX)),
            np.expm1(np.minimum(self.l2 * t, EXP_MAX)),
        )

    def dx(self, t):
        """x(t) - x0."""
        _, _, m1, m2 = self._e(t)
        return self.p1 * t + self.a1 * m1 + self.a2 * m2

    def x(self, t):
        return self.x0 + self.dx(t)

    def v(self, t):
        e1, e2, _, _ = self._e(t)
        return self.p1 + self.l1 * self.a1 * e1 + self.l2 * self.a2 * e2

    def dv(self, t):
        """v(t) - v0."""
        _, _, m1, m2 = self._e(t)
        return self.l1 * self.a1 * m1 + self.l2 * self.a2 * m2

    def acceleration(self, t):
        e1, e2, _, _ = self._e(t)
        return self.l1**2 * self.a1 * e1 + self.l2**2 * self.a2 * e2

    def event(self, F0, beta1, kx, kv) -> "EventFunction":
        """F(t) = F0 + beta1 t + kx (x(t) - x0) + kv (v(t) - v0) as an EventFunction."""
        F0, beta1, kx, kv = (np.asarray(a, dtype=float) for a in (F0, beta1, kx, kv))
        return EventFunction(
            F0=F0 + 0.0 * self.x0,
            b1=beta1 + kx * self.p1,
            g1=(kx + kv * self.l1) * self.a1,
            g2=(kx + kv * self.l2) * self.a2,
            l1=self.l1,
            l2=self.l2,
        )

    def time_of_rest(self):
        """Exact first t > 0 with v(t) = 0 (inf if none): e^{(l1-l2) t} = -l2 a2 / (l1 a1)."""
        num = -self.l2 * self.a2
        den = self.l1 * self.a1
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(den != 0.0, num / np.where(den != 0.0, den, 1.0), -1.0)
            ok = (ratio > 1.0) & np.isfinite(ratio)
            span = np.where(self.l1 > self.l2, self.l1 - self.l2, 1.0)
            t = np.where(ok, np.log(np.where(ok, ratio, 1.0)) / span, np.inf)
        return t

    def time_to_reach(self, X, horizon=None, t_min=0.0):
        """First t in (t_min, horizon] where x(t) crosses X in the direction of travel.

        Outwards (X > x0) with growing exponentials: horizon defaults to a safe upper
        bound, t = ln((X - p + |a2|) / a1) / l1, where x(t) >= X is guaranteed.
        """
        X = np.asarray(X, dtype=float)
        out = X >= self.x0
        if horizon is None:
            horizon = self.reach_bound(np.where(out, X, -np.inf), np.where(out, np.inf, X))
        sign = np.where(out, 1.0, -1.0)
        ev = self.event(sign * (self.x0 - X), 0.0, sign, 0.0)
        return ev.first_root(horizon, t_min)

    def reach_bound(self, x_hi, x_lo):
        """Upper bound on the time to reach x_hi (if a1 > 0) or x_lo (if a1 < 0); inf else.

        For t >= 0, x(t) lies within p + a1 e^{l1 t} -+ |a2|, which gives the bound.
        """
        p = self.x0 - self.a1 - self.a2
        l1 = np.where(self.l1 > 0, self.l1, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            up = np.where(self.a1 > 0, (x_hi - p + np.abs(self.a2)) / np.where(self.a1 > 0, self.a1, 1.0), np.nan)
            dn = np.where(self.a1 < 0, (p + np.abs(self.a2) - x_lo) / np.where(self.a1 < 0, -self.a1, 1.0), np.nan)
            arg = np.where(self.a1 > 0, up, dn)
            good = (self.l1 > 0) & np.isfinite(arg)
            t = np.where(good, np.log(np.maximum(np.where(good, arg, 1.0), 1.0)) / l1, np.inf)
        lin = (self.l1 == 0) & (self.p1 != 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            tl = np.where(self.p1 > 0, (x_hi - self.x0) / np.where(lin, self.p1, 1.0),
                          (x_lo - self.x0) / np.where(lin, self.p1, 1.0))
        t = np.where(lin, np.where(np.isfinite(tl) & (tl >= 0), tl, np.inf), t)
        return t * (1.0 + 1e-9) + 1e-15

