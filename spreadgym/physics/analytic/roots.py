"""First roots of the event functions of the closed-form motions along a vane.

An event function is F(t) = F0 + b1 t + g1 expm1(l1 t) + g2 expm1(l2 t) (l1 >= 0 >= l2),
element-wise over granules. Its first root is found exactly up to rounding: the zeros
of the derivative split [t_min, horizon] into monotone pieces (closed form when
b1 = 0, otherwise a bracketed solve on the monotone pieces of the derivative), then
a bracketed Newton solve on the first piece that changes sign.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

EXP_MAX = 700.0  # largest exponent evaluated (exp(700) ~ 1e304)
_MAX_ITER = 100  # iterations of solve_increasing (it converges long before)
_RTOL = 1e-14  # relative tolerance of solve_increasing


def solve_increasing(fun: Callable, lo, hi, f_lo=None, f_hi=None, guess=None, polish: bool = False):
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
    for _ in range(_MAX_ITER):
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
        tol = _RTOL * np.maximum(np.abs(ta), 1e-300)
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
        m1 = np.expm1(np.minimum(l1 * t, EXP_MAX))
        m2 = np.expm1(np.minimum(l2 * t, EXP_MAX))
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
            arg = (-F0 - b1 * t - g2 * np.expm1(np.minimum(l2 * t, EXP_MAX))) / g1s
            t = np.log1p(np.maximum(arg, -1.0 + 1e-16)) / l1s
            t = np.clip(t, lo, hi)
        return np.where(grow, t, np.nan)

    def derivative(self, t, idx=slice(None)):
        l1, l2 = self.l1[idx], self.l2[idx]
        e1 = np.exp(np.minimum(l1 * t, EXP_MAX))
        e2 = np.exp(np.minimum(l2 * t, EXP_MAX))
        g1, g2 = self.g1[idx], self.g2[idx]
        return self.b1[idx] + g1 * l1 * e1 + g2 * l2 * e2, g1 * l1 * l1 * e1 + g2 * l2 * l2 * e2

    @staticmethod
    def ratio_time(num, den, span):
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
        z1 = np.where(flat, self.ratio_time(-self.g2 * self.l2, self.g1 * self.l1, span), z1)
        gen = np.nonzero(~flat & (span > 0))[0]
        if gen.size:
            # F'' has at most one zero (closed form); F' is monotone on either side.
            ts = self.ratio_time(-self.g2[gen] * self.l2[gen] ** 2, self.g1[gen] * self.l1[gen] ** 2, span[gen])
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
        T = np.where(np.isfinite(T), T, EXP_MAX / np.maximum(self.l1, 1e-300))
        T = np.minimum(T, EXP_MAX / np.maximum(self.l1, 1e-300))
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


def newton_in_bracket(fun, lo, hi, t, max_iter=6):
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

