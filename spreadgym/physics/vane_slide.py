"""Exact motion of a granule along one straight vane, in the frame turning with the disc.

Plan view. The disc turns at omega (signed about +z); Omega = |omega|. A vane is a
straight plate; `u` is the unit vector along it (outwards) and `n` the unit normal on
its leading side (the face that pushes). The granule's centre sits on the line

    c = x u + w n,    x = c.u (varies),    w = c.n (constant on one face),

with w = p.n + h for a vane whose inner end is p and h = half the vane thickness plus
the granule radius. Every quantity below is written in (u, n) components; in those
components the equations do not depend on the sense of rotation (cw is the mirror
image of ccw), so this module only ever sees Omega > 0.

Forces per unit mass, rotating frame, granule on the leading face:
    centrifugal  Omega^2 c,   Coriolis  -2 omega z x (x' u) = -2 Omega x' n,
    vane normal  N n,   vane friction  f u,   disc friction  -mu_d g sgn(x') u.
The n-component fixes the normal force, and the u-component is the equation of motion:

    N   = 2 Omega x' - Omega^2 w                       (contact holds while N >= 0)
    x'' = Omega^2 x - mu_d g sgn(x') + f.

Spin about the vertical axis. Let phi' be the granule's spin relative to the disc
(inertial spin minus omega) and Phi = sgn(omega) r phi' (a speed). The contact point
of the granule slips along the face at

    slip = x' + Phi,        Phi' = f / kappa,   kappa = I / (m r^2) = 2/5 for a sphere.

Phi = -r Omega is a granule that does not turn in the machine frame (the frame's own
rotation enters the no-slip condition here). A "locked" granule keeps that value
(kappa -> infinity); a "free" granule starts with it (no spin at the catch).

Phases (each a linear ODE with constant coefficients, so each has a closed form):
  * slide:  f = -eps mu_v N, eps = sgn(slip):
        x'' + 2 eps mu_v Omega x' - Omega^2 x = -sgn(x') mu_d g + eps mu_v Omega^2 w
    roots Omega(-eps mu_v +- sqrt(1 + mu_v^2)); for eps = sgn(x') = +1 this is the
    classic sliding equation.  Phi(t) = Phi0 - (eps mu_v / kappa)(2 Omega (x - x0) - Omega^2 w t).
  * stick (no slip at the vane; "rolling" for a free sphere):
        x'' (1 + kappa) = Omega^2 x - sgn(x') mu_d g,    f = -kappa/(1+kappa) G,
    with G = Omega^2 x - sgn(x') mu_d g; it holds while |f| <= mu_v N. For a locked
    granule (kappa -> inf) sticking means x' = r Omega held by static friction f = -G.
  * flight: N would be negative, so the granule leaves the face. It then moves in a
    straight line in the machine frame (disc friction neglected during the flight:
    an approximation, see below) until the face catches it again (perfectly plastic:
    the normal relative velocity is lost, the component along the vane is kept, spin
    unchanged) or it crosses the disc rim.

Events end a phase: the centre reaches the rim (|c| = R) or the contact point the vane
tip, x' = 0 (exact: ratio of exponentials), N = 0, slip = 0, the friction limit while
sticking, the inner end of the vane while moving inwards, landing on the disc (a
granule caught while still falling has no disc friction before that). Each event function has the
form  b0 + b1 t + g1 expm1(l1 t) + g2 expm1(l2 t); its first root is found exactly up
to rounding: the zeros of the derivative split it into monotone pieces (closed form
when b1 = 0, otherwise a bracketed solve on the monotone pieces of the derivative),
then a bracketed Newton step on the first piece that changes sign.

Static checks (x' = 0, or stopped at the inner end): the granule stays (RETAINED_STUCK)
when the outward pull cannot beat static disc friction,
    Omega^2 x - sgn(slip) mu_v N <= mu_d g,   N = -Omega^2 w,
where the vane term is the kinetic friction of a contact point that still slips (a
locked granule always slips inwards there, slip = -r Omega, so the vane pushes it out).
Otherwise it starts outwards from rest. (With w > 0 the face does not press on a granule
at rest: the pull is then Omega^2 |c|, and if it wins the granule leaves in a flight.)
When N falls to 0 in a contact phase (only a granule that disc friction is slowing
down), the face lets go; it is then taken to stop on the disc beside the face at once
(its remaining x' = Omega w / 2 is dropped) and the static check decides.

Approximations (everything else is exact): disc friction is neglected during the
short flights off the face (hops, forward-pitched vanes at the catch) and after the
vane tip; the separation at N = 0 above; a granule that slides inwards past the inner
end of the vane is stopped there (a hub); spin friction at the disc contact
(drilling) and rolling on the disc are ignored (spin only about the vertical axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, RETAINED_TIMEOUT

GRAVITY_M_S2 = 9.81
KAPPA_SPHERE = 0.4  # I / (m r^2) of a solid sphere
_EXP_MAX = 700.0  # largest exponent evaluated (exp(700) ~ 1e304)


# --- building blocks ----------------------------------------------------------------------


def sliding_roots(omega_abs, mu_v, slip_sign=1.0):
    """Roots Omega(-eps mu_v +- sqrt(1 + mu_v^2)) of the sliding equation (l1 > 0 > l2)."""
    om = np.asarray(omega_abs, dtype=float)
    mu = np.asarray(mu_v, dtype=float) * slip_sign
    root = np.sqrt(1.0 + mu * mu)
    return om * (-mu + root), om * (-mu - root)


def rolling_roots(omega_abs, kappa=KAPPA_SPHERE):
    """Roots +-Omega / sqrt(1 + kappa) of rolling without slip along the face."""
    om = np.asarray(omega_abs, dtype=float)
    k = om / np.sqrt(1.0 + kappa)
    return k, -k


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


def stick_coefficients(omega_abs, mu_d, motion_sign=1.0, kappa=KAPPA_SPHERE, g=GRAVITY_M_S2):
    """(A, B, C) while the contact point does not slip (kappa=inf: locked, x'' = 0)."""
    om = np.asarray(omega_abs, dtype=float)
    shape = np.broadcast(om, np.asarray(mu_d), np.asarray(motion_sign), np.asarray(kappa)).shape
    kappa = np.broadcast_to(np.asarray(kappa, dtype=float), shape)
    finite = np.isfinite(kappa)
    scale = np.where(finite, 1.0 / (1.0 + np.where(finite, kappa, 0.0)), 0.0)
    A = np.zeros(shape)
    B = np.broadcast_to(om * om * scale, shape).copy()
    C = np.broadcast_to(-motion_sign * np.asarray(mu_d, dtype=float) * g * scale, shape).copy()
    return A, B, C


def slide_motion(omega_abs, mu_v, mu_d, p_u, w, s0, sd0, slip_sign=1.0, motion_sign=1.0, g=GRAVITY_M_S2):
    """Sliding along the vane from s0 (distance from the inner end) with s' = sd0.

    Returns a LinearMotion in x = s + p.u: s(t) = motion.x(t) - p_u, s'(t) = motion.v(t),
    time to reach s: motion.time_to_reach(s + p_u); normal force: normal_force(Omega, s', w).
    """
    A, B, C = slide_coefficients(omega_abs, mu_v, mu_d, w, slip_sign, motion_sign, g)
    return LinearMotion.solve(A, B, C, np.asarray(s0, dtype=float) + p_u, sd0)


def roll_motion(omega_abs, mu_d, p_u, s0, sd0, motion_sign=1.0, kappa=KAPPA_SPHERE, g=GRAVITY_M_S2):
    """Rolling without slip along the face (free sphere); LinearMotion in x = s + p.u."""
    A, B, C = stick_coefficients(omega_abs, mu_d, motion_sign, kappa, g)
    return LinearMotion.solve(A, B, C, np.asarray(s0, dtype=float) + p_u, sd0)


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
            np.exp(np.minimum(self.l1 * t, _EXP_MAX)),
            np.exp(np.minimum(self.l2 * t, _EXP_MAX)),
            np.expm1(np.minimum(self.l1 * t, _EXP_MAX)),
            np.expm1(np.minimum(self.l2 * t, _EXP_MAX)),
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


# --- first root of b0 + b1 t + g1 expm1(l1 t) + g2 expm1(l2 t) ------------------------------


def solve_increasing(fun: Callable, lo, hi, f_lo=None, f_hi=None, max_iter: int = 100, rtol: float = 1e-14,
                     guess=None):
    """Root of increasing functions on brackets [lo, hi] (f(lo) < 0 <= f(hi)), element-wise.

    `fun(t, idx)` returns (f, f') at t for the elements `idx`. Newton steps that leave
    the bracket are replaced by bisection, so it always converges. `guess`: optional
    starting points (default: the secant through the bracket).
    """
    lo = np.array(lo, dtype=float, copy=True)
    hi = np.array(hi, dtype=float, copy=True)
    n = lo.shape[0]
    idx_all = np.arange(n)
    if f_lo is None:
        f_lo, _ = fun(lo, idx_all)
    if f_hi is None:
        f_hi, _ = fun(hi, idx_all)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(f_hi > f_lo, -f_lo / (f_hi - f_lo), 0.5)
    frac = np.clip(np.nan_to_num(frac, nan=0.5), 0.0, 1.0)
    t = lo + frac * (hi - lo)
    if guess is not None:
        g = np.asarray(guess, dtype=float)
        t = np.where(np.isfinite(g) & (g > lo) & (g < hi), g, t)
    active = idx_all[hi > lo]
    for _ in range(max_iter):
        if active.size == 0:
            break
        ta = t[active]
        f, fp = fun(ta, active)
        neg = f < 0.0
        lo[active] = np.where(neg, ta, lo[active])
        hi[active] = np.where(neg, hi[active], ta)
        la, ha = lo[active], hi[active]
        with np.errstate(divide="ignore", invalid="ignore"):
            step = f / fp
        tol = rtol * np.maximum(np.abs(ta), 1e-300)
        # converged: the Newton step is below the tolerance (or the bracket is)
        done = (f == 0.0) | ((fp > 0) & (np.abs(step) <= tol)) | (ha - la <= tol)
        tn = ta - step
        bad = ~np.isfinite(tn) | (tn <= la) | (tn >= ha) | (fp <= 0)
        tn = np.where(bad, 0.5 * (la + ha), tn)
        t[active] = np.where(done, np.where((f == 0.0) | (ha - la > tol), ta, np.where(f < 0, ha, ta)), tn)
        active = active[~done]
    return t


@dataclass(frozen=True)
class EventFunction:
    """F(t) = F0 + b1 t + g1 expm1(l1 t) + g2 expm1(l2 t), element-wise (l1 >= 0 >= l2)."""

    F0: np.ndarray
    b1: np.ndarray
    g1: np.ndarray
    g2: np.ndarray
    l1: np.ndarray
    l2: np.ndarray

    def __call__(self, t, idx=slice(None)):
        l1, l2 = self.l1[idx], self.l2[idx]
        m1 = np.expm1(np.minimum(l1 * t, _EXP_MAX))
        m2 = np.expm1(np.minimum(l2 * t, _EXP_MAX))
        g1, g2, b1 = self.g1[idx], self.g2[idx], self.b1[idx]
        f = self.F0[idx] + b1 * t + g1 * m1 + g2 * m2
        fp = b1 + g1 * l1 * (m1 + 1.0) + g2 * l2 * (m2 + 1.0)
        return f, fp

    def take(self, sel) -> "EventFunction":
        """The event function of the elements `sel` only."""
        return EventFunction(self.F0[sel], self.b1[sel], self.g1[sel], self.g2[sel], self.l1[sel], self.l2[sel])

    def _guess(self, lo, hi, idx):
        """Start for Newton: the growing exponential solved with the rest frozen."""
        F0, b1, g1, g2 = self.F0[idx], self.b1[idx], self.g1[idx], self.g2[idx]
        l1, l2 = self.l1[idx], self.l2[idx]
        grow = (g1 > 0) & (l1 > 0)
        g1s = np.where(grow, g1, 1.0)
        l1s = np.where(grow, l1, 1.0)
        t = lo.copy()
        for _ in range(3):
            arg = (-F0 - b1 * t - g2 * np.expm1(np.minimum(l2 * t, _EXP_MAX))) / g1s
            t = np.log1p(np.maximum(arg, -1.0 + 1e-16)) / l1s
            t = np.clip(t, lo, hi)
        return np.where(grow, t, np.nan)

    def derivative(self, t, idx=slice(None)):
        l1, l2 = self.l1[idx], self.l2[idx]
        e1 = np.exp(np.minimum(l1 * t, _EXP_MAX))
        e2 = np.exp(np.minimum(l2 * t, _EXP_MAX))
        g1, g2 = self.g1[idx], self.g2[idx]
        return self.b1[idx] + g1 * l1 * e1 + g2 * l2 * e2, g1 * l1 * l1 * e1 + g2 * l2 * l2 * e2

    @staticmethod
    def _ratio_time(num, den, span):
        """t with e^{span t} = num / den, or nan."""
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(den != 0.0, num / np.where(den != 0.0, den, 1.0), -1.0)
            ok = (r > 0.0) & np.isfinite(r) & (span > 0)
            return np.where(ok, np.log(np.where(ok, r, 1.0)) / np.where(span > 0, span, 1.0), np.nan)

    def _derivative_zeros(self, T, t_min):
        """Up to two zeros of F' in (t_min, T), nan where none."""
        n = self.F0.shape[0]
        span = self.l1 - self.l2
        z1 = np.full(n, np.nan)
        z2 = np.full(n, np.nan)
        flat = self.b1 == 0.0
        # b1 = 0: F' = g1 l1 e^{l1 t} + g2 l2 e^{l2 t} has one zero in closed form.
        z1 = np.where(flat, self._ratio_time(-self.g2 * self.l2, self.g1 * self.l1, span), z1)
        gen = np.nonzero(~flat & (span > 0))[0]
        if gen.size:
            # F'' has at most one zero (closed form); F' is monotone on either side.
            ts = self._ratio_time(-self.g2[gen] * self.l2[gen] ** 2, self.g1[gen] * self.l1[gen] ** 2, span[gen])
            tmin = np.full(gen.size, t_min)[...] if np.ndim(t_min) == 0 else t_min[gen]
            Tg = T[gen]
            ts = np.where(np.isfinite(ts), np.clip(ts, tmin, Tg), Tg)
            for k, (a, b) in enumerate(((tmin, ts), (ts, Tg))):
                fa, _ = self.derivative(a, gen)
                fb, _ = self.derivative(b, gen)
                has = (b > a) & (np.sign(fa) * np.sign(fb) < 0)
                sub = gen[has]
                if sub.size == 0:
                    continue
                s = np.where(fb[has] > fa[has], 1.0, -1.0)

                def dfun(t, i, sub=sub, s=s):
                    d1, d2 = self.derivative(t, sub[i])
                    return s[i] * d1, s[i] * d2

                root = solve_increasing(dfun, a[has], b[has], s * fa[has], s * fb[has])
                if k == 0:
                    z1[sub] = root
                else:
                    z2[sub] = root
        return z1, z2

    def first_root(self, horizon, t_min=0.0):
        """First t in [t_min, horizon] with F(t) >= 0 after F < 0 (t_min if F(t_min) >= 0).

        inf where F stays negative on the interval.
        """
        if self.F0.ndim != 1:  # scalars and other shapes: solve flat, give the shape back
            arrays = np.broadcast_arrays(self.F0, self.b1, self.g1, self.g2, self.l1, self.l2,
                                         np.asarray(horizon, dtype=float), np.asarray(t_min, dtype=float))
            shape = arrays[0].shape
            flat = EventFunction(*(np.ravel(a).astype(float) for a in arrays[:6]))
            return flat.first_root(np.ravel(arrays[6]), np.ravel(arrays[7])).reshape(shape)
        n = self.F0.shape[0]
        T = np.broadcast_to(np.asarray(horizon, dtype=float), (n,)).copy()
        tmin = np.broadcast_to(np.asarray(t_min, dtype=float), (n,)).copy()
        T = np.where(np.isfinite(T), T, _EXP_MAX / np.maximum(self.l1, 1e-300))
        T = np.minimum(T, _EXP_MAX / np.maximum(self.l1, 1e-300))
        T = np.maximum(T, tmin)
        z1, z2 = self._derivative_zeros(T, tmin)
        z1 = np.where(np.isfinite(z1) & (z1 > tmin) & (z1 < T), z1, T)
        z2 = np.where(np.isfinite(z2) & (z2 > tmin) & (z2 < T), z2, T)
        pts = np.sort(np.stack([tmin, z1, z2, T], axis=1), axis=1)
        F = np.empty_like(pts)
        for j in range(4):
            F[:, j], _ = self(pts[:, j])
        nonneg = F >= 0.0
        first = np.argmax(nonneg, axis=1)
        found = nonneg[np.arange(n), first]
        result = np.full(n, np.inf)
        at_start = found & (first == 0)
        result[at_start] = tmin[at_start]
        need = np.nonzero(found & (first > 0))[0]
        if need.size:
            j = first[need]
            lo, hi = pts[need, j - 1], pts[need, j]
            flo, fhi = F[need, j - 1], F[need, j]

            def fun(t, i):
                return self(t, need[i])

            result[need] = solve_increasing(fun, lo, hi, flo, fhi, guess=self._guess(lo, hi, need))
        return result


# --- one vane: the phase machine -------------------------------------------------------------

# pending actions between phases
_CLASSIFY, _CONTACT, _STATIC, _STICKCHECK, _FLIGHT, _TIPFLIGHT, _DONE = range(7)


@dataclass
class VaneRun:
    """Result of `run_along_vane` (arrays of length n, SI units).

    Positions and velocities are (u, n) components in the axes of the disc at the
    final time `t_s` (time since the catch): `pos_u`, `pos_n` of the granule centre
    and `vel_u`, `vel_n` of its velocity in the machine (inertial) frame.
    `spin_offset` is Phi = sgn(omega) r (spin - omega); the inertial spin is
    omega + sgn(omega) Phi / r.
    """

    outcome: np.ndarray
    t_s: np.ndarray
    pos_u: np.ndarray
    pos_n: np.ndarray
    vel_u: np.ndarray
    vel_n: np.ndarray
    spin_offset: np.ndarray
    hops: np.ndarray  # flights off the face that ended in a re-catch
    separations: np.ndarray  # times N reached 0 (or was negative at a catch)
    stuck_at_hub: np.ndarray  # stopped at the inner end while sliding inwards
    stick_time_s: np.ndarray  # time spent without slip at the face (rolling, free)
    stick_breaks: np.ndarray  # times the friction limit ended a no-slip phase
    left_at_tip: np.ndarray  # left the vane at its tip before the centre reached R
    min_normal_force: np.ndarray  # smallest N met during contact phases (per unit mass)
    rounds: int = 0
    notes: list = field(default_factory=list)


def run_along_vane(
    omega_abs,
    x0,
    v0,
    w,
    x_in,
    x_tip,
    disc_radius,
    mu_v,
    mu_d,
    granule_radius,
    rotation: str = "free",
    spin_offset0=None,
    kappa: float = KAPPA_SPHERE,
    g: float = GRAVITY_M_S2,
    time_limit_s=3.0,
    max_rounds: int = 200,
    disc_contact_from_s=0.0,
) -> VaneRun:
    """Follow granules caught on a vane's leading face until they leave the disc.

    Element-wise over granules; every argument broadcasts to shape (n,).
    x0, v0: position and velocity along the face just after the catch (x = c.u);
    w = c.n of the face line; x_in, x_tip: x at the inner end and at the tip of the
    face; disc_radius: departure when |c| = R; rotation "free" or "locked";
    spin_offset0: Phi at the catch (default -r Omega: no spin in the machine frame).
    time_limit_s: per-granule time budget from the catch.
    disc_contact_from_s: time after the catch from which the granule lies on the disc
    (a granule caught while still falling below the vane tops feels no disc friction
    before it lands); default 0.
    """
    if rotation not in ("free", "locked"):
        raise ValueError(f"rotation must be 'free' or 'locked', got {rotation!r}")
    arrays = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (omega_abs, x0, v0, w, x_in, x_tip, disc_radius, mu_v, mu_d,
                                              granule_radius, time_limit_s, disc_contact_from_s))
    )
    n = arrays[0].shape[0] if arrays[0].ndim else 1
    Om, x, v, w, x_in, x_tip, R, mu_v, mu_full, r, tlim, t_on = (
        np.array(np.atleast_1d(a), dtype=float) for a in arrays
    )
    mu_d = np.where(t_on <= 0.0, mu_full, 0.0)  # disc friction in force now
    locked = rotation == "locked"
    q = 1.0 if locked else kappa / (1.0 + kappa)  # |f| = q |G| while sticking
    Phi = -r * Om if spin_offset0 is None else np.array(np.broadcast_to(spin_offset0, (n,)), dtype=float)
    if locked:
        Phi = -r * Om
    x_R = np.sqrt(np.maximum(R * R - w * w, 0.0))
    x_end = np.minimum(x_R, x_tip)
    tip_first = x_tip < x_R
    t = np.zeros(n)
    sgn_m = np.ones(n)  # sgn(x') of the current contact phase
    sgn_e = np.ones(n)  # sgn(slip) while sliding
    stick = np.zeros(n, dtype=bool)
    action = np.full(n, _CLASSIFY)
    outcome = np.full(n, RETAINED_TIMEOUT, dtype=np.int8)
    # final state (u, n components, spinner axes at the final time)
    pu, pn, vu, vn = x.copy(), w.copy(), v - Om * w, Om * x
    hops = np.zeros(n, dtype=np.int32)
    seps = np.zeros(n, dtype=np.int32)
    hub = np.zeros(n, dtype=bool)
    stick_time = np.zeros(n)
    breaks = np.zeros(n, dtype=np.int32)
    at_tip = np.zeros(n, dtype=bool)
    min_N = np.full(n, np.inf)
    t_eps = 1e-10 / np.maximum(Om, 1e-300)
    # |N| below this counts as touching: a rounding-level negative N is not a flight
    n_tol = 1e-7 * Om * Om * (np.abs(x_end) + np.abs(w))
    notes: list = []

    def finish(idx, code):
        outcome[idx] = code
        action[idx] = _DONE
        pu[idx], pn[idx] = x[idx], w[idx]
        vu[idx], vn[idx] = v[idx] - Om[idx] * w[idx], Om[idx] * x[idx]

    def stuck(idx):
        v[idx] = 0.0
        finish(idx, RETAINED_STUCK)
        if not locked:
            Phi[idx] = 0.0  # at rest on the disc the granule ends up turning with it

    rounds = 0
    for rounds in range(1, max_rounds + 1):
        live = action != _DONE
        if not np.any(live):
            break
        mu_d[:] = np.where(t >= t_on, mu_full, 0.0)
        # ---- value-based classification (after a catch, a re-catch) ----
        idx = np.nonzero(action == _CLASSIFY)[0]
        if idx.size:
            N = normal_force(Om[idx], v[idx], w[idx])
            past = x[idx] >= x_end[idx]
            sep = ~past & (N < -n_tol[idx])
            rest = ~past & ~sep & (v[idx] == 0.0)
            move = ~past & ~sep & ~rest
            action[idx[past]] = np.where(tip_first[idx[past]], _TIPFLIGHT, _DONE)
            dep = idx[past & ~tip_first[idx]]
            x[dep] = x_R[dep]
            finish(dep, DEPARTED)
            seps[idx[sep]] += 1
            action[idx[sep]] = _FLIGHT
            action[idx[rest]] = _STATIC
            mv = idx[move]
            sgn_m[mv] = np.sign(v[mv])
            slip = v[mv] + Phi[mv]
            stick[mv] = False
            sgn_e[mv] = np.where(slip != 0.0, np.sign(slip), 1.0)
            action[mv] = np.where(slip != 0.0, _CONTACT, _STICKCHECK)
        # ---- static check (x' = 0) ----
        idx = np.nonzero(action == _STATIC)[0]
        if idx.size:
            v[idx] = 0.0
            Ns = -Om[idx] ** 2 * w[idx]
            free_of_face = Ns < 0.0
            pull = Om[idx] ** 2 * x[idx]
            slip = Phi[idx]
            vane_push = np.where(free_of_face, 0.0, -np.sign(slip) * mu_v[idx] * Ns)
            pull_total = np.where(free_of_face, Om[idx] ** 2 * np.hypot(x[idx], w[idx]), pull + vane_push)
            hold = pull_total <= mu_d[idx] * g
            stuck(idx[hold])
            go = ~hold
            off = idx[go & free_of_face]
            seps[off] += 1
            action[off] = _FLIGHT
            on = idx[go & ~free_of_face]
            sgn_m[on] = 1.0
            stick[on] = False
            sgn_e[on] = np.where(Phi[on] != 0.0, np.sign(Phi[on]), 1.0)
            action[on] = np.where(Phi[on] != 0.0, _CONTACT, _STICKCHECK)
        # ---- slip has reached zero: stick if friction can hold it ----
        idx = np.nonzero(action == _STICKCHECK)[0]
        if idx.size:
            Gv = Om[idx] ** 2 * x[idx] - sgn_m[idx] * mu_d[idx] * g
            N = normal_force(Om[idx], v[idx], w[idx])
            ok = q * np.abs(Gv) <= mu_v[idx] * N
            stick[idx] = ok
            sgn_e[idx] = np.where(ok, sgn_e[idx], np.where(Gv >= 0.0, 1.0, -1.0))
            if not locked:
                Phi[idx] = -v[idx]
            action[idx] = _CONTACT
        # ---- flights (closed form), then contact phases ----
        for kind in (_FLIGHT, _TIPFLIGHT):
            idx = np.nonzero(action == kind)[0]
            if idx.size == 0:
                continue
            fl = _flight(Om[idx], x[idx], v[idx], w[idx], R[idx], x_in[idx], x_tip[idx], recatch=kind == _FLIGHT)
            t_new = t[idx] + fl["t"]
            late = t_new > tlim[idx]
            exit_ = ~fl["recatch"] & ~late
            ex = idx[exit_]
            t[ex] = t_new[exit_]
            pu[ex], pn[ex], vu[ex], vn[ex] = fl["pu"][exit_], fl["pn"][exit_], fl["vu"][exit_], fl["vn"][exit_]
            outcome[ex] = DEPARTED
            action[ex] = _DONE
            if kind == _TIPFLIGHT:
                at_tip[ex] = True
            rc = fl["recatch"] & ~late
            ri = idx[rc]
            t[ri] = t_new[rc]
            x[ri], v[ri] = fl["x"][rc], fl["v"][rc]
            hub[ri] |= fl["hub"][rc]
            hops[ri] += 1
            action[ri] = _CLASSIFY
            lt = idx[late]
            t[lt] = tlim[lt]
            finish(lt, RETAINED_TIMEOUT)
        idx = np.nonzero(action == _CONTACT)[0]
        if idx.size == 0:
            continue
        _contact_round(
            idx, Om, x, v, w, x_in, x_end, Phi, t, tlim, sgn_m, sgn_e, stick, action, mu_v, mu_d, r,
            locked, kappa, q, g, t_eps, stick_time, min_N, tip_first, x_R, hub, seps, finish, stuck, breaks, t_on,
        )
    left = action != _DONE
    if np.any(left):
        finish(np.nonzero(left)[0], RETAINED_TIMEOUT)
        notes.append(f"{int(left.sum())} granule(s) still changing phase after {max_rounds} rounds: timeout")
    return VaneRun(
        outcome=outcome, t_s=t, pos_u=pu, pos_n=pn, vel_u=vu, vel_n=vn, spin_offset=Phi, hops=hops,
        separations=seps, stuck_at_hub=hub, stick_time_s=stick_time, stick_breaks=breaks, left_at_tip=at_tip,
        min_normal_force=min_N, rounds=rounds, notes=notes,
    )


def _contact_round(idx, Om, x, v, w, x_in, x_end, Phi, t, tlim, sgn_m, sgn_e, stick, action, mu_v, mu_d, r,
                   locked, kappa, q, g, t_eps, stick_time, min_N, tip_first, x_R, hub, seps, finish, stuck, breaks,
                   t_on):
    """Advance every granule of `idx` (in contact) to the end of its current phase."""
    om, xx, vv, ww = Om[idx], x[idx], v[idx], w[idx]
    sm, se, st = sgn_m[idx], sgn_e[idx], stick[idx]
    mv, md = mu_v[idx], mu_d[idx]
    # coefficients of the phase
    As, Bs, Cs = slide_coefficients(om, mv, md, ww, se, sm, g)
    if locked:
        Ak, Bk, Ck = np.zeros_like(om), np.zeros_like(om), np.zeros_like(om)
    else:
        Ak, Bk, Ck = stick_coefficients(om, md, sm, kappa, g)
    A = np.where(st, Ak, As)
    B = np.where(st, Bk, Bs)
    C = np.where(st, Ck, Cs)
    mot = LinearMotion.solve(A, B, C, xx, vv)
    t_rem = np.maximum(tlim[idx] - t[idx], 0.0)
    t_rest = mot.time_of_rest()
    # a phase that starts at rest (x' = 0) has a spurious root at t = 0
    t_rest = np.where(t_rest > t_eps[idx], t_rest, np.inf)
    t_bound = mot.reach_bound(x_end[idx], x_in[idx])
    T = np.minimum(np.minimum(t_rem, t_bound), t_rest * (1.0 + 1e-12))
    tmin = np.minimum(t_eps[idx], T)
    N0 = normal_force(om, vv, ww)
    cand = np.full((idx.size, 9), np.inf)

    def put(col, ev, sel):
        sel = np.nonzero(sel)[0]
        if sel.size:
            cand[sel, col] = ev.take(sel).first_root(T[sel], tmin[sel])

    # 0: rim / tip (outwards) ; 1: inner end (inwards)
    out = sm > 0
    put(0, mot.event(xx - x_end[idx], 0.0, 1.0, 0.0), out)
    put(1, mot.event(x_in[idx] - xx, 0.0, -1.0, 0.0), ~out)
    # 2: x' = 0 (exact)
    cand[:, 2] = t_rest
    # 3: N = 0  (F = -N)
    put(3, mot.event(np.minimum(-N0, 0.0), 0.0, 0.0, -2.0 * om), np.ones(idx.size, dtype=bool))
    if locked:
        slip0 = vv - r[idx] * om
        # 4: slip = 0 while sliding, F = -eps (x' - r Omega)
        ev = mot.event(-se * slip0, 0.0, 0.0, -se)
    else:
        slip0 = vv + Phi[idx]
        # slip(t) = slip0 + dv - (2 Omega eps mu / kappa) dx + (eps mu Omega^2 w / kappa) t
        ev = mot.event(-se * slip0, -mv * om * om * ww / kappa, 2.0 * om * mv / kappa, -se)
    put(4, ev, ~st)
    # 5, 6: friction limit while sticking: +-q G - mu N = 0
    G0 = om * om * xx - sm * md * g
    for col, s in ((5, 1.0), (6, -1.0)):
        put(col, mot.event(s * q * G0 - mv * N0, 0.0, s * q * om * om, -2.0 * om * mv), st)
    cand[:, 7] = np.where(T >= t_rem, t_rem, np.inf)  # time limit
    # 8: the granule lands on the disc (disc friction starts)
    to_land = t_on[idx] - t[idx]
    cand[:, 8] = np.where((to_land > 0.0) & (to_land <= T), to_land, np.inf)
    which = np.argmin(cand, axis=1)
    tau = cand[np.arange(idx.size), which]
    none = ~np.isfinite(tau)
    # No event before the horizon (should not happen): stop at the horizon, time out.
    tau = np.where(none, T, tau)
    which = np.where(none, 7, which)
    # advance
    dx = mot.dx(tau)
    dv = mot.dv(tau)
    x_new = xx + dx
    v_new = vv + dv
    if locked:
        Phi_new = Phi[idx]
    else:
        Phi_sl = Phi[idx] - (se * mv / kappa) * (2.0 * om * dx - om * om * ww * tau)
        Phi_new = np.where(st, -v_new, Phi_sl)
    # smallest normal force met in this phase (N is a sum of two exponentials: check ends + extremum)
    Nend = normal_force(om, v_new, ww)
    Nmin = np.minimum(N0, Nend)
    acc_zero = mot.event(0.0, 0.0, 0.0, 1.0)  # F' = acceleration
    tz = EventFunction._ratio_time(-acc_zero.g2 * acc_zero.l2, acc_zero.g1 * acc_zero.l1, mot.l1 - mot.l2)
    inside = np.isfinite(tz) & (tz > 0) & (tz < tau)
    if np.any(inside):
        Nz = normal_force(om, mot.v(np.where(inside, tz, 0.0)), ww)
        Nmin = np.where(inside, np.minimum(Nmin, Nz), Nmin)
    min_N[idx] = np.minimum(min_N[idx], Nmin)
    stick_time[idx] += np.where(st, tau, 0.0)
    t[idx] = t[idx] + tau
    x[idx], v[idx], Phi[idx] = x_new, v_new, Phi_new
    # transitions
    e = which
    i = idx[e == 0]  # rim or tip
    x[i] = x_end[i]
    tipf = tip_first[i]
    action[i[tipf]] = _TIPFLIGHT
    dep = i[~tipf]
    x[dep] = x_R[dep]
    finish(dep, DEPARTED)
    i = idx[e == 1]  # inner end, moving inwards: the hub stops it
    x[i] = x_in[i]
    hub[i] = True
    action[i] = _STATIC
    i = idx[e == 2]
    action[i] = _STATIC
    i = idx[e == 3]  # N = 0: the face lets go of a granule that disc friction slows down
    seps[i] += 1
    action[i] = _STATIC  # it stops on the disc beside the face (residual x' = Omega w / 2 lost)
    i = idx[e == 4]  # slip = 0
    if not locked:
        Phi[i] = -v[i]
    action[i] = _STICKCHECK
    i = idx[(e == 5) | (e == 6)]  # friction limit: slide in the sense of G
    Gi = Om[i] ** 2 * x[i] - sgn_m[i] * mu_d[i] * g
    breaks[i] += 1
    stick[i] = False
    sgn_e[i] = np.where(Gi >= 0.0, 1.0, -1.0)
    action[i] = _CONTACT
    i = idx[e == 7]
    finish(i, RETAINED_TIMEOUT)
    i = idx[e == 8]  # landed: same motion, now with disc friction; re-check a no-slip phase
    t[i] = t_on[i]
    action[i] = np.where(stick[i], _STICKCHECK, _CONTACT)


def _theta_terms(theta):
    """(cos t - 1)/t^2, (t cos t - sin t)/t^2, sin t / t, stable for small t > 0."""
    th = np.asarray(theta, dtype=float)
    half = np.sin(0.5 * th)
    safe = np.where(th > 0, th, 1.0)
    c1 = np.where(th > 0, -2.0 * (half / safe) ** 2, -0.5)
    t2 = th * th
    series = -th / 3.0 + th * t2 / 30.0 - th * t2 * t2 / 840.0 + th * t2**3 / 45360.0
    direct = (th * np.cos(th) - np.sin(th)) / (safe * safe)
    c2 = np.where(th < 0.1, series, direct)
    c3 = np.sinc(th / np.pi)
    return c1, c2, c3


def _flight(Om, x0, v0, w, R, x_in, x_tip, recatch=True, n_scan=40):
    """Straight flight (machine frame) from the face line at (x0, w) with x' = v0.

    Returns the exit at |c| = R or the first re-catch by the same face, whichever
    comes first. All in (u, n) components; time origin at the start of the flight.
    Machine-frame velocity: V = (v0 - Omega w, Omega x0). The face (spinner) axes turn
    by theta = Omega t, and the gap to the face line is
        d(theta) = w (cos th - 1) + x0 (th cos th - sin th) - (v0/Omega - w) th sin th.
    """
    Vu, Vn = v0 - Om * w, Om * x0
    XV = x0 * Vu + w * Vn
    V2 = Vu * Vu + Vn * Vn
    X2 = x0 * x0 + w * w
    gap = np.maximum(R * R - X2, 0.0)
    root = np.sqrt(XV * XV + V2 * gap)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_exit = np.where(XV >= 0, gap / (XV + root), (root - XV) / V2)
    t_exit = np.where(np.isfinite(t_exit), t_exit, 0.0)
    th_exit = Om * t_exit
    n = x0.shape[0]
    th_catch = np.full(n, np.inf)
    if recatch and n:
        k = v0 / Om - w

        def g_of(th, i=slice(None)):
            c1, c2, c3 = _theta_terms(th)
            return w[i] * c1 + x0[i] * c2 - k[i] * c3

        scan = th_exit[:, None] * np.logspace(-9, 0, n_scan)[None, :]
        G = g_of(scan, (slice(None), None))
        neg = G <= 0.0
        first = np.argmax(neg, axis=1)
        found = neg[np.arange(n), first]
        i0 = np.nonzero(found & (first == 0))[0]
        th_catch[i0] = scan[i0, 0]
        need = np.nonzero(found & (first > 0))[0]
        if need.size:
            lo = scan[need, first[need] - 1]
            hi = scan[need, first[need]]

            def minus_d(th, i):  # -d(theta) and its derivative: increasing through the re-catch
                j = need[i]
                s_, c_ = np.sin(th), np.cos(th)
                d = w[j] * (c_ - 1.0) + x0[j] * (th * c_ - s_) - k[j] * th * s_
                dd = -w[j] * s_ - x0[j] * th * s_ - k[j] * (s_ + th * c_)
                return -d, -dd

            th_catch[need] = solve_increasing(minus_d, lo, hi)
    th = np.where(np.isfinite(th_catch), th_catch, th_exit)
    c, s = np.cos(th), np.sin(th)
    t = th / Om
    # machine-frame position X0 + V t, in the face axes turned by theta
    Xu, Xn = x0 + Vu * t, w + Vn * t
    pu, pn = Xu * c + Xn * s, Xn * c - Xu * s
    vu, vn = Vu * c + Vn * s, Vn * c - Vu * s
    xc = pu
    vc = vu + Om * w  # relative velocity along the face at the re-catch
    rc = np.isfinite(th_catch) & (xc <= x_tip)
    hub = rc & (xc < x_in)
    # past the tip: it does not meet the face again, it leaves the disc
    th2 = np.where(np.isfinite(th_catch) & ~rc, th_exit, th)
    redo = np.isfinite(th_catch) & ~rc
    if np.any(redo):
        c2, s2 = np.cos(th2), np.sin(th2)
        t2 = th2 / Om
        Xu2, Xn2 = x0 + Vu * t2, w + Vn * t2
        pu = np.where(redo, Xu2 * c2 + Xn2 * s2, pu)
        pn = np.where(redo, Xn2 * c2 - Xu2 * s2, pn)
        vu = np.where(redo, Vu * c2 + Vn * s2, vu)
        vn = np.where(redo, Vn * c2 - Vu * s2, vn)
        t = np.where(redo, t2, t)
    return {
        "t": t, "recatch": rc, "x": np.where(hub, x_in, xc), "v": vc, "hub": hub,
        "pu": pu, "pn": pn, "vu": vu, "vn": vn,
    }
