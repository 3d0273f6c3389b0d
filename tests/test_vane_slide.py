"""Closed forms of motion along one vane (spreadgym.physics.vane_slide) against solve_ivp.

The reference below is written independently of the module: 2-D vectors in the frame
turning with the disc, the constraint force taken from the normal component of the
other forces, friction from the slip vector of the contact point, spin from the
torque; it integrates with DOP853 at rtol 1e-11 and switches phase on events.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from spreadgym.physics import vane_slide as vs
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK

G = 9.81
KAPPA = 0.4
RTOL, ATOL = 1e-11, 1e-15


def _cross_z(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _zx(v):
    """z x v for a plan-view vector."""
    return np.array([-v[1], v[0]])


def vane_vectors(k, count, r_in, pitch, omega):
    """Inner end p, direction u, leading normal n of vane k at spinner angle 0."""
    th = 2 * math.pi * k / count
    sense = math.copysign(1.0, omega)
    p = r_in * np.array([math.cos(th), math.sin(th)])
    a = th + sense * pitch
    u = np.array([math.cos(a), math.sin(a)])
    n = sense * _zx(u)
    return p, u, n


def reference_on_vane(omega, p, u, n, h, r, R, s_tip, mu_v, mu_d_on_disc, rotation, s0, sd0, spin0=0.0,
                      disc_friction_in_flight=False, t_max=5.0, disc_from=0.0):
    """Follow one granule on the leading face from (s0, s'0) until |c| = R.

    Rotating frame, vectors; `spin` is the inertial spin about z (0 when locked).
    Returns dict(outcome, t, c, v_rel, spin, hops, rolled), c and v_rel in the
    spinner frame at the final time; outcome "separated" when N reaches 0 in a
    contact phase (not followed here). disc_from: no disc friction before this time.
    """
    mu_d = mu_d_on_disc if disc_from <= 0.0 else 0.0
    w2 = omega * omega
    locked = rotation == "locked"
    e_cp = _zx(-r * n)  # z x (contact point - centre)

    def c_of(s):
        return p + s * u + h * n

    def disc(v_rel):
        sp = math.hypot(*v_rel)
        return -mu_d * G * v_rel / sp if sp > 0 else np.zeros(2)

    def contact(s, sd, m_sign=None):
        # disc friction against the sliding direction (fixed within a phase: the
        # event x' = 0 ends the phase, which keeps the integrator off the jump)
        c = c_of(s)
        v_rel = sd * u
        fric = disc(v_rel) if m_sign is None else -mu_d * G * m_sign * u
        a0 = -2.0 * omega * _zx(v_rel) + w2 * c + fric  # all but the vane
        return c, a0, -float(a0 @ n)  # N holds the granule on the face line

    def slip(sd, spin):
        return float((sd * u + ((0.0 if locked else spin) - omega) * e_cp) @ u)

    def stick_force(a_u):
        # keep d(slip)/dt = 0: s'' + spin' (e_cp.u) = 0 with spin' = torque / (kappa r^2)
        if locked:
            return -a_u
        k = _cross_z(-r * n, u) * float(e_cp @ u) / (KAPPA * r * r)
        return -a_u / (1.0 + k)

    def result(outcome, t, c, v_rel, spin):
        return dict(outcome=outcome, t=t, c=c, v_rel=v_rel, spin=0.0 if locked else spin,
                    hops=hops, rolled=rolled)

    t, s, sd, spin = 0.0, s0, sd0, (0.0 if locked else spin0)
    hops, rolled = 0, False
    phase = None  # None: decide from the state
    for _ in range(100):
        c, a0, N = contact(s, sd)
        if math.hypot(*c) >= R:
            return result(DEPARTED, t, c, sd * u, spin)
        if phase is None and N < -1e-9 * w2 * math.hypot(*c):
            y0 = np.concatenate([c, sd * u])

            def f_fl(_, y):
                a = -2.0 * omega * _zx(y[2:]) + w2 * y[:2]
                if disc_friction_in_flight:
                    a = a + disc(y[2:])
                return np.concatenate([y[2:], a])

            def ev_face(_, y):
                return float((y[:2] - p) @ n) - h

            def ev_rim(_, y):
                return math.hypot(y[0], y[1]) - R

            ev_face.terminal, ev_face.direction = True, -1
            ev_rim.terminal, ev_rim.direction = True, 1
            sol = solve_ivp(f_fl, (0.0, t_max), y0, method="DOP853", rtol=RTOL, atol=ATOL,
                            events=[ev_face, ev_rim])
            y = sol.y[:, -1]
            t += sol.t[-1]
            if sol.t_events[1].size or not sol.t_events[0].size:
                return result(DEPARTED, t, y[:2], y[2:], spin)
            hops += 1
            s, sd = float((y[:2] - p) @ u), float(y[2:] @ u)  # plastic re-catch
            continue
        if phase is None:
            sl = slip(sd, spin)
            phase = ("slide", math.copysign(1.0, sl)) if sl != 0.0 else ("check",)
        if phase[0] == "check":
            f = stick_force(float(a0 @ u))
            phase = ("stick",) if abs(f) <= mu_v * N else ("slide", math.copysign(1.0, -f))
        m_sign = math.copysign(1.0, sd)
        mode, eps = phase[0], (phase[1] if phase[0] == "slide" else 0.0)

        def vane_force(a_u, N, mode=mode, eps=eps):
            return -eps * mu_v * N if mode == "slide" else stick_force(a_u)

        def rhs(_, y, m_sign=m_sign):
            c, a0, N = contact(y[0], y[1], m_sign)
            fv = vane_force(float(a0 @ u), N)
            spin_d = 0.0 if locked else _cross_z(-r * n, fv * u) / (KAPPA * r * r)
            return [y[1], float(a0 @ u) + fv, spin_d]

        def ev_rim(_, y):
            return math.hypot(*c_of(y[0])) - R

        def ev_tip(_, y):
            return y[0] - s_tip

        def ev_N(_, y, m_sign=m_sign):
            return contact(y[0], y[1], m_sign)[2]

        def ev_rest(_, y):
            return y[1]

        def ev_slip(_, y, mode=mode):
            return slip(y[1], y[2]) if mode == "slide" else 1.0

        def ev_limit(_, y, mode=mode, m_sign=m_sign):
            if mode != "stick":
                return -1.0
            c, a0, N = contact(y[0], y[1], m_sign)
            return abs(stick_force(float(a0 @ u))) - mu_v * N

        def ev_land(t_local, _, t0=t, on=mu_d == mu_d_on_disc):
            return -1.0 if on else t0 + t_local - disc_from

        events = [ev_rim, ev_tip, ev_N, ev_rest, ev_slip, ev_limit, ev_land]
        for e, d in zip(events, (1, 1, -1, -m_sign, -eps if eps else 0, 1, 1)):
            e.terminal, e.direction = True, d
        sol = solve_ivp(rhs, (0.0, t_max), [s, sd, spin], method="DOP853", rtol=RTOL, atol=ATOL,
                        events=events)
        y = sol.y[:, -1]
        t += sol.t[-1]
        s, sd, spin = float(y[0]), float(y[1]), float(y[2])
        rolled |= mode == "stick"
        hit = [i for i, te in enumerate(sol.t_events) if te.size]
        assert hit, "reference: no event before t_max"
        k = hit[0]
        if k == 0:
            return result(DEPARTED, t, c_of(s), sd * u, spin)
        if k == 1:  # off the tip: straight line in the machine frame to the rim
            c = c_of(s)
            V = sd * u + omega * _zx(c)
            a, b, cc = V @ V, 2 * c @ V, c @ c - R * R
            tau = (-b + math.sqrt(b * b - 4 * a * cc)) / (2 * a)
            X = c + V * tau
            ang = -omega * tau
            rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
            Xs, Vs = rot @ X, rot @ V
            return result(DEPARTED, t + tau, Xs, Vs - omega * _zx(Xs), spin)
        if k == 2:
            return result("separated", t, c_of(s), sd * u, spin)
        if k == 3:  # at rest on the face: static disc friction against the rest
            c = c_of(s)
            a_rest = w2 * c  # no Coriolis at rest
            N = -float(a_rest @ n)
            if N < 0:
                return result("separated", t, c, np.zeros(2), spin)
            sl = slip(0.0, spin)
            pull = float(a_rest @ u) - math.copysign(mu_v * N, sl) * (sl != 0.0)
            if pull <= mu_d * G:
                return result(RETAINED_STUCK, t, c, np.zeros(2), spin)
            sd, phase = 0.0, None
            continue
        if k == 4:
            if not locked:  # exact no-slip spin
                spin = omega - sd / float(e_cp @ u)
            phase = ("check",)
            continue
        if k == 5:
            c, a0, N = contact(s, sd)
            phase = ("slide", math.copysign(1.0, -stick_force(float(a0 @ u))))
            continue
        if k == 6:  # lands on the disc: disc friction from now on
            mu_d = mu_d_on_disc
            t = disc_from
            phase = ("check",) if mode == "stick" else phase
            continue
    raise AssertionError("reference: too many phases")


# --- a case on one vane: the geometry of the scenes, set up independently -------------------


def vane_case(rpm, pitch_deg, mu_v, mu_d, sense, rotation, rho=0.043, r_in=0.025, R=0.15, thickness=0.005,
              r=0.0015, k=1, count=4):
    """Granule caught at radius rho by vane k (at rest in the machine frame before)."""
    omega = sense * rpm * 2 * math.pi / 60
    p, u, n = vane_vectors(k, count, r_in, math.radians(pitch_deg), omega)
    h = thickness / 2 + r
    w = float(p @ n) + h
    x0 = math.sqrt(rho * rho - w * w)
    s0 = x0 - float(p @ u)
    c = p + s0 * u + h * n
    sd0 = float((-omega * _zx(c)) @ u)  # plastic catch keeps the along-vane part
    b = float(p @ u)
    s_tip = -b + math.sqrt(b * b + R * R - r_in * r_in)
    return dict(omega=omega, p=p, u=u, n=n, h=h, w=w, x0=x0, s0=s0, sd0=sd0, s_tip=s_tip, R=R, r=r,
                mu_v=mu_v, mu_d=mu_d, rotation=rotation, x_in=b, x_tip=math.sqrt(R * R - float(p @ n) ** 2))


def run_both(case, spin0=None, phi0=None):
    ref = reference_on_vane(case["omega"], case["p"], case["u"], case["n"], case["h"], case["r"], case["R"],
                            case["s_tip"], case["mu_v"], case["mu_d"], case["rotation"], case["s0"], case["sd0"],
                            spin0=0.0 if spin0 is None else spin0)
    res = vs.run_along_vane(abs(case["omega"]), case["x0"], case["sd0"], case["w"], case["x_in"], case["x_tip"],
                            case["R"], case["mu_v"], case["mu_d"], case["r"], rotation=case["rotation"],
                            spin_offset0=phi0)
    return ref, res


def departure_speed_ref(case, ref):
    return float(np.hypot(*(ref["v_rel"] + case["omega"] * _zx(ref["c"]))))


def model_spin(case, res):
    if case["rotation"] == "locked":
        return 0.0
    sense = math.copysign(1.0, case["omega"])
    return case["omega"] + sense * float(res.spin_offset[0]) / case["r"]


def _sweep_cases(count, seed):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield dict(rpm=rng.uniform(200, 1100), pitch_deg=rng.uniform(-30, 30), mu_v=rng.uniform(0, 0.6),
                   mu_d=rng.uniform(0, 0.6), sense=float(rng.choice([-1.0, 1.0])),
                   rotation=str(rng.choice(["free", "locked"])), rho=rng.uniform(0.026, 0.12))


# --- the building blocks ---------------------------------------------------------------------


@pytest.mark.parametrize("mu", [0.0, 0.2, 0.52, 1.0])
def test_sliding_roots_are_the_classic_ones(mu):
    om = 80.0
    l1, l2 = vs.sliding_roots(om, mu)
    assert l1 == pytest.approx(om * (-mu + math.sqrt(1 + mu * mu)), rel=1e-14)
    assert l2 == pytest.approx(om * (-mu - math.sqrt(1 + mu * mu)), rel=1e-14)
    A, B, C = vs.slide_coefficients(om, mu, 0.3, 0.004)
    mot = vs.LinearMotion.solve(A, B, C, 0.05, 0.3)
    assert mot.l1 == pytest.approx(l1, rel=1e-13) and mot.l2 == pytest.approx(l2, rel=1e-13)
    r1, r2 = vs.rolling_roots(om)
    assert r1 == pytest.approx(om * math.sqrt(5 / 7), rel=1e-14) and r2 == -r1


@pytest.mark.parametrize("mu_v, mu_d, w", [(0.0, 0.0, 0.004), (0.3, 0.5, 0.004), (0.6, 0.1, -0.008)])
def test_sliding_closed_form_solves_the_sliding_equation(mu_v, mu_d, w):
    """s'' + 2 mu_v W s' - W^2 s = W^2 (p.u) - mu_d g + mu_v W^2 (c.n), integrated by solve_ivp."""
    om, pu, s0, sd0 = 70.0, 0.025, 0.02, 0.4
    A, B, C = vs.slide_coefficients(om, mu_v, mu_d, w)
    mot = vs.LinearMotion.solve(A, B, C, pu + s0, sd0)  # x = s + p.u

    def rhs(_, y):
        return [y[1], -2 * mu_v * om * y[1] + om * om * y[0] + om * om * pu - mu_d * G + mu_v * om * om * w]

    t = np.linspace(0, 0.05, 11)
    sol = solve_ivp(rhs, (0, 0.05), [s0, sd0], method="DOP853", rtol=RTOL, atol=ATOL, t_eval=t)
    np.testing.assert_allclose(mot.x(t) - pu, sol.y[0], rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(mot.v(t), sol.y[1], rtol=1e-9, atol=1e-12)
    # normal force of the closed form
    np.testing.assert_allclose(vs.normal_force(om, mot.v(t), w), 2 * om * sol.y[1] - om * om * w, rtol=1e-9)


def test_slide_and_roll_motion_in_distance_along_the_vane():
    om, pu, w = 60.0, 0.025, 0.004
    mot = vs.slide_motion(om, 0.4, 0.3, pu, w, 0.02, 0.3)
    t = mot.time_to_reach(0.1 + pu)
    assert mot.x(t) - pu == pytest.approx(0.1, rel=1e-13)

    def rhs(_, y):  # the brief's form, in s
        return [y[1], -2 * 0.4 * om * y[1] + om * om * y[0] + om * om * pu - 0.3 * G + 0.4 * om * om * w]

    sol = solve_ivp(rhs, (0, t), [0.02, 0.3], method="DOP853", rtol=RTOL, atol=ATOL)
    assert sol.y[0, -1] == pytest.approx(0.1, rel=1e-9)
    roll = vs.roll_motion(om, 0.3, pu, 0.02, 0.3)
    # (1 + 2/5) s'' = W^2 (s + p.u) - mu_d g
    tt = np.array([0.0, 0.01, 0.02])
    np.testing.assert_allclose(1.4 * roll.acceleration(tt), om * om * roll.x(tt) - 0.3 * G, rtol=1e-12)


def test_time_to_reach_inverts_the_closed_form():
    om = np.array([30.0, 80.0, 115.0, 50.0])
    A, B, C = vs.slide_coefficients(om, np.array([0.0, 0.3, 0.6, 0.1]), np.array([0.0, 0.5, 0.2, 0.6]), 0.004)
    mot = vs.LinearMotion.solve(A, B, C, np.array([0.03, 0.04, 0.05, 0.1]), np.array([0.1, 0.2, 0.3, 0.4]))
    X = np.array([0.15, 0.15, 1.0, 0.2])
    t = mot.time_to_reach(X)
    assert np.all(np.isfinite(t)) and np.all(t > 0)
    np.testing.assert_allclose(mot.x(t), X, rtol=1e-13)


def test_first_root_finds_the_first_of_several():
    # F(t) = b0 + b1 t + g1 expm1(l1 t) + g2 expm1(l2 t) with two or three roots
    rng = np.random.default_rng(4)
    n = 300
    ev = vs.EventFunction(F0=-rng.uniform(0.01, 1, n), b1=rng.uniform(-30, 30, n), g1=rng.uniform(-1, 1, n),
                          g2=rng.uniform(-3, 3, n), l1=rng.uniform(1, 10, n), l2=-rng.uniform(1, 10, n))
    T = np.full(n, 1.5)
    t = ev.first_root(T)
    grid = np.linspace(0, 1.5, 200001)
    for i in range(n):
        f, _ = ev(grid, np.full(grid.size, i))
        pos = np.nonzero(f >= 0)[0]
        if pos.size == 0:
            assert t[i] == np.inf
        else:
            assert abs(t[i] - grid[pos[0]]) <= 2 * (grid[1] - grid[0])
            assert abs(ev(np.array([t[i]]), np.array([i]))[0][0]) < 1e-9


# --- the whole vane against the reference ----------------------------------------------------

SWEEP = list(_sweep_cases(60, seed=11))


@pytest.mark.parametrize("params", SWEEP, ids=[f"case{i}" for i in range(len(SWEEP))])
def test_departure_matches_reference(params):
    """rpm 200-1100, pitch -30..30 deg, mu_v, mu_d 0-0.6, both senses, free and locked."""
    case = vane_case(**params)
    ref, res = run_both(case)
    assert ref["outcome"] == DEPARTED and res.outcome[0] == DEPARTED
    speed_ref = departure_speed_ref(case, ref)
    speed = float(np.hypot(res.vel_u[0], res.vel_n[0]))
    assert speed == pytest.approx(speed_ref, rel=1e-9)
    assert res.t_s[0] == pytest.approx(ref["t"], rel=1e-9)
    # position on the rim and direction of the velocity relative to the vane
    c, v = ref["c"], ref["v_rel"] + case["omega"] * _zx(ref["c"])
    assert res.pos_u[0] == pytest.approx(float(c @ case["u"]), abs=1e-10)
    assert res.pos_n[0] == pytest.approx(float(c @ case["n"]), abs=1e-10)
    assert res.vel_u[0] == pytest.approx(float(v @ case["u"]), abs=1e-9 * speed_ref)
    assert res.vel_n[0] == pytest.approx(float(v @ case["n"]), abs=1e-9 * speed_ref)
    assert model_spin(case, res) == pytest.approx(ref["spin"], rel=1e-8, abs=1e-6)
    assert int(res.hops[0]) == ref["hops"]
    assert bool(res.stick_time_s[0] > 0) == ref["rolled"]
    # the normal force never goes negative in a contact phase (the granule hops instead)
    assert res.min_normal_force[0] >= -1e-6 * case["omega"] ** 2 * case["R"]


def test_sweep_accuracy_summary():
    """Largest relative error in departure speed over the sweep (printed with -s)."""
    worst = 0.0
    for params in SWEEP:
        case = vane_case(**params)
        ref, res = run_both(case)
        speed_ref = departure_speed_ref(case, ref)
        worst = max(worst, abs(float(np.hypot(res.vel_u[0], res.vel_n[0])) / speed_ref - 1.0))
    print(f"\nvane_slide vs solve_ivp: max relative departure-speed error {worst:.2e} over {len(SWEEP)} cases")
    assert worst < 1e-9


def test_vectorised_run_equals_one_by_one():
    cases = [vane_case(**p) for p in SWEEP[:20]]
    one = [run_both(c)[1] for c in cases]
    rot = "free"
    cases_f = [c for c in cases if c["rotation"] == rot]
    res = vs.run_along_vane(
        [abs(c["omega"]) for c in cases_f], [c["x0"] for c in cases_f], [c["sd0"] for c in cases_f],
        [c["w"] for c in cases_f], [c["x_in"] for c in cases_f], [c["x_tip"] for c in cases_f],
        [c["R"] for c in cases_f], [c["mu_v"] for c in cases_f], [c["mu_d"] for c in cases_f],
        [c["r"] for c in cases_f], rotation=rot)
    single = [o for c, o in zip(cases, one) if c["rotation"] == rot]
    np.testing.assert_array_equal(res.t_s, [s.t_s[0] for s in single])
    np.testing.assert_array_equal(res.vel_u, [s.vel_u[0] for s in single])


@pytest.mark.parametrize("sense", [1.0, -1.0])
@pytest.mark.parametrize("mu", [0.12, 0.15, 0.16])
def test_rolling_breaks_into_sliding_like_the_reference(sense, mu):
    """Start rolling fast: rolling needs (2/7) G <= mu N, which tends to mu >= 0.169."""
    case = vane_case(800, 0.0, mu, 0.2, sense, "free", rho=0.05, R=0.15)
    om = abs(case["omega"])
    case["sd0"] = om * case["x0"]
    phi0 = -case["sd0"]  # no slip at the start
    spin0 = case["omega"] + sense * phi0 / case["r"]
    ref, res = run_both(case, spin0=spin0, phi0=phi0)
    assert bool(res.stick_breaks[0] > 0) == ref["rolled"]
    assert float(np.hypot(res.vel_u[0], res.vel_n[0])) == pytest.approx(departure_speed_ref(case, ref), rel=1e-9)
    assert model_spin(case, res) == pytest.approx(ref["spin"], rel=1e-8)


@pytest.mark.parametrize("rotation", ["free", "locked"])
@pytest.mark.parametrize("mu_v, rho", [(0.3, 0.012), (0.0, 0.0125)])
def test_granule_stopped_by_disc_friction_is_stuck(rotation, mu_v, rho):
    """200 rpm, mu_d 0.6, forward pitch: it hops, slows down and stops."""
    case = vane_case(200, 30.0, mu_v, 0.6, 1.0, rotation, rho=rho, r_in=0.01)
    ref, res = run_both(case)
    assert ref["outcome"] == RETAINED_STUCK
    assert res.outcome[0] == RETAINED_STUCK
    assert res.t_s[0] == pytest.approx(ref["t"], rel=1e-9)
    assert res.pos_u[0] == pytest.approx(float(ref["c"] @ case["u"]), abs=1e-10)


def test_frictionless_free_equals_locked():
    case = vane_case(650, 10.0, 0.0, 0.3, -1.0, "free")
    _, free = run_both(case)
    case["rotation"] = "locked"
    _, locked = run_both(case)
    assert free.vel_u[0] == pytest.approx(locked.vel_u[0], rel=1e-12)
    assert free.t_s[0] == pytest.approx(locked.t_s[0], rel=1e-12)


def test_short_vane_leaves_at_the_tip_and_flies_straight():
    case = vane_case(500, 0.0, 0.3, 0.3, 1.0, "free", R=0.15)
    case["x_tip"] = 0.1  # the vane ends well inside the disc
    ref_s_tip = case["x_tip"] - case["x_in"]
    ref = reference_on_vane(case["omega"], case["p"], case["u"], case["n"], case["h"], case["r"], case["R"],
                            ref_s_tip, case["mu_v"], case["mu_d"], "free", case["s0"], case["sd0"])
    res = vs.run_along_vane(abs(case["omega"]), case["x0"], case["sd0"], case["w"], case["x_in"], case["x_tip"],
                            case["R"], case["mu_v"], case["mu_d"], case["r"], rotation="free")
    assert res.left_at_tip[0]
    assert np.hypot(res.pos_u[0], res.pos_n[0]) == pytest.approx(case["R"], rel=1e-12)
    assert float(np.hypot(res.vel_u[0], res.vel_n[0])) == pytest.approx(departure_speed_ref(case, ref), rel=1e-9)
    assert res.t_s[0] == pytest.approx(ref["t"], rel=1e-9)


@pytest.mark.parametrize("rotation", ["free", "locked"])
@pytest.mark.parametrize("delay", [0.002, 0.01])
def test_disc_friction_from_landing_like_the_reference(rotation, delay):
    """A granule caught while still falling feels the disc only once it lands."""
    case = vane_case(600, 0.0, 0.5, 0.5, 1.0, rotation, rho=0.045)
    ref = reference_on_vane(case["omega"], case["p"], case["u"], case["n"], case["h"], case["r"], case["R"],
                            case["s_tip"], case["mu_v"], case["mu_d"], rotation, case["s0"], case["sd0"],
                            disc_from=delay)
    res = vs.run_along_vane(abs(case["omega"]), case["x0"], case["sd0"], case["w"], case["x_in"], case["x_tip"],
                            case["R"], case["mu_v"], case["mu_d"], case["r"], rotation=rotation,
                            disc_contact_from_s=delay)
    assert float(np.hypot(res.vel_u[0], res.vel_n[0])) == pytest.approx(departure_speed_ref(case, ref), rel=1e-9)
    assert res.t_s[0] == pytest.approx(ref["t"], rel=1e-9)
    never = vs.run_along_vane(abs(case["omega"]), case["x0"], case["sd0"], case["w"], case["x_in"],
                              case["x_tip"], case["R"], case["mu_v"], 0.0, case["r"], rotation=rotation)
    late = vs.run_along_vane(abs(case["omega"]), case["x0"], case["sd0"], case["w"], case["x_in"], case["x_tip"],
                             case["R"], case["mu_v"], case["mu_d"], case["r"], rotation=rotation,
                             disc_contact_from_s=10.0)
    assert late.t_s[0] == never.t_s[0] and late.vel_u[0] == never.vel_u[0]
