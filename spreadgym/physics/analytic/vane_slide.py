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
  * flight: N would be negative, or the granule rebounds from an impact, so it is off
    the face. It then moves in a straight line in the machine frame, plus the disc's
    drag to first order if asked (flight_drag; closed form along the line, `_DragLine`),
    until the face catches it again (an impact, below), it crosses the disc rim, or the
    drag has used up its velocity relative to the disc (it then lies on the disc: held
    there if Omega^2 |c| <= mu_d g, else a new flight from rest).

Impacts (the catch when approach_speed0 > 0, every re-catch): the relative normal
velocity -a (towards the face) becomes e a (restitution e); with impact_friction a
tangential impulse of at most mu_v (1 + e) a (per unit mass) acts against the slip of
the contact point and stops it at most (slip changes by the impulse times 1 + 1/kappa,
times 1 when locked), Phi changes by impulse / kappa. A rebound e a above
rebound_stop Omega x starts a flight; a slower one ends the bouncing: plastic. The
rebounds fall by about e per impact, so that takes log(rebound_stop) / log(e) impacts
(8 for e = 0.43 and the default 1e-3). With e = 0 and no impact friction (the
defaults) a re-catch is plastic and frictionless, the model before restitution.

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

Approximations (everything else is exact): disc friction during flights off the face
is neglected (flight_drag False) or first order (True: the drag direction is that of
the velocity relative to the disc along the straight line); it is neglected after the
vane tip; bouncing ends below rebound_stop; the separation at N = 0 above; a granule
that slides inwards past the inner end of the vane is stopped there (a hub); spin
friction at the disc contact (drilling) and rolling on the disc are ignored (spin only
about the vertical axis).
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
                     guess=None, polish: bool = False):
    """Root of increasing functions on brackets [lo, hi] (f(lo) < 0 <= f(hi)), element-wise.

    `fun(t, idx)` returns (f, f') at t for the elements `idx`. Newton steps that leave
    the bracket are replaced by bisection, so it always converges. `guess`: optional
    starting points (default: the secant through the bracket). polish: stop once the
    Newton step is below 1e-8 |t| and return t minus that step (in the quadratic
    regime its error is ~ step^2: one evaluation fewer for the same precision).
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
        newton = (fp > 0) & (np.abs(step) <= (1e-8 * np.maximum(np.abs(ta), 1e-300) if polish else tol))
        done = (f == 0.0) | newton | (ha - la <= tol)
        tn = ta - step
        bad = ~np.isfinite(tn) | (tn <= la) | (tn >= ha) | (fp <= 0)
        tn = np.where(bad, 0.5 * (la + ha), tn)
        end = np.where((f == 0.0) | (ha - la > tol), ta, np.where(f < 0, ha, ta))
        if polish:
            end = np.where(newton & (f != 0.0), np.clip(ta - step, la, ha), end)
        t[active] = np.where(done, end, tn)
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
_CLASSIFY, _CONTACT, _STATIC, _STICKCHECK, _FLIGHT, _TIPFLIGHT, _DONE, _IMPACT = range(8)

# A rebound off the face slower than this fraction of the face's own speed there (Omega x)
# ends the bouncing: the impact is then taken as plastic (see run_along_vane).
REBOUND_STOP = 1e-3


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
    hops: np.ndarray  # flights off the face (N < 0, not rebounds) that ended in a re-catch
    bounces: np.ndarray  # rebounds off the face (impacts with e v_n above the stop threshold)
    flight_stops: np.ndarray  # times disc drag brought a flight to rest on the disc
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
    approach_speed0=0.0,
    restitution=0.0,
    impact_friction: bool = False,
    rebound_stop: float = REBOUND_STOP,
    flight_drag: bool = False,
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
    approach_speed0: speed towards the face just before the catch (relative, normal to
    the face, >= 0); with it the catch is an impact (see IMPACT in the module
    docstring) and v0, spin_offset0 are the values just before it. Default 0: v0 is
    kept, as in a plastic frictionless catch.
    restitution: e of every impact on the face (the catch and each re-catch after a
    flight); 0 is plastic. impact_friction: Coulomb friction impulse at impacts.
    rebound_stop: a rebound slower than rebound_stop * Omega * x ends the bouncing
    (that impact is taken as plastic). flight_drag: disc friction during flights off
    the face, to first order (`_drag_offsets`); tip flights stay straight.
    The defaults (e = 0, no impact friction, no drag in flight) are the model before
    restitution: a plastic, frictionless re-catch after a hop.
    """
    if rotation not in ("free", "locked"):
        raise ValueError(f"rotation must be 'free' or 'locked', got {rotation!r}")
    arrays = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (omega_abs, x0, v0, w, x_in, x_tip, disc_radius, mu_v, mu_d,
                                              granule_radius, time_limit_s, disc_contact_from_s,
                                              approach_speed0, restitution))
    )
    n = arrays[0].shape[0] if arrays[0].ndim else 1
    Om, x, v, w, x_in, x_tip, R, mu_v, mu_full, r, tlim, t_on, approach, e_rest = (
        np.array(np.atleast_1d(a), dtype=float) for a in arrays
    )
    approach = np.maximum(approach, 0.0)
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
    action = np.where(approach > 0.0, _IMPACT, _CLASSIFY)
    vn_fl = np.zeros(n)  # relative speed away from the face at the start of a flight (a rebound)
    n_fl = w.copy()  # c.n at the start of a flight (w: on the face line)
    rebounding = np.zeros(n, dtype=bool)  # the current flight started with a rebound
    stops = np.zeros(n, dtype=np.int32)
    outcome = np.full(n, RETAINED_TIMEOUT, dtype=np.int8)
    # final state (u, n components, spinner axes at the final time)
    pu, pn, vu, vn = x.copy(), w.copy(), v - Om * w, Om * x
    hops = np.zeros(n, dtype=np.int32)
    bounces = np.zeros(n, dtype=np.int32)
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
    drag_dropped = 0

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
        # ---- impact on the face (the catch, a re-catch): restitution and friction impulses ----
        idx = np.nonzero(action == _IMPACT)[0]
        if idx.size:
            a_n, e_i = approach[idx], e_rest[idx]
            if impact_friction:
                # per unit mass: normal impulse (1 + e) a_n; the tangential one stops the slip
                # of the contact point at most (it never reverses it), Coulomb-limited
                slip = v[idx] + Phi[idx]
                stop = np.abs(slip) * q
                f = -np.sign(slip) * np.minimum(mu_v[idx] * (1.0 + e_i) * a_n, stop)
                v[idx] += f
                if not locked:
                    Phi[idx] += f / kappa
            reb = e_i * a_n
            fly = reb > rebound_stop * Om[idx] * np.abs(x[idx])
            vn_fl[idx] = np.where(fly, reb, 0.0)
            n_fl[idx] = w[idx]
            rebounding[idx] = fly
            bounces[idx[fly]] += 1
            approach[idx] = 0.0
            action[idx] = np.where(fly, _FLIGHT, _CLASSIFY)
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
            vn_fl[idx[sep]] = 0.0
            n_fl[idx[sep]] = w[idx[sep]]
            rebounding[idx[sep]] = False
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
            vn_fl[off] = 0.0
            n_fl[off] = w[off]
            rebounding[off] = False
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
            fly = kind == _FLIGHT
            vn0 = vn_fl[idx] if fly else np.zeros(idx.size)
            drag = mu_full[idx] * g if (flight_drag and fly) else None
            fl = _flight(Om[idx], x[idx], v[idx], w[idx], R[idx], x_in[idx], x_tip[idx], recatch=fly,
                         vn0=vn0, n0=n_fl[idx] if fly else None, drag=drag,
                         drag_from=np.maximum(t_on[idx] - t[idx], 0.0))
            drag_dropped += int(fl["drag_dropped"].sum())
            t_new = t[idx] + fl["t"]
            late = t_new > tlim[idx]
            exit_ = (fl["event"] == 0) & ~late
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
            hops[ri] += ~rebounding[ri]
            approach[ri] = np.where(fl["hub"][rc], 0.0, fl["approach"][rc])
            action[ri] = _IMPACT
            vn_fl[idx] = 0.0
            # the drag used up the velocity relative to the disc: at rest on it, off the face
            sp = (fl["event"] == 2) & ~late
            si = idx[sp]
            t[si] = t_new[sp]
            cu, cn = fl["pu"][sp], fl["pn"][sp]
            stops[si] += 1
            hold = Om[si] ** 2 * np.hypot(cu, cn) <= mu_full[si] * g
            held = si[hold]
            stuck(held)
            pu[held], pn[held] = cu[hold], cn[hold]
            vu[held], vn[held] = -Om[held] * cn[hold], Om[held] * cu[hold]
            go = si[~hold]  # the pull wins: a new flight from rest on the disc
            x[go], n_fl[go], v[go] = cu[~hold], cn[~hold], 0.0
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
    if drag_dropped:
        notes.append(f"{drag_dropped} flight(s) off the face with disc drag reached neither the rim nor the face "
                     "within 8 drag-free exit times: drag dropped for them")
    left = action != _DONE
    if np.any(left):
        finish(np.nonzero(left)[0], RETAINED_TIMEOUT)
        notes.append(f"{int(left.sum())} granule(s) still changing phase after {max_rounds} rounds: timeout")
    return VaneRun(
        outcome=outcome, t_s=t, pos_u=pu, pos_n=pn, vel_u=vu, vel_n=vn, spin_offset=Phi, hops=hops,
        bounces=bounces, flight_stops=stops, separations=seps, stuck_at_hub=hub, stick_time_s=stick_time,
        stick_breaks=breaks, left_at_tip=at_tip,
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


_DRAG_SERIES = 1e-4  # b s / |W0| below this: the drag integrals by their Taylor series
_EXIT_MULTIPLES = np.array([1.0, 1.25, 1.6, 2.0, 3.0, 4.5, 8.0])  # of the drag-free exit time, tried with drag
_CATCH_STEPS = (1.25, 1.6, 2.0, 3.0)  # widening of the re-catch bracket with drag


class _DragLine:
    """First-order disc drag along straight flights in the machine frame, closed form.

    Along the straight line the velocity relative to the disc is affine in time,
    W(s) = W0 + s B (B = -omega x V). The drag -a_d W/|W| taken along it gives
        dV(s) = -a_d int_0^s W/|W|,   dX(s) = -a_d int_0^s (s - sigma) W/|W| dsigma.
    With W = P + y B (P perpendicular to B, |P| = h, y = y0 + sigma, b = |B|,
    F = |W| = sqrt(h^2 + b^2 y^2), S = asinh(b y / h)):
        int W/|W| = P dS / b + B dF / b^2,
        int (s - sigma) W/|W| = P J1 / b + B J2 / b^2,
        J1 = y dS - dF / b,   J2 = (y dF - s F0) / 2 + h^2 dS / (2 b),
    with dS = S(y) - S(y0) = asinh(b s (y + y0) / (y F0 + y0 F)) (same signs) or
    asinh(b (y F0 - y0 F) / h^2) (opposite signs) and dF = b^2 s (y + y0) / (F + F0),
    free of cancellation; for b s < 1e-4 |W0| the Taylor series in s (Legendre
    coefficients of 1/|W|) instead. The parts that do not depend on s are computed
    once per flight. Element-wise; all zero where a_d = 0.
    """

    def __init__(self, W0u, W0n, Bu, Bn, a_d):
        with np.errstate(divide="ignore", invalid="ignore"):
            F0 = np.hypot(W0u, W0n)
            b2 = Bu * Bu + Bn * Bn
            b = np.sqrt(b2)
            ib = np.where(b > 0.0, 1.0 / np.where(b > 0.0, b, 1.0), 0.0)
            y0 = (W0u * Bu + W0n * Bn) * ib * ib
            Pu, Pn = W0u - y0 * Bu, W0n - y0 * Bn
            h2 = Pu * Pu + Pn * Pn
            self.F0, self.b, self.b2, self.ib, self.y0, self.h2 = F0, b, b2, ib, y0, h2
            self.ih2 = 1.0 / np.maximum(h2, 1e-200)
            m = -np.array(a_d, dtype=float)
            self.Pu, self.Pn = m * Pu * ib, m * Pn * ib  # -a_d P / b
            self.Bu, self.Bn = m * Bu * ib * ib, m * Bn * ib * ib  # -a_d B / b^2
            # Taylor series where b s < 1e-4 F0 (and always where b = 0)
            self.s_series = np.where(b > 0.0, _DRAG_SERIES * F0 * ib, np.inf)
            self.any_series = bool(np.any(F0 > 0.0))
        self._raw = (W0u, W0n, Bu, Bn, m)
        self._k = None

    @property
    def k(self):
        """Taylor coefficients of -a_d W/|W| (computed when first needed)."""
        if self._k is None:
            W0u, W0n, Bu, Bn, m = self._raw
            F0 = self.F0
            with np.errstate(divide="ignore", invalid="ignore"):
                Fs = np.where(F0 > 0.0, F0, 1.0)
                u0u, u0n, bu, bn = W0u / Fs, W0n / Fs, Bu / Fs, Bn / Fs
                u0u, u0n = np.where(F0 > 0.0, u0u, 0.0), np.where(F0 > 0.0, u0n, 0.0)
                c1 = u0u * bu + u0n * bn
                be2 = bu * bu + bn * bn
                g1, g2, g3 = -c1, 0.5 * (3.0 * c1 * c1 - be2), 0.5 * c1 * (3.0 * be2 - 5.0 * c1 * c1)
                self._k = [m * a for a in (u0u, u0n, u0u * g1 + bu, u0n * g1 + bn, u0u * g2 + bu * g1,
                                           u0n * g2 + bn * g1, u0u * g3 + bu * g2, u0n * g3 + bn * g2)]
        return self._k

    def drop(self, idx):
        """No drag for the elements idx from now on."""
        self._raw[4][idx] = 0.0
        for a in [self.Pu, self.Pn, self.Bu, self.Bn] + (self._k or []):
            a[idx] = 0.0

    def at(self, s, i=slice(None)):
        """(dVu, dVn, dXu, dXn) after a time s >= 0 of drag (elements i; s broadcasts)."""
        y0, F0, b, b2, ib, h2 = self.y0[i], self.F0[i], self.b[i], self.b2[i], self.ib[i], self.h2[i]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            y = y0 + s
            F = np.sqrt(h2 + b2 * y * y)
            ypy = y + y0
            dF = b2 * s * ypy / np.maximum(F + F0, 1e-300)
            same = y * y0 > 0.0
            arg = np.where(same, b * s * ypy / (y * F0 + y0 * F), b * (y * F0 - y0 * F) * self.ih2[i])
            dS = np.arcsinh(arg)
            J1 = y * dS - dF * ib
            J2 = 0.5 * (y * dF - s * F0 + h2 * dS * ib)
        Pu, Pn, Bu, Bn = self.Pu[i], self.Pn[i], self.Bu[i], self.Bn[i]
        dVu, dVn = Pu * dS + Bu * dF, Pn * dS + Bn * dF
        dXu, dXn = Pu * J1 + Bu * J2, Pn * J1 + Bn * J2
        if self.any_series:
            ser = s < self.s_series[i]
            if np.any(ser):
                k0u, k0n, k1u, k1n, k2u, k2n, k3u, k3n = (a[i] for a in self.k)
                dVu = np.where(ser, s * (k0u + s * (0.5 * k1u + s * (k2u / 3.0 + 0.25 * s * k3u))), dVu)
                dVn = np.where(ser, s * (k0n + s * (0.5 * k1n + s * (k2n / 3.0 + 0.25 * s * k3n))), dVn)
                ss = s * s
                dXu = np.where(ser, ss * (0.5 * k0u + s * (k1u / 6.0 + s * (k2u / 12.0 + s * k3u / 20.0))), dXu)
                dXn = np.where(ser, ss * (0.5 * k0n + s * (k1n / 6.0 + s * (k2n / 12.0 + s * k3n / 20.0))), dXn)
        return dVu, dVn, dXu, dXn


def _drag_offsets(W0u, W0n, Bu, Bn, a_d, s):
    """`_DragLine` in one call: (dVu, dVn, dXu, dXn) after a time s of drag (broadcasting)."""
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (W0u, W0n, Bu, Bn, a_d, s)))
    shape = arrays[0].shape
    W0u, W0n, Bu, Bn, a_d, s = (np.ravel(a) for a in arrays)
    return tuple(np.reshape(r, shape) for r in _DragLine(W0u, W0n, Bu, Bn, a_d).at(s))


def _newton_in_bracket(fun, lo, hi, t, max_iter=6):
    """Newton steps on all elements at once, kept inside [lo, hi] (bisection otherwise).

    fun(t) -> (f, f') for an increasing f with f(lo) < 0 <= f(hi). An element has
    converged once its step is below 1e-8 t; it then takes that last step (in the
    quadratic regime the error is ~ step^2). Returns (t, converged).
    """
    lo, hi = lo.copy(), hi.copy()
    t = np.where((t > lo) & (t < hi), t, 0.5 * (lo + hi))
    conv = np.zeros(t.shape, dtype=bool)
    for _ in range(max_iter):
        f, fp = fun(t)
        neg = f < 0.0
        lo = np.where(neg, t, lo)
        hi = np.where(neg, hi, t)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = f / fp
        conv = (fp > 0.0) & (np.abs(step) <= 1e-8 * t)
        tn = t - step
        tn = np.where(np.isfinite(tn) & (tn > lo) & (tn < hi) & (fp > 0.0), tn, 0.5 * (lo + hi))
        t = np.where(conv, np.clip(t - step, lo, hi), tn)
        if np.all(conv):
            break
    return t, conv


def _flight(Om, x0, v0, w, R, x_in, x_tip, recatch=True, n_scan=40, vn0=None, n0=None, drag=None, drag_from=None):
    """Flight off the face: from (x0, n0) with relative velocity (v0, vn0), to the next event.

    All in (u, n) components of the face axes at the start of the flight; time origin
    at the start. n0 (default w, on the face line) >= w; vn0 >= 0 (default 0): speed
    away from the face (a rebound). Machine-frame velocity at the start:
    V = (v0 - Omega n0, Omega x0 + vn0); the path is the straight line X0 + V t, plus
    the first-order disc drag `_drag_offsets` where drag = mu_d g > 0, from drag_from
    (the landing, default 0) on. The face (spinner) axes turn by theta = Omega t, and
    the gap to the face line is, with a = vn0/Omega and k = v0/Omega - n0, on the
    straight line
        d(theta) = (n0 cos th - w) + x0 (th cos th - sin th) + a th cos th - k th sin th
    (plus dXn cos th - dXu sin th with drag). Events, the first one wins:
      0 exit at |c| = R (closed form on the straight line; with drag bracketed between
        0 and multiples of that time, up to 8);
      1 re-catch by the same face, d = 0, as a bracketed Newton solve. A rebound
        (a > 0) is bracketed in closed form: while the granule moves outwards, the
        Coriolis push of that motion bounds the gap by a th - (k + w/2) th^2 - x0 th^3/3,
        whose positive root th_p is the upper end (checked with the drag, else widened
        to 1.25 ... 3 th_p); Newton on d / theta (the root at 0 divided out, nearly
        linear) from there. Other flights, and rebounds whose bracket fails, scan
        d / theta^2 on 40 points up to the exit;
      2 stop (drag only): the drag has used up the velocity relative to the disc,
        W_drag . W_straight = 0; the granule is then at rest on the disc. Searched
        (scan and solve) only where |W_straight| > a_d s (1 + Omega s / 2) fails
        somewhere before the event (the bound on the drag's share).
    Where drag finds no event, the flight is redone without drag ("drag_dropped").
    At a re-catch, "approach" is the relative speed towards the face (normal).
    """
    n = x0.shape[0]
    vn0 = np.zeros(n) if vn0 is None else np.asarray(vn0, dtype=float)
    n0 = w if n0 is None else np.asarray(n0, dtype=float)
    a_d = np.zeros(n) if drag is None else np.array(np.broadcast_to(drag, (n,)), dtype=float)
    s_on = np.zeros(n) if drag_from is None else np.array(np.broadcast_to(drag_from, (n,)), dtype=float)
    if not recatch:  # tip flights stay straight
        a_d[:] = 0.0
    a_n = vn0 / Om
    k = v0 / Om - n0
    Vu, Vn = v0 - Om * n0, Om * x0 + vn0
    Bu, Bn = Om * Vn, -Om * Vu  # relative to the disc: W(t) = W0 + t B, W0 = (v0, vn0)
    Wou, Won = v0 + s_on * Bu, vn0 + s_on * Bn  # W when the drag starts
    XV = x0 * Vu + n0 * Vn
    V2 = Vu * Vu + Vn * Vn
    X2 = x0 * x0 + n0 * n0
    gap = np.maximum(R * R - X2, 0.0)
    root = np.sqrt(XV * XV + V2 * gap)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_exit0 = np.where(XV >= 0, gap / (XV + root), (root - XV) / V2)
    t_exit0 = np.where(np.isfinite(t_exit0), t_exit0, 0.0)
    a_d = np.where(t_exit0 > 0.0, a_d, 0.0)
    has_drag = a_d > 0.0

    line = _DragLine(Wou, Won, Bu, Bn, a_d)

    def offsets(t, i=slice(None)):
        if isinstance(i, tuple):  # (rows, None): a 2-D grid
            sub = i[0]
            return line.at(np.maximum(t - s_on[i], 0.0), i) if np.any(has_drag[sub]) else (0.0, 0.0, 0.0, 0.0)
        if not np.any(has_drag[i]):
            return 0.0, 0.0, 0.0, 0.0
        return line.at(np.maximum(t - s_on[i], 0.0), i)

    def state(t, i=slice(None)):
        """Machine-frame position and velocity (initial face axes) at flight time t."""
        dVu, dVn, dXu, dXn = offsets(t, i)
        return x0[i] + Vu[i] * t + dXu, n0[i] + Vn[i] * t + dXn, Vu[i] + dVu, Vn[i] + dVn

    def gap_fun(th, i):  # -d(theta) and -d'(theta): increasing through a re-catch
        sh = np.sin(0.5 * th)
        s_, cm1 = 2.0 * sh * np.cos(0.5 * th), -2.0 * sh * sh  # sin, cos - 1 without cancellation
        c_ = 1.0 + cm1
        t2 = th * th
        # th - sin th: series below 0.5 (error < 1e-17 relative), direct above
        tms = np.where(th < 0.5, th * t2 * (1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 * (1.0 / 5040.0 - t2 * (
            1.0 / 362880.0 - t2 * (1.0 / 39916800.0 - t2 / 6227020800.0))))), th - s_)
        d = n0[i] * cm1 + (n0[i] - w[i]) + x0[i] * (th * cm1 + tms) - k[i] * th * s_ + a_n[i] * th * c_
        dd = -n0[i] * s_ - x0[i] * th * s_ - k[i] * (s_ + th * c_) + a_n[i] * (c_ - th * s_)
        dVu, dVn, dXu, dXn = offsets(th / Om[i], i)
        d = d + dXn * c_ - dXu * s_
        dd = dd + (dVn * c_ - dVu * s_) / Om[i] - (dXn * s_ + dXu * c_)
        return -d, -dd

    def hop_fun(th, i):  # -d/theta for a rebound (d = 0 at theta = 0 divided out: nearly linear)
        f, fp = gap_fun(th, i)
        return f / th, (fp - f / th) / th

    def out_fun(t, i):  # |X|^2 - R^2 and its derivative
        xu, xn, vu_, vn_ = state(t, i)
        return xu * xu + xn * xn - R[i] ** 2, 2.0 * (xu * vu_ + xn * vn_)

    exit_known = ~has_drag  # drag-free exits are known in closed form; the others when needed
    th_exit = np.where(exit_known, Om * t_exit0, np.inf)  # (not needed after a re-catch inside the rim)

    def drag_exit(sel):
        """Exit angle with drag for the granules `sel` (inf where none within 8 t_exit0).

        Usually the drag moves the exit little: Newton from t_exit0 converges in three
        steps. Otherwise a bracketed solve: [0, t_exit0] or multiples of t_exit0.
        """
        sel = sel[~exit_known[sel]]
        if sel.size == 0:
            return
        exit_known[sel] = True
        # Newton from the drag-free exit (|X|^2 - R^2 rises through the exit); converged once
        # a step is below 1e-8 t (the last step then leaves an error ~ 1e-16 t)
        t = t_exit0[sel].copy()
        ok = np.zeros(sel.size, dtype=bool)
        for _ in range(4):
            f, fp = out_fun(t, sel)
            step = f / np.where(fp > 0.0, fp, np.nan)
            ok = np.abs(step) <= 1e-8 * t
            t = t - step
            if np.all(ok):
                break
        ok &= np.isfinite(t) & (t > 0.0)
        th_exit[sel[ok]] = Om[sel[ok]] * t[ok]
        sel = sel[~ok]
        if sel.size == 0:
            return
        hi = t_exit0[sel]
        f_hi, fp_hi = out_fun(hi, sel)
        lo, f_lo = np.zeros(sel.size), X2[sel] - R[sel] ** 2
        far = np.nonzero(f_hi < 0.0)[0]
        if far.size:  # slowed down by the drag: look further
            j = sel[far]
            grid = t_exit0[j, None] * _EXIT_MULTIPLES[None, 1:]
            f, fp = out_fun(grid, (j, None))
            out = f >= 0.0
            first = np.argmax(out, axis=1)
            found = out[np.arange(j.size), first]
            rows = np.arange(j.size)
            hi[far] = np.where(found, grid[rows, first], np.inf)
            f_hi[far], fp_hi[far] = f[rows, first], fp[rows, first]
            prev = np.maximum(first - 1, 0)
            lo[far] = np.where(first > 0, grid[rows, prev], t_exit0[j])
            f_lo[far] = np.where(first > 0, f[rows, prev], f_hi[far] * 0.0 - 1.0)
            th_exit[j[~found]] = np.inf
        got = np.nonzero(np.isfinite(hi))[0]
        if got.size:
            j = sel[got]
            guess = hi[got] - f_hi[got] / np.where(fp_hi[got] > 0.0, fp_hi[got], np.inf)  # Newton from the upper end
            th_exit[j] = Om[j] * solve_increasing(lambda t, i: out_fun(t, j[i]), lo[got], hi[got], f_lo[got],
                                                  f_hi[got], guess=guess, polish=True)

    th_catch = np.full(n, np.inf)
    slow = np.zeros(n, dtype=bool)
    cached = np.zeros(0, dtype=np.intp)  # state at the re-catch already known for these
    if recatch and n:
        slow[:] = True
        # --- rebounds: closed-form bracket from the bound on the gap ---
        fast = np.nonzero((vn0 > 0.0) & (n0 == w) & (x0 > 0.0))[0]
        if fast.size:
            A, Bq, a = x0[fast] / 3.0, k[fast] + 0.5 * w[fast], a_n[fast]
            th_p = 2.0 * a / (Bq + np.sqrt(Bq * Bq + 4.0 * A * a))
            lo = 1e-6 * th_p
            f_lo = -a  # d / theta = a at theta = 0
            f_hi, fp_hi = hop_fun(th_p, slice(None) if fast.size == n else fast)
            hi = np.where(f_hi >= 0.0, th_p, np.nan)
            todo = np.nonzero(f_hi < 0.0)[0]  # the drag can move the re-catch past the bound: widen
            for m in _CATCH_STEPS:
                if todo.size == 0:
                    break
                cand = m * th_p[todo]
                f, fp = hop_fun(cand, fast[todo])
                got = f >= 0.0
                hi[todo[got]] = cand[got]
                f_hi[todo[got]] = f[got]
                fp_hi[todo[got]] = fp[got]
                todo = todo[~got]
            ok = np.isfinite(hi) & (f_lo < 0.0) & (th_p > 0.0)
            fo = fast[ok]
            guess = hi[ok] - f_hi[ok] / np.where(fp_hi[ok] > 0.0, fp_hi[ok], np.inf)  # Newton from the upper end
            sub = slice(None) if fo.size == n else fo
            th0, conv = _newton_in_bracket(lambda th: hop_fun(th, sub), lo[ok], hi[ok], guess)
            th_catch[fo] = th0
            if not np.all(conv):
                fc = fo[~conv]
                th_catch[fc] = solve_increasing(lambda th, i: hop_fun(th, fc[i]), lo[ok][~conv], hi[ok][~conv],
                                                f_lo[ok][~conv], f_hi[ok][~conv], polish=True)
            slow[fo] = False
            # the exit first? (the straight path leaves the disc once; beyond the tip: no re-catch)
            cached = fo
            cache = state(th_catch[fo] / Om[fo], fo)
            Xu, Xn = cache[0], cache[1]
            cth = th_catch[fo]
            xc = Xu * np.cos(cth) + Xn * np.sin(cth)
            gone = (Xu * Xu + Xn * Xn >= R[fo] ** 2) | (xc > x_tip[fo])
            th_catch[fo[gone]] = np.inf
            drag_exit(np.concatenate([fo[gone], np.nonzero(slow)[0]]))
        # --- everything else: scan d / theta^2 up to the exit ---
        sl = np.nonzero(slow)[0]
        if sl.size:
            drag_exit(sl)
            th_h = np.where(np.isfinite(th_exit[sl]), th_exit[sl], Om[sl] * t_exit0[sl] * _EXIT_MULTIPLES[-1])
            scan = th_h[:, None] * np.logspace(-9, 0, n_scan)[None, :]
            c1, c2, c3 = _theta_terms(scan)
            i2 = (sl, None)
            _, _, dXu, dXn = offsets(scan / Om[i2], i2)
            with np.errstate(divide="ignore", invalid="ignore"):
                G = (n0[i2] * c1 + (n0[i2] - w[i2]) / (scan * scan) + x0[i2] * c2 - k[i2] * c3
                     + a_n[i2] * np.cos(scan) / scan + (dXn * np.cos(scan) - dXu * np.sin(scan)) / (scan * scan))
            neg = G <= 0.0
            first = np.argmax(neg, axis=1)
            found = neg[np.arange(sl.size), first]
            i0 = found & (first == 0)
            th_catch[sl[i0]] = scan[i0, 0]
            need = np.nonzero(found & (first > 0))[0]
            if need.size:
                j = sl[need]
                th_catch[j] = solve_increasing(lambda th, i: gap_fun(th, j[i]), scan[need, first[need] - 1],
                                               scan[need, first[need]])
            # a re-catch beyond the tip is none: the face has ended there
            cth = np.where(np.isfinite(th_catch[sl]), th_catch[sl], 0.0)
            Xu, Xn, _, _ = state(cth / Om[sl], sl)
            xc = Xu * np.cos(cth) + Xn * np.sin(cth)
            th_catch[sl[xc > x_tip[sl]]] = np.inf
    drag_exit(np.nonzero(~np.isfinite(th_catch))[0])
    # --- stop: only where the drag could use up the relative velocity before the event ---
    th_stop = np.full(n, np.inf)
    th_ev = np.minimum(th_catch, th_exit)
    jd = np.nonzero(has_drag)[0]
    if jd.size:
        s_ev = np.where(np.isfinite(th_ev[jd]), th_ev[jd], Om[jd] * t_exit0[jd] * _EXIT_MULTIPLES[-1]) / Om[jd]
        b2 = Bu[jd] ** 2 + Bn[jd] ** 2
        s_min = np.clip(-(v0[jd] * Bu[jd] + vn0[jd] * Bn[jd]) / np.where(b2 > 0.0, b2, 1.0), 0.0, s_ev)
        W_min = np.hypot(v0[jd] + s_min * Bu[jd], vn0[jd] + s_min * Bn[jd])
        suspect = W_min <= a_d[jd] * s_ev * (1.0 + 0.5 * Om[jd] * s_ev)
        js = jd[suspect]
        if js.size:
            th_h = Om[js] * s_ev[suspect]
            scan = th_h[:, None] * np.logspace(-9, 0, n_scan)[None, :]

            def stop_fun(th, i):  # -(W_drag . W_straight) and its derivative in theta
                t_ = th / Om[i]
                dVu, dVn, dXu, dXn = offsets(t_, i)
                Wu, Wn = v0[i] + t_ * Bu[i], vn0[i] + t_ * Bn[i]
                Pu, Pn = Wu + dVu + Om[i] * dXn, Wn + dVn - Om[i] * dXu  # W - Omega J dX, J(a, b) = (-b, a)
                F = np.hypot(Wu, Wn)
                ad = np.where(t_ >= s_on[i], a_d[i], 0.0) / np.where(F > 0.0, F, 1.0)
                dPu = Bu[i] - ad * Wu + Om[i] * dVn
                dPn = Bn[i] - ad * Wn - Om[i] * dVu
                phi = Pu * Wu + Pn * Wn
                dphi = dPu * Wu + dPn * Wn + Pu * Bu[i] + Pn * Bn[i]
                return -phi, -dphi / Om[i]

            f, _ = stop_fun(scan, (js, None))
            hit = f >= 0.0
            first = np.argmax(hit, axis=1)
            found = hit[np.arange(js.size), first]
            at0 = found & (first == 0)
            th_stop[js[at0]] = scan[at0, 0]
            need = np.nonzero(found & (first > 0))[0]
            if need.size:
                j = js[need]
                th_stop[j] = solve_increasing(lambda th, i: stop_fun(th, j[i]), scan[need, first[need] - 1],
                                              scan[need, first[need]])
    times = np.stack([th_exit, th_catch, th_stop], axis=1)
    event = np.argmin(times, axis=1)
    th = times[np.arange(n), event]
    lost = ~np.isfinite(th)
    drag_dropped = lost.copy()
    if np.any(lost):  # drag found no event: fly this one straight
        li = np.nonzero(lost)[0]
        sub = _flight(Om[li], x0[li], v0[li], w[li], R[li], x_in[li], x_tip[li], recatch, n_scan, vn0[li], n0[li])
        th[li] = sub["t"] * Om[li]
        event[li] = sub["event"]
        has_drag[li] = False
        line.drop(li)
    c, s = np.cos(th), np.sin(th)
    t = th / Om
    # machine-frame position and velocity, in the face axes turned by theta
    if cached.size:
        Xu, Xn, Wu, Wn = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        reuse = np.zeros(n, dtype=bool)
        reuse[cached] = True
        reuse &= (event == 1) & ~lost
        for arr, val in zip((Xu, Xn, Wu, Wn), cache):
            arr[cached] = val
        other = np.nonzero(~reuse)[0]
        if other.size:
            for arr, val in zip((Xu, Xn, Wu, Wn), state(t[other], other)):
                arr[other] = val
    else:
        Xu, Xn, Wu, Wn = state(t)
    pu, pn = Xu * c + Xn * s, Xn * c - Xu * s
    vu, vn = Wu * c + Wn * s, Wn * c - Wu * s
    rc = event == 1
    xc = pu
    vc = vu + Om * pn  # relative velocity along the face
    hub = rc & (xc < x_in)
    approach = np.where(rc, np.maximum(Om * xc - vn, 0.0), 0.0)  # relative velocity towards the face
    return {
        "t": t, "event": event, "recatch": rc, "x": np.where(hub, x_in, xc), "v": vc, "hub": hub,
        "approach": approach, "pu": pu, "pn": pn, "vu": vu, "vn": vn, "drag_dropped": drag_dropped,
    }
