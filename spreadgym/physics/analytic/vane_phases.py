"""The phase machine behind `vane_slide.run_along_vane`: rounds of closed-form phases.

Every round advances each granule to the end of its current phase (an impact, a
classification of its state, a static check, a stick check, a flight off the face or
a contact phase) and sets the next one; see `vane_slide` for the physics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spreadgym.physics.analytic.motions import Face, LinearMotion, normal_force, slide_coefficients, stick_coefficients
from spreadgym.physics.analytic.roots import EventFunction
from spreadgym.physics.analytic.vane_flight import FlightDrag, FlightStart, fly_off_face
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, RETAINED_TIMEOUT

# pending actions between phases
_CLASSIFY, _CONTACT, _STATIC, _STICKCHECK, _FLIGHT, _TIPFLIGHT, _DONE, _IMPACT = range(8)


@dataclass
class _Granules:
    """Per-granule constants of a run (arrays (n,))."""

    face: Face
    mu_v: np.ndarray
    mu_r: np.ndarray  # rolling resistance at the vane
    mu_full: np.ndarray  # disc friction once on the disc
    r: np.ndarray
    tlim: np.ndarray
    t_on: np.ndarray  # time the granule lands on the disc
    e_rest: np.ndarray
    x_R: np.ndarray  # x where |c| = R on the face line
    x_end: np.ndarray  # min(x_R, x_tip): the end of contact phases
    tip_first: np.ndarray  # the tip comes before the rim
    t_eps: np.ndarray  # times below this are rounding
    n_tol: np.ndarray  # |N| below this counts as touching


@dataclass
class _State:
    """What changes from phase to phase (arrays (n,))."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    Phi: np.ndarray
    mu_d: np.ndarray  # disc friction in force now
    approach: np.ndarray  # speed towards the face at a pending impact
    sgn_m: np.ndarray  # sgn(x') of the current contact phase
    sgn_e: np.ndarray  # sgn(slip) while sliding
    rho: np.ndarray  # sgn(Phi) the rolling resistance opposes while sliding; 0: held at Phi = 0
    stick: np.ndarray
    action: np.ndarray
    vn_fl: np.ndarray  # relative speed away from the face at the start of a flight (a rebound)
    n_fl: np.ndarray  # c.n at the start of a flight (w: on the face line)
    rebounding: np.ndarray  # the current flight started with a rebound


@dataclass
class _Tally:
    """Final state (u, n components, spinner axes at the final time) and counts."""

    outcome: np.ndarray
    pu: np.ndarray
    pn: np.ndarray
    vu: np.ndarray
    vn: np.ndarray
    hops: np.ndarray
    bounces: np.ndarray
    stops: np.ndarray
    seps: np.ndarray
    hub: np.ndarray
    stick_time: np.ndarray
    breaks: np.ndarray
    at_tip: np.ndarray
    min_N: np.ndarray


class PhaseMachine:
    """The rounds of run_along_vane: every granule advances to the end of its phase."""

    def __init__(self, face: Face, start, friction, options):
        """start, friction, options: vane_slide's CatchState, FaceFriction and VaneOptions."""
        arrays = np.broadcast_arrays(
            *(np.asarray(a, dtype=float) for a in (
                face.omega_abs, start.x0, start.v0, face.w, face.x_in, face.x_tip, face.disc_radius, friction.mu_v,
                friction.mu_d, start.granule_radius, start.time_limit_s, start.disc_contact_from_s,
                start.approach_speed0, friction.restitution, friction.mu_r))
        )
        n = arrays[0].shape[0] if arrays[0].ndim else 1
        Om, x, v, w, x_in, x_tip, R, mu_v, mu_full, r, tlim, t_on, approach, e_rest, mu_r = (
            np.array(np.atleast_1d(a), dtype=float) for a in arrays
        )
        approach = np.maximum(approach, 0.0)
        mu_d = np.where(t_on <= 0.0, mu_full, 0.0)
        self.options = options
        self.locked = options.rotation == "locked"
        if self.locked:
            mu_r = np.zeros_like(mu_r)  # a granule that does not turn feels no rolling resistance
        self.q = 1.0 if self.locked else options.kappa / (1.0 + options.kappa)  # |f| = q |G| while sticking
        Phi = (-r * Om if start.spin_offset0 is None
               else np.array(np.broadcast_to(start.spin_offset0, (n,)), dtype=float))
        if self.locked:
            Phi = -r * Om
        x_R = np.sqrt(np.maximum(R * R - w * w, 0.0))
        x_end = np.minimum(x_R, x_tip)
        self.c = _Granules(
            face=Face(Om, w, x_in, x_tip, R), mu_v=mu_v, mu_r=mu_r, mu_full=mu_full, r=r, tlim=tlim, t_on=t_on,
            e_rest=e_rest,
            x_R=x_R, x_end=x_end, tip_first=x_tip < x_R, t_eps=1e-10 / np.maximum(Om, 1e-300),
            # a rounding-level negative N is not a flight
            n_tol=1e-7 * Om * Om * (np.abs(x_end) + np.abs(w)),
        )
        self.s = _State(
            t=np.zeros(n), x=x, v=v, Phi=Phi, mu_d=mu_d, approach=approach, sgn_m=np.ones(n), sgn_e=np.ones(n),
            rho=np.where(Phi != 0.0, np.sign(Phi), 1.0),
            stick=np.zeros(n, dtype=bool), action=np.where(approach > 0.0, _IMPACT, _CLASSIFY),
            vn_fl=np.zeros(n), n_fl=w.copy(), rebounding=np.zeros(n, dtype=bool),
        )
        self.out = _Tally(
            outcome=np.full(n, RETAINED_TIMEOUT, dtype=np.int8), pu=x.copy(), pn=w.copy(), vu=v - Om * w,
            vn=Om * x, hops=np.zeros(n, dtype=np.int32), bounces=np.zeros(n, dtype=np.int32),
            stops=np.zeros(n, dtype=np.int32), seps=np.zeros(n, dtype=np.int32), hub=np.zeros(n, dtype=bool),
            stick_time=np.zeros(n), breaks=np.zeros(n, dtype=np.int32), at_tip=np.zeros(n, dtype=bool),
            min_N=np.full(n, np.inf),
        )
        self.drag_dropped = 0

    # --- endings -----------------------------------------------------------------------------

    def finish(self, idx, code):
        """End the run of `idx` on the face line with outcome `code`."""
        c, s, out = self.c, self.s, self.out
        Om, w = c.face.omega_abs, c.face.w
        out.outcome[idx] = code
        s.action[idx] = _DONE
        out.pu[idx], out.pn[idx] = s.x[idx], w[idx]
        out.vu[idx], out.vn[idx] = s.v[idx] - Om[idx] * w[idx], Om[idx] * s.x[idx]

    def stuck(self, idx):
        """Held on the disc by static friction."""
        self.s.v[idx] = 0.0
        self.finish(idx, RETAINED_STUCK)
        if not self.locked:
            self.s.Phi[idx] = 0.0  # at rest on the disc the granule ends up turning with it

    def leave_face(self, idx):
        """The face lets go of `idx` (N < 0): a flight from the face line, not a rebound."""
        s = self.s
        self.out.seps[idx] += 1
        s.vn_fl[idx] = 0.0
        s.n_fl[idx] = self.c.face.w[idx]
        s.rebounding[idx] = False
        s.action[idx] = _FLIGHT

    def spin_resistance_sign(self, idx):
        """rho of sliding granules `idx` (sgn_e set): sgn(Phi); at Phi = 0, 0 (held) where the
        rolling resistance can hold the spin against the friction's torque (mu_r >= mu_v > ...
        and mu_r > 0), else the way that torque turns it (-eps)."""
        s, c = self.s, self.c
        Phi, eps = s.Phi[idx], s.sgn_e[idx]
        held = (c.mu_r[idx] > 0.0) & (c.mu_v[idx] <= c.mu_r[idx])
        return np.where(Phi != 0.0, np.sign(Phi), np.where(held, 0.0, -eps))

    # --- the rounds ----------------------------------------------------------------------------

    def run(self):
        """Rounds until every granule is done: (final _State, _Tally, rounds, notes)."""
        s, c, out = self.s, self.c, self.out
        max_rounds = self.options.max_rounds
        rounds = 0
        for rounds in range(1, max_rounds + 1):  # noqa: B007 (the count is reported)
            live = s.action != _DONE
            if not np.any(live):
                break
            s.mu_d[:] = np.where(s.t >= c.t_on, c.mu_full, 0.0)
            for action, step in ((_IMPACT, self.impact), (_CLASSIFY, self.classify), (_STATIC, self.static_check),
                                 (_STICKCHECK, self.stick_check), (_FLIGHT, self.flight),
                                 (_TIPFLIGHT, self.flight), (_CONTACT, self.contact_round)):
                idx = np.nonzero(s.action == action)[0]
                if idx.size:
                    step(idx, action)
        notes: list = []
        if self.drag_dropped:
            notes.append(f"{self.drag_dropped} flight(s) off the face with disc drag reached neither the rim nor "
                         "the face within 8 drag-free exit times: drag dropped for them")
        left = s.action != _DONE
        if np.any(left):
            self.finish(np.nonzero(left)[0], RETAINED_TIMEOUT)
            notes.append(f"{int(left.sum())} granule(s) still changing phase after {max_rounds} rounds: timeout")
        return s, out, rounds, notes

    def impact(self, idx, _action):
        """Impact on the face (the catch, a re-catch): restitution and friction impulses."""
        s, c = self.s, self.c
        Om, x, v, Phi = c.face.omega_abs, s.x, s.v, s.Phi
        a_n, e_i = s.approach[idx], c.e_rest[idx]
        if self.options.impact_friction:
            # per unit mass: normal impulse (1 + e) a_n; the tangential one stops the slip
            # of the contact point at most (it never reverses it), Coulomb-limited
            slip = v[idx] + Phi[idx]
            stop = np.abs(slip) * self.q
            f = -np.sign(slip) * np.minimum(c.mu_v[idx] * (1.0 + e_i) * a_n, stop)
            v[idx] += f
            if not self.locked:
                Phi[idx] += f / self.options.kappa
                most = c.mu_r[idx] * (1.0 + e_i) * a_n / self.options.kappa
                Phi[idx] = np.where(np.abs(Phi[idx]) <= most, 0.0, Phi[idx] - np.sign(Phi[idx]) * most)
        reb = e_i * a_n
        fly = reb > self.options.rebound_stop * Om[idx] * np.abs(x[idx])
        s.vn_fl[idx] = np.where(fly, reb, 0.0)
        s.n_fl[idx] = c.face.w[idx]
        s.rebounding[idx] = fly
        self.out.bounces[idx[fly]] += 1
        s.approach[idx] = 0.0
        s.action[idx] = np.where(fly, _FLIGHT, _CLASSIFY)

    def classify(self, idx, _action):
        """Value-based classification (after a catch, a re-catch)."""
        s, c = self.s, self.c
        x, v, w = s.x, s.v, c.face.w
        N = normal_force(c.face.omega_abs[idx], v[idx], w[idx])
        past = x[idx] >= c.x_end[idx]
        sep = ~past & (N < -c.n_tol[idx])
        rest = ~past & ~sep & (v[idx] == 0.0)
        move = ~past & ~sep & ~rest
        s.action[idx[past]] = np.where(c.tip_first[idx[past]], _TIPFLIGHT, _DONE)
        dep = idx[past & ~c.tip_first[idx]]
        x[dep] = c.x_R[dep]
        self.finish(dep, DEPARTED)
        self.leave_face(idx[sep])
        s.action[idx[rest]] = _STATIC
        mv = idx[move]
        s.sgn_m[mv] = np.sign(v[mv])
        slip = v[mv] + s.Phi[mv]
        s.stick[mv] = False
        s.sgn_e[mv] = np.where(slip != 0.0, np.sign(slip), 1.0)
        s.rho[mv] = self.spin_resistance_sign(mv)
        s.action[mv] = np.where(slip != 0.0, _CONTACT, _STICKCHECK)

    def static_check(self, idx, _action):
        """x' = 0: held by static disc friction, or off again (outwards, or off the face)."""
        s, c = self.s, self.c
        Om, x, w, Phi = c.face.omega_abs, s.x, c.face.w, s.Phi
        s.v[idx] = 0.0
        Ns = -Om[idx] ** 2 * w[idx]
        free_of_face = Ns < 0.0
        pull = Om[idx] ** 2 * x[idx]
        slip = Phi[idx]
        vane_push = np.where(free_of_face, 0.0, -np.sign(slip) * c.mu_v[idx] * Ns)
        pull_total = np.where(free_of_face, Om[idx] ** 2 * np.hypot(x[idx], w[idx]), pull + vane_push)
        hold = pull_total <= s.mu_d[idx] * self.options.g
        self.stuck(idx[hold])
        go = ~hold
        self.leave_face(idx[go & free_of_face])
        on = idx[go & ~free_of_face]
        s.sgn_m[on] = 1.0
        s.stick[on] = False
        s.sgn_e[on] = np.where(Phi[on] != 0.0, np.sign(Phi[on]), 1.0)
        s.rho[on] = self.spin_resistance_sign(on)
        s.action[on] = np.where(Phi[on] != 0.0, _CONTACT, _STICKCHECK)

    def stick_check(self, idx, _action):
        """Slip has reached zero: stick if friction can hold it (with the rolling resistance:
        |kappa G + sgn(x') mu_r N| / (1 + kappa) <= mu_v N)."""
        s, c = self.s, self.c
        Om = c.face.omega_abs
        Gv = Om[idx] ** 2 * s.x[idx] - s.sgn_m[idx] * s.mu_d[idx] * self.options.g
        N = normal_force(Om[idx], s.v[idx], c.face.w[idx])
        ok = np.abs(self.q * Gv + self._rolling_term(idx, N)) <= c.mu_v[idx] * N
        s.stick[idx] = ok
        s.sgn_e[idx] = np.where(ok, s.sgn_e[idx], np.where(Gv >= 0.0, 1.0, -1.0))
        if not self.locked:
            s.Phi[idx] = -s.v[idx]
        s.rho[idx] = self.spin_resistance_sign(idx)
        s.action[idx] = _CONTACT

    def _rolling_term(self, idx, N):
        """sgn(x') mu_r N / (1 + kappa): the rolling resistance's share of the vane friction while rolling."""
        if self.locked:
            return np.zeros_like(N)
        return self.s.sgn_m[idx] * self.c.mu_r[idx] * N / (1.0 + self.options.kappa)

    def flight(self, idx, kind):
        """Flights off the face (closed form): to the rim, a re-catch or rest on the disc."""
        s, c, out = self.s, self.c, self.out
        Om, t = c.face.omega_abs, s.t
        fly = kind == _FLIGHT
        vn0 = s.vn_fl[idx] if fly else np.zeros(idx.size)
        drag = None
        if self.options.flight_drag and fly:
            drag = FlightDrag(c.mu_full[idx] * self.options.g, np.maximum(c.t_on[idx] - t[idx], 0.0))
        fl = fly_off_face(c.face.take(idx), FlightStart(s.x[idx], s.v[idx], vn0, s.n_fl[idx] if fly else None),
                          recatch=fly, drag=drag)
        self.drag_dropped += int(fl.drag_dropped.sum())
        t_new = t[idx] + fl.t
        late = t_new > c.tlim[idx]
        exit_ = (fl.event == 0) & ~late
        ex = idx[exit_]
        t[ex] = t_new[exit_]
        out.pu[ex], out.pn[ex], out.vu[ex], out.vn[ex] = fl.pu[exit_], fl.pn[exit_], fl.vu[exit_], fl.vn[exit_]
        out.outcome[ex] = DEPARTED
        s.action[ex] = _DONE
        if kind == _TIPFLIGHT:
            out.at_tip[ex] = True
        rc = fl.recatch & ~late
        ri = idx[rc]
        t[ri] = t_new[rc]
        s.x[ri], s.v[ri] = fl.x[rc], fl.v[rc]
        out.hub[ri] |= fl.hub[rc]
        out.hops[ri] += ~s.rebounding[ri]
        s.approach[ri] = np.where(fl.hub[rc], 0.0, fl.approach[rc])
        s.action[ri] = _IMPACT
        s.vn_fl[idx] = 0.0
        # the drag used up the velocity relative to the disc: at rest on it, off the face
        sp = (fl.event == 2) & ~late
        si = idx[sp]
        t[si] = t_new[sp]
        cu, cn = fl.pu[sp], fl.pn[sp]
        out.stops[si] += 1
        hold = Om[si] ** 2 * np.hypot(cu, cn) <= c.mu_full[si] * self.options.g
        held = si[hold]
        self.stuck(held)
        out.pu[held], out.pn[held] = cu[hold], cn[hold]
        out.vu[held], out.vn[held] = -Om[held] * cn[hold], Om[held] * cu[hold]
        go = si[~hold]  # the pull wins: a new flight from rest on the disc
        s.x[go], s.n_fl[go], s.v[go] = cu[~hold], cn[~hold], 0.0
        lt = idx[late]
        t[lt] = c.tlim[lt]
        self.finish(lt, RETAINED_TIMEOUT)

    def contact_round(self, idx, _action):
        """Advance every granule of `idx` (in contact) to the end of its current phase."""
        phase = self._phase(idx)
        tau, which = self._first_event(idx, phase)
        self._advance(idx, phase, tau)
        self._transition(idx, which)

    def _phase(self, idx) -> "_Phase":
        """The closed-form motion of the current phase (slide or stick) and its horizon."""
        s, c, g = self.s, self.c, self.options.g
        om, xx, vv, ww = c.face.omega_abs[idx], s.x[idx], s.v[idx], c.face.w[idx]
        sm, se, st = s.sgn_m[idx], s.sgn_e[idx], s.stick[idx]
        mv, md = c.mu_v[idx], s.mu_d[idx]
        As, Bs, Cs = slide_coefficients(om, mv, md, ww, se, sm, g)
        if self.locked:
            Ak, Bk, Ck = np.zeros_like(om), np.zeros_like(om), np.zeros_like(om)
        else:
            Ak, Bk, Ck = stick_coefficients(om, md, sm, self.options.kappa, g, c.mu_r[idx], ww)
        A = np.where(st, Ak, As)
        B = np.where(st, Bk, Bs)
        C = np.where(st, Ck, Cs)
        mot = LinearMotion.solve(A, B, C, xx, vv)
        t_rem = np.maximum(c.tlim[idx] - s.t[idx], 0.0)
        t_rest = mot.time_of_rest()
        # a phase that starts at rest (x' = 0) has a spurious root at t = 0
        t_rest = np.where(t_rest > c.t_eps[idx], t_rest, np.inf)
        t_bound = mot.reach_bound(c.x_end[idx], c.face.x_in[idx])
        T = np.minimum(np.minimum(t_rem, t_bound), t_rest * (1.0 + 1e-12))
        return _Phase(mot=mot, T=T, tmin=np.minimum(c.t_eps[idx], T), t_rem=t_rem, t_rest=t_rest,
                      N0=normal_force(om, vv, ww))

    def _first_event(self, idx, phase: "_Phase"):
        """(time, kind) of the first event that ends the phase of each granule of `idx`."""
        s, c, g, q = self.s, self.c, self.options.g, self.q
        om, xx, vv, ww = c.face.omega_abs[idx], s.x[idx], s.v[idx], c.face.w[idx]
        sm, se, st = s.sgn_m[idx], s.sgn_e[idx], s.stick[idx]
        mv, md = c.mu_v[idx], s.mu_d[idx]
        mot, T, tmin, t_rem, N0 = phase.mot, phase.T, phase.tmin, phase.t_rem, phase.N0
        cand = np.full((idx.size, 10), np.inf)

        def put(col, ev, sel):
            sel = np.nonzero(sel)[0]
            if sel.size:
                cand[sel, col] = ev.take(sel).first_root(T[sel], tmin[sel])

        # 0: rim / tip (outwards) ; 1: inner end (inwards)
        out = sm > 0
        put(0, mot.event(xx - c.x_end[idx], 0.0, 1.0, 0.0), out)
        put(1, mot.event(c.face.x_in[idx] - xx, 0.0, -1.0, 0.0), ~out)
        # 2: x' = 0 (exact)
        cand[:, 2] = phase.t_rest
        # 3: N = 0  (F = -N)
        put(3, mot.event(np.minimum(-N0, 0.0), 0.0, 0.0, -2.0 * om), np.ones(idx.size, dtype=bool))
        if self.locked:
            slip0 = vv - c.r[idx] * om
            # 4: slip = 0 while sliding, F = -eps (x' - r Omega)
            ev = mot.event(-se * slip0, 0.0, 0.0, -se)
        else:
            slip0 = vv + s.Phi[idx]
            # slip(t) = slip0 + dv - k (2 Omega dx - Omega^2 w t), k = (eps mu_v + rho mu_r) / kappa
            ek = se * self._phi_rate(idx)
            ev = mot.event(-se * slip0, -ek * om * om * ww, 2.0 * om * ek, -se)
        held = (s.rho[idx] == 0.0) & (c.mu_r[idx] > 0.0)  # slip = x': its zero is the x' = 0 event (2)
        put(4, ev, ~st & ~held)
        # 5, 6: friction limit while sticking: +-(q G + sgn(x') mu_r N / (1 + kappa)) - mu_v N = 0
        G0 = om * om * xx - sm * md * g
        roll = self._rolling_term(idx, 1.0)
        for col, sign in ((5, 1.0), (6, -1.0)):
            put(col, mot.event(sign * (q * G0 + roll * N0) - mv * N0, 0.0, sign * q * om * om,
                               2.0 * om * (sign * roll - mv)), st)
        cand[:, 7] = np.where(T >= t_rem, t_rem, np.inf)  # time limit
        # 8: the granule lands on the disc (disc friction starts)
        to_land = c.t_on[idx] - s.t[idx]
        cand[:, 8] = np.where((to_land > 0.0) & (to_land <= T), to_land, np.inf)
        # 9: Phi reaches 0 while sliding against the rolling resistance: -rho Phi(t) = 0
        turning = ~st & (s.rho[idx] != 0.0) & (c.mu_r[idx] > 0.0)
        if not self.locked and np.any(turning):
            rk = s.rho[idx] * self._phi_rate(idx)
            put(9, mot.event(-s.rho[idx] * s.Phi[idx], -rk * om * om * ww, 2.0 * om * rk, 0.0), turning)
        which = np.argmin(cand, axis=1)
        tau = cand[np.arange(idx.size), which]
        none = ~np.isfinite(tau)
        # No event before the horizon (should not happen): stop at the horizon, time out.
        return np.where(none, T, tau), np.where(none, 7, which)

    def _phi_rate(self, idx):
        """k of a sliding phase, Phi' = -k N: (eps mu_v + rho mu_r) / kappa (0 while held)."""
        s, c = self.s, self.c
        rate = (s.sgn_e[idx] * c.mu_v[idx] + s.rho[idx] * c.mu_r[idx]) / self.options.kappa
        return np.where((s.rho[idx] == 0.0) & (c.mu_r[idx] > 0.0), 0.0, rate)

    def _advance(self, idx, phase: "_Phase", tau):
        """Move `idx` along its phase by tau; track the smallest normal force met."""
        s, c, out = self.s, self.c, self.out
        om, xx, vv, ww = c.face.omega_abs[idx], s.x[idx], s.v[idx], c.face.w[idx]
        st = s.stick[idx]
        mot = phase.mot
        dx = mot.dx(tau)
        dv = mot.dv(tau)
        x_new = xx + dx
        v_new = vv + dv
        if self.locked:
            Phi_new = s.Phi[idx]
        else:
            Phi_sl = s.Phi[idx] - self._phi_rate(idx) * (2.0 * om * dx - om * om * ww * tau)
            Phi_new = np.where(st, -v_new, Phi_sl)
        # smallest normal force met in this phase (N is a sum of two exponentials: check ends + extremum)
        Nend = normal_force(om, v_new, ww)
        Nmin = np.minimum(phase.N0, Nend)
        acc_zero = mot.event(0.0, 0.0, 0.0, 1.0)  # F' = acceleration
        tz = EventFunction.ratio_time(-acc_zero.g2 * acc_zero.l2, acc_zero.g1 * acc_zero.l1, mot.l1 - mot.l2)
        inside = np.isfinite(tz) & (tz > 0) & (tz < tau)
        if np.any(inside):
            Nz = normal_force(om, mot.v(np.where(inside, tz, 0.0)), ww)
            Nmin = np.where(inside, np.minimum(Nmin, Nz), Nmin)
        out.min_N[idx] = np.minimum(out.min_N[idx], Nmin)
        out.stick_time[idx] += np.where(st, tau, 0.0)
        s.t[idx] = s.t[idx] + tau
        s.x[idx], s.v[idx], s.Phi[idx] = x_new, v_new, Phi_new

    def _transition(self, idx, e):
        """What follows the event `e` that ended each granule's phase."""
        s, c, out = self.s, self.c, self.out
        x, action = s.x, s.action
        i = idx[e == 0]  # rim or tip
        x[i] = c.x_end[i]
        tipf = c.tip_first[i]
        action[i[tipf]] = _TIPFLIGHT
        dep = i[~tipf]
        x[dep] = c.x_R[dep]
        self.finish(dep, DEPARTED)
        i = idx[e == 1]  # inner end, moving inwards: the hub stops it
        x[i] = c.face.x_in[i]
        out.hub[i] = True
        action[i] = _STATIC
        i = idx[e == 2]
        action[i] = _STATIC
        i = idx[e == 3]  # N = 0: the face lets go of a granule that disc friction slows down
        out.seps[i] += 1
        action[i] = _STATIC  # it stops on the disc beside the face (residual x' = Omega w / 2 lost)
        i = idx[e == 4]  # slip = 0
        if not self.locked:
            s.Phi[i] = -s.v[i]
        action[i] = _STICKCHECK
        i = idx[(e == 5) | (e == 6)]  # friction limit: slide in the sense of G
        Gi = c.face.omega_abs[i] ** 2 * x[i] - s.sgn_m[i] * s.mu_d[i] * self.options.g
        out.breaks[i] += 1
        s.stick[i] = False
        s.sgn_e[i] = np.where(Gi >= 0.0, 1.0, -1.0)
        s.rho[i] = self.spin_resistance_sign(i)
        action[i] = _CONTACT
        i = idx[e == 7]
        self.finish(i, RETAINED_TIMEOUT)
        i = idx[e == 9]  # Phi = 0 while sliding: held there, or turned on through 0
        s.Phi[i] = 0.0
        s.rho[i] = self.spin_resistance_sign(i)
        action[i] = _CONTACT
        i = idx[e == 8]  # landed: same motion, now with disc friction; re-check a no-slip phase
        s.t[i] = c.t_on[i]
        action[i] = np.where(s.stick[i], _STICKCHECK, _CONTACT)


@dataclass(frozen=True)
class _Phase:
    """The current phase of the granules of a contact round."""

    mot: LinearMotion
    T: np.ndarray  # horizon: no event can come later
    tmin: np.ndarray
    t_rem: np.ndarray  # time left
    t_rest: np.ndarray  # x' = 0 (inf if never)
    N0: np.ndarray  # normal force at the start
