"""The `analytic` spinner model against an independent numerical solve, and its invariants."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from test_vane_slide import ATOL, RTOL, G, _zx, reference_on_vane, vane_vectors

from spreadgym.config.scene import load_scene
from spreadgym.physics.analytic.catch import catch_granules
from spreadgym.physics.analytic.spinner import simulate_analytic
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK
from spreadgym.physics.granules import GranuleBatch, rotate
from spreadgym.physics.stepped.pymunk_spinner import simulate_pymunk
from spreadgym.spread.pipeline import departure_summary


def _rot(v, a):
    c, s = math.cos(a), math.sin(a)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def reference_granule(scene, contacts, radius, q, phase):
    """Wait (machine frame, full Coulomb drag of the disc), catch, then the vane.

    q: release point with the spinner at angle 0 at release; drop height 0. The catch
    and every re-catch are impacts with the pair's restitution and Coulomb friction
    (`reference_on_vane`). Disc friction acts during flights off the face with the full
    Coulomb law (the model takes it to first order there).
    """
    omega = scene.spinner.omega_rad_s
    count, r_in = scene.vanes.count, scene.vanes.inner_radius_m
    R, r_out = scene.spinner.radius_m, scene.vane_outer_radius_m
    h = 0.5 * scene.vanes.thickness_m + radius
    mu_v, mu_d = contacts.vane_friction, contacts.disc_friction
    vanes = [vane_vectors(k, count, r_in, scene.vanes.pitches_rad()[k], omega) for k in range(count)]

    def s_tip(p, u):
        b = float(p @ u)
        return -b + math.sqrt(b * b + r_out**2 - r_in**2)

    def drag(_, y):
        rel = omega * _zx(y[:2]) - y[2:]
        sp = math.hypot(*rel)
        return np.concatenate([y[2:], mu_d * G * rel / sp if sp > 0 else np.zeros(2)])

    events = []
    for p, _u, n in vanes:
        def ev(t, y, p=p, n=n):
            return float((_rot(y[:2], -omega * t) - p) @ n) - h

        ev.direction = -1
        events.append(ev)
    # the face line sweeps the point once per revolution per vane: small steps so that no
    # crossing falls between two steps (without drag the solver would take huge ones)
    period = 2 * math.pi / abs(omega)
    sol = solve_ivp(drag, (0.0, 1.5 * period), [q[0], q[1], 0.0, 0.0], method="DOP853", rtol=RTOL, atol=ATOL,
                    events=events, dense_output=True, max_step=0.05 / abs(omega))
    hits = []
    for k, times in enumerate(sol.t_events):
        p, u, _ = vanes[k]
        for tt in times:  # the face line is crossed on the vane itself, not on its extension
            s = float((_rot(sol.sol(tt)[:2], -omega * tt) - p) @ u)
            if 0.0 <= s <= s_tip(p, u):
                hits.append((tt, k))
                break
    t_c, k = min(hits)
    y = sol.sol(t_c)
    p, u, n = vanes[k]
    ys = _rot(y[:2], -omega * t_c)
    v_rel = _rot(y[2:], -omega * t_c) - omega * _zx(ys)
    ref = reference_on_vane(omega, p, u, n, h, radius, R, s_tip(p, u), mu_v, mu_d, scene.granule.rotation,
                            float((ys - p) @ u), float(v_rel @ u), disc_friction_in_flight=True,
                            approach0=-float(v_rel @ n), restitution=contacts.vane_restitution, impact_friction=True)
    T = t_c + ref["t"]
    turn = omega * T + phase
    return dict(outcome=ref["outcome"], t=T, t_catch=t_c, vane=k, pos=_rot(ref["c"], turn),
                vel=_rot(ref["v_rel"] + omega * _zx(ref["c"]), turn), spin=ref["spin"])


def compare_with_reference(scene, prepare, count=8):
    """Max errors (relative speed, direction in degrees, time in s) over `count` granules."""
    granules, contacts = prepare(scene)
    dep = simulate_analytic(scene, granules, contacts)
    catch = catch_granules(scene, granules, contacts)
    q = granules.release_in_spinner_frame()
    errors = []
    for i in range(granules.count):
        if catch.snapped[i] or catch.moved_in[i]:
            continue  # conventions of the model, not physics the reference knows
        ref = reference_granule(scene, contacts, granules.radius_m[i], q[i], granules.phase_rad[i])
        assert ref["outcome"] == DEPARTED and dep.outcome[i] == DEPARTED
        v_ref, v = ref["vel"], dep.velocity_m_s[i]
        turn = math.atan2(v_ref[0] * v[1] - v_ref[1] * v[0], float(v_ref @ v))
        errors.append((abs(dep.speed_m_s[i] / math.hypot(*v_ref) - 1.0), abs(math.degrees(turn)),
                       abs(dep.time_s[i] - ref["t"]), abs(dep.spin_rad_s[i] - ref["spin"]) / max(abs(ref["spin"]), 1)))
        if len(errors) == count:
            break
    assert len(errors) >= 4
    return np.max(np.array(errors), axis=0)


def paper(overrides):
    base = {"feed.drop_height_m": 0.0, "sim.granules": 16, "sim.seed": 1}
    base.update(overrides)
    return load_scene("paper", base)


EXACT_SCENES = [
    {"spinner.rpm": 800, "contact.disc_friction": 0.0},
    {"spinner.rpm": 300, "contact.disc_friction": 0.0, "spinner.direction": "cw", "vanes.pitch_deg": -20.0},
    {"spinner.rpm": 1100, "contact.disc_friction": 0.0, "vanes.pitch_deg": 25.0, "granule.rotation": "locked"},
    {"spinner.rpm": 500, "contact.disc_friction": 0.0, "contact.vane_friction": 0.1, "vanes.count": 3},
]


@pytest.mark.parametrize("restitution", [None, 0.0, 0.8], ids=["e0.43", "e0", "e0.8"])
@pytest.mark.parametrize("overrides", EXACT_SCENES, ids=["800rpm", "cw-pitch-20", "pitch25-locked", "3vanes"])
def test_without_disc_drag_the_model_is_exact(overrides, restitution, prepare):
    """With mu_d = 0 nothing is approximated (drop 0): agreement to rounding.

    The catch and every re-catch are impacts with the pair's restitution (0.43 for the
    paper pair; also 0 and 0.8) and a Coulomb friction impulse, in the model and in
    the reference alike.
    """
    if restitution is not None:
        overrides = dict(overrides, **{"contact.vane_restitution": restitution})
    speed, direction, time, spin = compare_with_reference(paper(overrides), prepare)
    assert speed < 1e-9 and direction < 1e-6 and time < 1e-9 and spin < 1e-8


@pytest.mark.parametrize(
    "overrides, max_speed, max_direction_deg, max_time_s",
    [
        ({"spinner.rpm": 800}, 1e-7, 1e-3, 1e-7),  # paper pair, mu_d = 0.52
        ({"spinner.rpm": 500, "granule.rotation": "locked"}, 1e-6, 1e-2, 1e-6),
        # worst corner: long waits at 200 rpm with strong drag (drift arc up to half a radian)
        ({"spinner.rpm": 200, "contact.disc_friction": 0.6}, 1e-3, 5.0, 5e-3),
        pytest.param({"spinner.rpm": 300, "vanes.pitch_deg": 20.0, "spinner.direction": "cw"}, 1e-3, 2.0, 1.5e-3,
                     marks=pytest.mark.xfail(strict=True, reason=(
                         "known defect: in the QMC sample one granule of 16 leaves 2 m/s and 62 deg off the "
                         "tight solve (first-order drag during hops off a forward-pitched vane); the fast "
                         "model's fidelity is open work"))),
    ],
    ids=["800rpm", "500rpm-locked", "200rpm-mu0.6", "300rpm-pitch20-hops"],
)
def test_with_disc_drag_the_errors_are_small(overrides, max_speed, max_direction_deg, max_time_s, prepare):
    """First-order drag during the wait; first-order drag during hops (forward pitch).

    Plastic catch (e = 0, with its friction impulse): the wait is what is checked here;
    flights after rebounds are in the next test.
    """
    overrides = dict(overrides, **{"contact.vane_restitution": 0.0})
    speed, direction, time, _ = compare_with_reference(paper(overrides), prepare)
    print(f"\n{overrides}: speed {speed:.1e}, direction {direction:.2e} deg, time {time:.1e} s")
    assert speed < max_speed and direction < max_direction_deg and time < max_time_s


@pytest.mark.parametrize(
    "overrides, max_speed, max_direction_deg",
    [
        # 800 rpm: 2e-6 m/s on the earlier draw, 3.2e-6 on the QMC draw: the first-order drag of
        # the bounces leaves micrometres per second on a 15 m/s departure
        ({"spinner.rpm": 800}, 5e-6, 1e-3),
        ({"spinner.rpm": 1100, "vanes.pitch_deg": -15.0}, 2e-6, 1e-3),
        ({"spinner.rpm": 500, "granule.rotation": "locked"}, 1e-4, 1e-2),
        ({"spinner.rpm": 500, "vanes.pitch_deg": -15.0, "granule.rotation": "locked"}, 1e-4, 1e-2),
        ({"spinner.rpm": 200}, 1e-3, 1.0),
        ({"spinner.rpm": 200, "granule.rotation": "locked"}, 1e-3, 1.0),
    ],
    ids=["800rpm", "1100rpm-pitch-15", "500rpm-locked", "500rpm-pitch-15-locked", "200rpm", "200rpm-locked"],
)
def test_bouncing_catch_with_disc_drag_in_flight(overrides, max_speed, max_direction_deg, prepare):
    """Restitution 0.43 (paper pair): the bounces fly with first-order disc drag.

    The reference integrates the full Coulomb drag during the flights. Measured (8
    granules): speed 7e-8..2e-4, direction 1e-5..0.7 deg (200 rpm: the wait's drift
    dominates, as without bounces).
    """
    speed, direction, time, spin = compare_with_reference(paper(overrides), prepare)
    print(f"\n{overrides}: speed {speed:.1e}, direction {direction:.2e} deg, time {time:.1e} s, spin {spin:.1e}")
    assert speed < max_speed and direction < max_direction_deg and time < 2e-3


@pytest.mark.parametrize("mu", [0.0, 0.2, 0.44, 0.6])
def test_departure_angle_tends_to_patterson_and_reece(mu, prepare):
    """Radial vanes, feed near the centre of a large disc: atan(sqrt(1+mu^2) - mu) from the tangent."""
    scene = load_scene("paper", {
        "spinner.radius_m": 1.0, "vanes.inner_radius_m": 0.0, "feed.radius_m": 0.01, "feed.spread_m": 0.0,
        "feed.drop_height_m": 0.0, "granule.rotation": "locked", "contact.vane_friction": mu,
        "contact.disc_friction": 0.0, "sim.granules": 40,
    })
    granules, contacts = prepare(scene)
    dep = simulate_analytic(scene, granules, contacts)
    assert np.all(dep.departed)
    pos, vel = dep.position_m, dep.velocity_m_s
    radial = np.sum(vel * pos, axis=1) / np.hypot(pos[:, 0], pos[:, 1])
    tangential = np.abs(vel[:, 0] * pos[:, 1] - vel[:, 1] * pos[:, 0]) / np.hypot(pos[:, 0], pos[:, 1])
    angle = np.degrees(np.arctan2(radial, tangential))
    expected = math.degrees(math.atan(math.sqrt(1 + mu * mu) - mu))
    assert np.max(np.abs(angle - expected)) < 0.5
    if mu == 0.0:
        assert expected == pytest.approx(45.0)


def _mirror(batch: GranuleBatch) -> GranuleBatch:
    release = batch.release_xy_m * np.array([1.0, -1.0])
    return dataclasses.replace(batch, release_xy_m=release, phase_rad=-batch.phase_rad)


@pytest.mark.parametrize("pitch", [0.0, 15.0, -25.0])
@pytest.mark.parametrize("rotation", ["free", "locked"])
def test_cw_is_the_mirror_image_of_ccw(pitch, rotation, prepare):
    ccw = load_scene("paper", {"spinner.rpm": 700, "vanes.pitch_deg": pitch, "granule.rotation": rotation,
                               "sim.granules": 200})
    cw = load_scene("paper", {"spinner.rpm": 700, "vanes.pitch_deg": pitch, "granule.rotation": rotation,
                              "sim.granules": 200, "spinner.direction": "cw"})
    granules, contacts = prepare(ccw)
    a = simulate_analytic(ccw, granules, contacts)
    b = simulate_analytic(cw, _mirror(granules), contacts)
    flip = np.array([1.0, -1.0])
    np.testing.assert_array_equal(a.outcome, b.outcome)
    np.testing.assert_allclose(b.position_m, a.position_m * flip, atol=1e-12)
    np.testing.assert_allclose(b.velocity_m_s, a.velocity_m_s * flip, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.spin_rad_s, -a.spin_rad_s, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(b.time_s, a.time_s, rtol=1e-12, atol=1e-15)


def test_a_later_phase_departs_turned_by_that_phase(prepare):
    scene = load_scene("paper", {"spinner.rpm": 600, "vanes.pitch_deg": 10.0, "sim.granules": 1,
                                 "feed.spread_m": 0.0})
    granules, contacts = prepare(scene)
    phases = np.linspace(0.0, 2 * math.pi, 9)[:-1] + 0.3
    n = phases.size
    q0 = granules.release_in_spinner_frame()[0]
    batch = GranuleBatch(
        diameter_m=np.full(n, granules.diameter_m[0]), mass_kg=np.full(n, granules.mass_kg[0]),
        density_kg_m3=granules.density_kg_m3, release_xy_m=rotate(np.tile(q0, (n, 1)), phases), phase_rad=phases,
    )
    dep = simulate_analytic(scene, batch, contacts)
    base_pos = rotate(dep.position_m, -phases)
    base_vel = rotate(dep.velocity_m_s, -phases)
    np.testing.assert_allclose(base_pos, np.tile(base_pos[0], (n, 1)), atol=1e-13)
    np.testing.assert_allclose(base_vel, np.tile(base_vel[0], (n, 1)), atol=1e-11)
    np.testing.assert_allclose(dep.time_s, dep.time_s[0], rtol=1e-13)


@pytest.mark.parametrize("rpm", [200.0, 650.0, 1100.0])
@pytest.mark.parametrize("pitch", [-30.0, 0.0, 30.0])
@pytest.mark.parametrize("mu", [0.0, 0.3, 0.6])
def test_no_nan_and_every_granule_accounted_for(rpm, pitch, mu, prepare):
    for rotation in ("free", "locked"):
        for direction in ("ccw", "cw"):
            scene = load_scene("paper", {
                "spinner.rpm": rpm, "vanes.pitch_deg": pitch, "contact.vane_friction": mu,
                "contact.disc_friction": mu, "granule.rotation": rotation, "spinner.direction": direction,
                "sim.granules": 150, "feed.spread_m": 0.02,
            })
            granules, contacts = prepare(scene)
            dep = simulate_analytic(scene, granules, contacts)
            for arr in (dep.position_m, dep.velocity_m_s, dep.spin_rad_s, dep.time_s, dep.height_m):
                assert np.all(np.isfinite(arr))
            assert set(np.unique(dep.outcome)) <= {0, 1, 2}
            assert np.all(dep.departed)  # the paper geometry throws everything at these speeds
            np.testing.assert_allclose(np.hypot(*dep.position_m[dep.departed].T), scene.spinner.radius_m,
                                       rtol=1e-12)
            assert np.all(dep.speed_m_s > 0) and np.all(dep.time_s > 0)


def test_slow_disc_keeps_everything(prepare):
    """Fed at the feed point (no spread): 40 rpm cannot beat disc friction there. (A granule
    released near the rim would rightly be knocked off by the vane's impact.)"""
    scene = load_scene("paper", {"spinner.rpm": 40, "sim.granules": 100, "feed.spread_m": 0.0})
    granules, contacts = prepare(scene)
    dep = simulate_analytic(scene, granules, contacts)
    assert np.all(dep.outcome == RETAINED_STUCK)
    assert np.all(np.isfinite(dep.position_m))


def test_departure_contract(prepare):
    scene = load_scene("paper", {"sim.granules": 50, "feed.drop_height_m": 0.0})
    granules, contacts = prepare(scene)
    dep = simulate_analytic(scene, granules, contacts)
    assert dep.model == "analytic" and dep.dt_s == 0.0 and dep.notes
    assert dep.position_m.shape == (50, 2) and dep.outcome.dtype == np.int8
    np.testing.assert_array_equal(dep.height_m, 0.0)
    np.testing.assert_array_equal(dep.vertical_velocity_m_s, 0.0)
    assert any("first order" in note for note in dep.notes)


def test_a_granule_that_leaves_before_landing_is_still_falling(prepare):
    """High drop, fast disc: caught below the vane tops and thrown before it lands."""
    scene = load_scene("paper", {"sim.granules": 50, "feed.drop_height_m": 0.6, "spinner.rpm": 1000,
                                 "vanes.height_m": 0.5})
    granules, contacts = prepare(scene)
    dep = simulate_analytic(scene, granules, contacts)
    t_land = math.sqrt(2 * 0.6 / G)
    air = dep.time_s < t_land
    assert air.any() and dep.departed.all()
    np.testing.assert_allclose(dep.height_m[air], 0.6 - 0.5 * G * dep.time_s[air] ** 2)
    np.testing.assert_allclose(dep.vertical_velocity_m_s[air], -G * dep.time_s[air])
    assert np.all(dep.height_m[air] > 0) and np.all(dep.height_m[~air] == 0)
    assert any("before landing" in note for note in dep.notes)


def test_free_rotation_departs_faster_when_vane_friction_is_large(prepare):
    """Paper scene, drop 0: rolling replaces the sliding friction (printed with -s)."""
    speeds = {}
    for mu in (0.0, 0.52):
        for rotation in ("free", "locked"):
            scene = load_scene("paper", {"feed.drop_height_m": 0.0, "granule.rotation": rotation,
                                         "contact.vane_friction": mu, "sim.granules": 400})
            granules, contacts = prepare(scene)
            speeds[mu, rotation] = float(np.mean(simulate_analytic(scene, granules, contacts).speed_m_s))
    print(f"\npaper scene, drop 0, mu_v 0.52: free {speeds[0.52, 'free']:.3f} m/s, "
          f"locked {speeds[0.52, 'locked']:.3f} m/s")
    assert speeds[0.52, "free"] > 1.03 * speeds[0.52, "locked"]
    assert speeds[0.0, "free"] == pytest.approx(speeds[0.0, "locked"], rel=1e-12)


# --- restitution at the vane: against the pymunk model -----------------------------------------

PYMUNK_POINTS = [
    ("locked", 1100, -15.0),
    ("locked", 200, 0.0),
    ("free", 500, 0.0),
    ("free", 200, -15.0),
    ("free", 800, -7.5),
]
_PYMUNK_CACHE: dict = {}


def _against_pymunk(rotation, rpm, pitch, restitution, prepare, **analytic_kwargs):
    """(speed ratio - 1, angle difference in deg): analytic against pymunk, same 150 granules."""

    scene = load_scene("paper", {
        "feed.drop_height_m": 0.0, "feed.spread_m": 0.0, "sim.granules": 150, "granule.rotation": rotation,
        "spinner.rpm": rpm, "vanes.pitch_deg": pitch, "contact.vane_restitution": restitution,
    })
    granules, contacts = prepare(scene)
    key = (rotation, rpm, pitch, restitution)
    if key not in _PYMUNK_CACHE:
        _PYMUNK_CACHE[key] = departure_summary(simulate_pymunk(scene, granules, contacts), scene.spinner.omega_rad_s)
    p = _PYMUNK_CACHE[key]
    a = departure_summary(simulate_analytic(scene, granules, contacts, **analytic_kwargs), scene.spinner.omega_rad_s)
    return a["speed_mean_m_s"] / p["speed_mean_m_s"] - 1.0, a["angle_mean_deg"] - p["angle_mean_deg"]


@pytest.mark.parametrize("restitution", [0.43, 0.0])
@pytest.mark.parametrize("rotation, rpm, pitch", PYMUNK_POINTS,
                         ids=[f"{r}-{rpm}rpm-pitch{p:g}" for r, rpm, p in PYMUNK_POINTS])
def test_agrees_with_pymunk(rotation, rpm, pitch, restitution, prepare):
    """Paper spinner, drop 0, point feed: mean departure speed within 0.5 %, angle within 0.5 deg.

    Measured (400 granules, 200-1100 rpm, pitch -15..0): within 0.09 % and 0.09 deg at
    e = 0.43, 0.24 % and 0.09 deg at e = 0.
    """
    speed, angle = _against_pymunk(rotation, rpm, pitch, restitution, prepare)
    print(f"\n{rotation} {rpm} rpm pitch {pitch}: e {restitution}: speed {100 * speed:+.3f} %, angle {angle:+.3f} deg")
    assert abs(speed) < 0.005 and abs(angle) < 0.5


@pytest.mark.parametrize("rotation, rpm, pitch", [("locked", 1100, -15.0), ("free", 500, 0.0)])
def test_bounces_without_impact_friction_miss_pymunk(rotation, rpm, pitch, prepare):
    """Why the impact carries friction: keeping the tangential velocity at each bounce is off by
    more than 1.5 % in speed and 1.5 deg (too fast when locked, too slow when free)."""
    speed, angle = _against_pymunk(rotation, rpm, pitch, 0.43, prepare, impact_friction=False)
    assert abs(speed) > 0.015 and abs(angle) > 1.5


@pytest.mark.parametrize("overrides", [
    {"granule.rotation": "locked", "spinner.rpm": 1100, "vanes.pitch_deg": -15.0},
    {"spinner.rpm": 200},
    {"spinner.rpm": 500, "feed.drop_height_m": 0.05, "feed.spread_m": 0.015},
])
def test_rebound_threshold_is_converged(overrides, prepare):
    """REBOUND_STOP = 1e-3 against 1e-8: mean speed within 1e-4, each direction within 0.05 deg."""
    scene = load_scene("paper", dict({"feed.drop_height_m": 0.0, "feed.spread_m": 0.0, "sim.granules": 200},
                                     **overrides))
    granules, contacts = prepare(scene)
    dep = simulate_analytic(scene, granules, contacts)
    fine = simulate_analytic(scene, granules, contacts, rebound_stop=1e-8)
    assert np.mean(dep.speed_m_s) == pytest.approx(np.mean(fine.speed_m_s), rel=1e-4)
    turn = np.arctan2(dep.velocity_m_s[:, 0] * fine.velocity_m_s[:, 1] - dep.velocity_m_s[:, 1]
                      * fine.velocity_m_s[:, 0], np.sum(dep.velocity_m_s * fine.velocity_m_s, axis=1))
    assert np.max(np.abs(np.degrees(turn))) < 0.05


def test_bouncing_catch_is_deterministic_and_noted(prepare):
    scene = load_scene("paper", {"sim.granules": 300, "contact.vane_restitution": 0.8, "spinner.rpm": 300})
    granules, contacts = prepare(scene)
    a = simulate_analytic(scene, granules, contacts)
    b = simulate_analytic(scene, granules, contacts)
    for x, y in ((a.position_m, b.position_m), (a.velocity_m_s, b.velocity_m_s), (a.spin_rad_s, b.spin_rad_s),
                 (a.time_s, b.time_s)):
        np.testing.assert_array_equal(x, y)
        assert np.all(np.isfinite(x))
    assert any("bounced off the face (restitution 0.8)" in note for note in a.notes)
    assert a.departed.all()
