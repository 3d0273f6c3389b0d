"""The compiled spinner model's pieces against exact references, and its determinism."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from spreadgym.config.scene import load_scene
from spreadgym.physics.analytic.spinner import simulate_analytic
from spreadgym.physics.compiled import granule_run, layout
from spreadgym.physics.compiled.model import simulate_compiled
from spreadgym.physics.departure import DEPARTED, RETAINED_TIMEOUT

G = 9.81
NO_VANES = np.zeros((0, layout.V_SIZE))


def kernel_parameters(scene, contacts, time_limit_s, step_s=None):
    p = layout.pack_parameters(scene, contacts, 1e-9, time_limit_s, 1e-4)
    if step_s is not None:
        p[layout.STEP] = step_s
    return p


def run_single(params, xy, z0, radius=1.5e-3):
    out = np.zeros(granule_run.OUT_SIZE)
    code = granule_run.run_one(xy[0], xy[1], radius, z0, 0.0, params, NO_VANES, out, np.empty((0, 3)))
    return code, out


def bounce_height(t, z0, e):
    """Closed form: dropped from rest at z0 on a still disc, restitution e (no settling)."""
    v = math.sqrt(2.0 * G * z0)
    t_k = math.sqrt(2.0 * z0 / G)
    if t < t_k:
        return z0 - 0.5 * G * t * t, -G * t
    while True:
        v *= e
        flight = 2.0 * v / G
        if t < t_k + flight:
            s = t - t_k
            return v * s - 0.5 * G * s * s, v - G * s
        t_k += flight


@pytest.mark.parametrize("time_s", [0.05, 0.11, 0.2, 0.31])
def test_a_granule_bounces_on_a_still_disc_as_the_closed_form(prepare, time_s):
    scene = load_scene("paper", {"sim.granules": 1})
    _, contacts = prepare(scene)
    params = kernel_parameters(scene, contacts, time_s, step_s=1e-3)
    params[layout.OMEGA] = 0.0
    code, out = run_single(params, (0.05, 0.0), 0.1)
    z, vz = bounce_height(time_s, 0.1, contacts.disc_restitution)
    assert code == RETAINED_TIMEOUT and out[granule_run.TIME] == pytest.approx(time_s, abs=1e-15)
    assert out[granule_run.Z] == pytest.approx(z, abs=1e-12)
    assert out[granule_run.VZ] == pytest.approx(vz, abs=1e-11)
    assert out[granule_run.CX] == 0.05 and out[granule_run.VX] == 0.0


@pytest.mark.parametrize("rpm", [300, 700])
def test_a_granule_waiting_on_the_spinning_disc_follows_coulomb_drag(prepare, rpm):
    """No vanes, resting on the disc from rest in the machine frame: against a tight solve
    of dv/dt = -mu g (v - w x r) / |v - w x r| in the machine frame."""
    scene = load_scene("paper", {"sim.granules": 1, "spinner.rpm": rpm, "feed.drop_height_m": 0.0})
    _, contacts = prepare(scene)
    omega = scene.spinner.omega_rad_s
    horizon = 0.03
    params = kernel_parameters(scene, contacts, horizon)
    code, out = run_single(params, (0.04, 0.01), 0.0)
    assert code == RETAINED_TIMEOUT
    _, half = run_single(kernel_parameters(scene, contacts, horizon, step_s=0.5 * params[layout.STEP]),
                         (0.04, 0.01), 0.0)
    a = contacts.disc_friction * G

    def rhs(_t, y):
        rel = y[2:] - omega * np.array([-y[1], y[0]])
        return np.concatenate([y[2:], -a * rel / np.linalg.norm(rel)])

    sol = solve_ivp(rhs, (0.0, horizon), [0.04, 0.01, 0.0, 0.0], method="DOP853", rtol=1e-10, atol=1e-13)
    r, v = sol.y[:2, -1], sol.y[2:, -1]
    turn = -omega * horizon
    rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    expected_c = rot @ r
    expected_v = rot @ (v - omega * np.array([-r[1], r[0]]))
    # fourth-order steps of |omega| dt = 0.1: ~3e-8 m of the ~1 cm it moves and ~4e-6 m/s
    # of ~3 m/s, and fourth order: halving the step cuts the error about 16x (at least 8x here)
    position = [granule_run.CX, granule_run.CY]
    assert out[position] == pytest.approx(expected_c, abs=1e-7)
    assert out[[granule_run.VX, granule_run.VY]] == pytest.approx(expected_v, abs=1e-5)
    error, error_half = (np.abs(run[position] - expected_c).max() for run in (out, half))
    assert error_half < error / 8.0
    moved = np.linalg.norm(r - np.array([0.04, 0.01]))
    assert moved > 1e-3  # the drag did move it: the comparison is not trivial


@pytest.mark.parametrize("rotation", ["free", "locked"])
@pytest.mark.parametrize("pitch_deg", [-15.0, 0.0, 20.0])
def test_rolling_and_sliding_along_a_vane_match_the_closed_forms(prepare, rotation, pitch_deg, monkeypatch):
    """Fed onto the disc without drop and without disc drag before the catch (the analytic
    model is then exact: plastic catch with its friction impulse, then slide or roll)."""
    scene = load_scene("paper", {
        "sim.granules": 256, "feed.drop_height_m": 0.0, "feed.spread_m": 0.004, "vanes.pitch_deg": pitch_deg,
        "granule.rotation": rotation, "contact.vane_restitution": 0.0, "contact.disc_friction": 0.0,
    })
    granules, contacts = prepare(scene)
    fast = simulate_compiled(scene, granules, contacts)
    exact = simulate_analytic(scene, granules, contacts)
    assert np.all(fast.outcome == DEPARTED) and np.all(exact.outcome == DEPARTED)
    # Granules released overlapping a vane are pushed off it by conventions that differ
    # (shortest separation here, angular half-width there): compared elsewhere.
    clear = ~released_on_a_vane(scene, granules)
    assert clear.sum() > 200
    speed = exact.speed_m_s[clear]
    # default step (|omega| dt = 0.1): measured up to 4e-5 m/s, 9e-6 s and 7e-5 m
    assert np.abs(fast.speed_m_s[clear] - speed).max() < 3e-4 * speed.max()
    assert np.abs(fast.time_s[clear] - exact.time_s[clear]).max() < 2e-5
    gap = np.linalg.norm(fast.position_m[clear] - exact.position_m[clear], axis=1)
    assert gap.max() < 1e-3 * scene.spinner.radius_m  # 2e-5 s at ~10 m/s
    if rotation == "free":
        spin = exact.spin_rad_s[clear]
        assert np.abs(fast.spin_rad_s[clear] - spin).max() < 3e-4 * np.abs(spin).max()
    # and it is the step's error: half the step, at least 4x closer (measured 8-16x)
    monkeypatch.setattr(layout, "OMEGA_STEP", 0.5 * layout.OMEGA_STEP)
    finer = simulate_compiled(scene, granules, contacts)
    finer_gap = np.linalg.norm(finer.position_m[clear] - exact.position_m[clear], axis=1)
    assert finer_gap.max() < gap.max() / 4.0


def released_on_a_vane(scene, granules):
    vanes = layout.pack_vanes(scene)
    start = granules.release_in_spinner_frame()
    offset = start[:, None, :] - vanes[None, :, [layout.PX, layout.PY]]
    normal = np.sum(offset * vanes[None, :, [layout.NX, layout.NY]], axis=2)
    along = np.sum(offset * vanes[None, :, [layout.UX, layout.UY]], axis=2)
    reach = granules.radius_m[:, None] + 0.5 * scene.vanes.thickness_m
    on_face = (np.abs(normal) < reach) & (along > -reach) & (along < vanes[None, :, layout.LENGTH] + reach)
    return np.any(on_face, axis=1)


def test_same_seed_gives_identical_arrays(prepare):
    scene = load_scene("field", {"sim.granules": 256})
    granules, contacts = prepare(scene)
    first = simulate_compiled(scene, granules, contacts, track_count=3)
    second = simulate_compiled(scene, granules, contacts, track_count=3)
    for name in ("position_m", "velocity_m_s", "spin_rad_s", "height_m", "vertical_velocity_m_s", "time_s",
                 "outcome"):
        assert np.array_equal(getattr(first, name), getattr(second, name)), name
    assert all(np.array_equal(a, b) for a, b in zip(first.tracks, second.tracks))
    assert len(first.tracks) == 3 and first.model == "compiled"


def test_tracks_end_where_the_granule_leaves(prepare):
    scene = load_scene("paper", {"sim.granules": 8})
    granules, contacts = prepare(scene)
    departure = simulate_compiled(scene, granules, contacts, track_count=2)
    for k, track in enumerate(departure.tracks):
        assert np.allclose(track[-1], departure.position_m[k])
        assert np.linalg.norm(track[0] - granules.release_xy_m[k]) < 1e-12


def test_a_granule_pressed_on_a_vane_end_in_the_air_does_not_chatter(prepare):
    """A start found in the field scene's sample: bouncing on the disc, the frame presses
    it on the inner end of a vane. Re-located as a new crossing after every catch, it took
    33 581 events of ~1e-9 s each; held exactly on the cap, a few hundred."""
    scene = load_scene("field")
    _, contacts = prepare(scene)
    params = layout.pack_parameters(scene, contacts, 6.631455962162307e-05, 3.0, 1e-4)
    out, track = np.zeros(granule_run.OUT_SIZE), np.full((50_000, 3), np.nan)
    code = granule_run.run_one(6.189228593293274e-05, 0.053813171625773766, 0.0015099412096945878, 0.02, 0.0,
                               params, layout.pack_vanes(scene), out, track)
    assert code == DEPARTED
    assert np.count_nonzero(~np.isnan(track[:, 0])) < 1000


def test_the_event_root_converges_superlinearly():
    """Illinois regula falsi on a smooth event function: to 1e-10 of the step in a few
    updates (plain regula falsi, or halving at every update, needs dozens)."""
    from spreadgym.physics.compiled.event_root import FRACTION_TOLERANCE, illinois_step

    def g(f):
        return 0.3 - f - 0.8 * f * f * f  # one root in (0, 1), curved enough to stall plain regula falsi

    lo, hi, g_lo, g_hi = 0.0, 1.0, g(0.0), g(1.0)
    f, moved, converged, updates = g_lo / (g_lo - g_hi), 0, False, 0
    while not converged and updates < 40:
        lo, hi, g_lo, g_hi, f, converged, moved = illinois_step(lo, hi, g_lo, g_hi, f, g(f), moved)
        updates += 1
    assert converged and updates <= 8
    root = 0.28204986651378205  # brentq, xtol 1e-15
    assert abs(f - root) < 10 * FRACTION_TOLERANCE


def test_the_free_phase_event_root_is_newton_with_a_bisection_guard():
    """Safeguarded Newton from the regula falsi guess: to 1e-10 of the step in at most 4
    updates on a smooth event; where the slope would throw it out of the bracket (a grazing
    approach) the bracket halves instead, and it still converges."""
    from spreadgym.physics.compiled.event_root import FRACTION_TOLERANCE, newton_step

    root = 0.28204986651378205  # of 0.3 - f - 0.8 f^3 (brentq, xtol 1e-15)

    def solve(g, slope, guess):
        lo, hi, f, converged, updates = 0.0, 1.0, guess, False, 0
        while not converged and updates < 60:
            lo, hi, f_next, converged = newton_step(lo, hi, f, g(f), slope(f))
            assert lo - 1e-15 <= root <= hi + 1e-15  # the root to brentq's xtol
            updates += 1
            if not converged:
                f = f_next
        return f, updates

    f, updates = solve(lambda f: 0.3 - f - 0.8 * f**3, lambda f: -1.0 - 2.4 * f * f, 0.3 / 1.1)
    assert updates <= 4 and abs(f - root) < 10 * FRACTION_TOLERANCE
    # a wrong, tiny slope sends every Newton point outside: the guard alone must converge
    f, updates = solve(lambda f: 0.3 - f - 0.8 * f**3, lambda f: -1e-30, 0.9)
    assert 20 <= updates <= 40 and abs(f - root) < 10 * FRACTION_TOLERANCE


def test_a_short_rebound_off_a_face_returns_at_the_located_root_in_few_newton_updates(prepare, monkeypatch):
    """A granule leaving a leading face at 2 cm/s while sliding out at 2 m/s: Coriolis
    presses it back within a tenth of a step. The free phase's step finds that return
    where its fourth-order path meets the face (brentq on the same path, to 1e-10 of the
    step), starting Newton from the parabola's return 2 v_n / press: at most 4 updates
    (from the regula falsi guess between the apex and the step's end it took 9 here)."""
    from scipy.optimize import brentq

    from spreadgym.physics.compiled import free_motion
    from spreadgym.physics.compiled.event_root import FRACTION_TOLERANCE

    scene = load_scene("paper")
    _, contacts = prepare(scene)
    P = layout.pack_parameters(scene, contacts, 6.6e-05, 3.0, 1e-4)
    V = layout.pack_vanes(scene)
    radius = 0.0015
    reach = radius + 0.5 * scene.vanes.thickness_m
    k, along, vn, xd = 0, 0.5 * V[0, layout.LENGTH], 0.02, 2.0
    n, u = V[k, [layout.NX, layout.NY]], V[k, [layout.UX, layout.UY]]
    cx, cy = V[k, [layout.PX, layout.PY]] + along * u + reach * n
    vx, vy = xd * u + vn * n
    h, omega, drag = P[layout.STEP], P[layout.OMEGA], P[layout.MU_DISC] * P[layout.GRAVITY]
    updates = []
    counted = free_motion.newton_step

    def newton_step(*args):
        updates.append(1)
        return counted(*args)

    monkeypatch.setattr(free_motion, "newton_step", newton_step)
    sx, sy, _, _, used, event, vane, side = free_motion.step.py_func(cx, cy, vx, vy, h, True, drag, reach, P, V)
    assert (event, vane, side) == (free_motion.FACE, k, 1.0)

    def gap(f):  # the face's distance along the same fourth-order path
        px, py, _, _ = free_motion.rk4(cx, cy, vx, vy, f * h, omega, drag)
        return (px - V[k, layout.PX]) * n[0] + (py - V[k, layout.PY]) * n[1] - reach

    root = brentq(gap, 1e-9, 1.0, xtol=1e-15)  # gap(0) = 0: the start on the face
    assert 0.01 < root < 0.2  # a short flight, well inside the step
    assert abs(used / h - root) < 10 * FRACTION_TOLERANCE
    assert len(updates) <= 4, len(updates)


def test_a_granule_sliding_off_a_vane_tip_goes_round_it(prepare):
    """A start found in twin-field's sample: it slides off the tip of a leading face while
    the frame presses it on that face's line. Caught back onto the face at its very end,
    it left and returned there ~100 000 times and was counted as retained (found when
    twin-field's four vanes all started at 0.06 m)."""
    scene = load_scene("twin-field", {"vanes.inner_radius_m": 0.06})
    _, contacts = prepare(scene)
    params = layout.pack_parameters(scene, contacts, 4.774648292756861e-05, 3.0, 1e-4)
    out, track = np.zeros(granule_run.OUT_SIZE), np.full((50_000, 3), np.nan)
    code = granule_run.run_one(0.08646045373866859, -0.029642386172222156, 0.0014093200506502803, 0.02, 0.0,
                               params, layout.pack_vanes(scene), out, track)
    assert code == DEPARTED
    assert np.count_nonzero(~np.isnan(track[:, 0])) < 1000


def test_the_machine_frame_turn_is_the_numpy_rotation():
    from spreadgym.physics.compiled.model import machine_frame
    from spreadgym.physics.granules import rotate

    rng = np.random.default_rng(3)
    out = rng.normal(size=(500, granule_run.OUT_SIZE))
    angle, omega = rng.uniform(-np.pi, np.pi, 500), 73.3
    c = out[:, [granule_run.CX, granule_run.CY]]
    v = out[:, [granule_run.VX, granule_run.VY]] + omega * np.stack([-c[:, 1], c[:, 0]], axis=1)
    turn = angle + omega * out[:, granule_run.TIME]
    position, velocity = machine_frame(out, angle, omega)
    # the C library's cos and sin against numpy's: the same bits where numpy calls the C library
    np.testing.assert_allclose(position, rotate(c, turn), rtol=0, atol=4e-16 * np.abs(c).max())
    np.testing.assert_allclose(velocity, rotate(v, turn), rtol=0, atol=4e-16 * np.abs(v).max())
