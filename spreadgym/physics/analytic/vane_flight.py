"""Flights off a vane face, in closed form: straight lines in the machine frame.

A granule leaves the face when the normal force would turn negative (a hop) or after
a rebound. It then moves in a straight line in the machine frame, plus the disc's
drag to first order if asked (`DragLine`), until the face catches it again, it
crosses the disc rim, or the drag has used up its velocity relative to the disc.
Everything is in the face's (u, n) components at the start of the flight (see
`vane_slide` for the frame); time origin at the start of the flight.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from spreadgym.physics.analytic.motions import Face
from spreadgym.physics.analytic.roots import newton_in_bracket, solve_increasing

N_SCAN = 40  # points of the scan for the first re-catch of flights without a closed-form bracket
_DRAG_SERIES = 1e-4  # b s / |W0| below this: the drag integrals by their Taylor series
_EXIT_MULTIPLES = np.array([1.0, 1.25, 1.6, 2.0, 3.0, 4.5, 8.0])  # of the drag-free exit time, tried with drag
_CATCH_STEPS = (1.25, 1.6, 2.0, 3.0)  # widening of the re-catch bracket with drag



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



class DragLine:
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



@dataclass(frozen=True)
class FlightStart:
    """Where a flight off the face starts, per granule (face axes at the start, SI).

    x0 = c.u; v0: relative velocity along the face; vn0 >= 0: relative speed away from
    the face (a rebound; default 0); n0 = c.n (default the face line w, n0 >= w).
    """

    x0: np.ndarray
    v0: np.ndarray
    vn0: Optional[np.ndarray] = None
    n0: Optional[np.ndarray] = None


@dataclass(frozen=True)
class FlightDrag:
    """First-order disc drag during a flight: deceleration mu_d g (m/s^2) from `from_s` (s) on."""

    accel: np.ndarray
    from_s: np.ndarray


@dataclass(frozen=True)
class FlightEnd:
    """How each flight ends (face axes at the *end* of the flight for pu, pn, vu, vn).

    event: 0 exit at |c| = R, 1 re-catch by the face, 2 at rest on the disc (drag).
    At a re-catch: x, v along the face (x held at the inner end when `hub`) and the
    relative speed `approach` towards the face. drag_dropped: drag found no event.
    """

    t: np.ndarray
    event: np.ndarray
    recatch: np.ndarray
    x: np.ndarray
    v: np.ndarray
    hub: np.ndarray
    approach: np.ndarray
    pu: np.ndarray
    pn: np.ndarray
    vu: np.ndarray
    vn: np.ndarray
    drag_dropped: np.ndarray


def fly_off_face(face: Face, start: FlightStart, recatch: bool = True, drag: Optional[FlightDrag] = None) -> FlightEnd:
    """Flight off the face: from (x0, n0) with relative velocity (v0, vn0), to the next event.

    `recatch` False: past the vane tip, the face cannot catch it (and no drag). All in
    (u, n) components of the face axes at the start of the flight; time origin at the
    start. n0 (default w, on the face line) >= w; vn0 >= 0 (default 0): speed away from
    the face (a rebound). Machine-frame velocity at the start:
    V = (v0 - Omega n0, Omega x0 + vn0); the path is the straight line X0 + V t, plus
    the first-order disc drag `DragLine` where drag.accel = mu_d g > 0, from drag.from_s
    (the landing) on. The face (spinner) axes turn by theta = Omega t, and
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
    Om, w, R, x_in, x_tip = face.omega_abs, face.w, face.disc_radius, face.x_in, face.x_tip
    x0, v0, vn0, n0 = start.x0, start.v0, start.vn0, start.n0
    drag, drag_from = (None, None) if drag is None else (drag.accel, drag.from_s)
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

    line = DragLine(Wou, Won, Bu, Bn, a_d)

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
            th0, conv = newton_in_bracket(lambda th: hop_fun(th, sub), lo[ok], hi[ok], guess)
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
            scan = th_h[:, None] * np.logspace(-9, 0, N_SCAN)[None, :]
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
            scan = th_h[:, None] * np.logspace(-9, 0, N_SCAN)[None, :]

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
        sub = fly_off_face(face.take(li), FlightStart(x0[li], v0[li], vn0[li], n0[li]), recatch)
        th[li] = sub.t * Om[li]
        event[li] = sub.event
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
    return FlightEnd(t=t, event=event, recatch=rc, x=np.where(hub, x_in, xc), v=vc, hub=hub, approach=approach,
                     pu=pu, pn=pn, vu=vu, vn=vn, drag_dropped=drag_dropped)
