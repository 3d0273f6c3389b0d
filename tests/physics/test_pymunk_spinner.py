"""The pymunk spinner model against exact solutions, and its bookkeeping."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from spreadgym.config.scene import load_scene
from spreadgym.physics.departure import DEPARTED
from spreadgym.physics.geometry import vane_segments
from spreadgym.physics.stepped.pymunk_spinner import simulate_pymunk

G = 9.81


def large_disc(rpm, pitch_deg, vane_friction, **extra):
    """R = 0.3 m, vanes from 0.02 m, feed at 0.04 m, no drop, locked rotation, one size."""
    overrides = {
        "spinner.radius_m": 0.3, "spinner.rpm": rpm, "vanes.inner_radius_m": 0.02,
        "vanes.pitch_deg": pitch_deg, "feed.radius_m": 0.04, "feed.spread_m": 0.0,
        "feed.drop_height_m": 0.0, "granule.rotation": "locked", "granule.diameter_sd_m": 0.0,
        "contact.vane_friction": vane_friction, "sim.granules": 12,
    }
    overrides.update(extra)
    return load_scene("paper", overrides)


def exact_sliding_departure_speed(scene, mu_d, mu_v, diameter):
    """Closed form of a point granule sliding out along vane 0 (derived independently).

    Rotating frame, c = p + s u + w n with w = p.n + h fixed:
        s'' + 2 mu_v W s' - W^2 s = W^2 (p.u) - mu_d g + mu_v W^2 w,   W = |omega|,
    s(t) = s_p + A exp(l1 t) + B exp(l2 t),  l = W (-mu_v +- sqrt(1 + mu_v^2)).
    Start: the catch point, at rest in the machine frame (plastic catch keeps the
    component along the vane). Departure: |c| = R; speed |s' u + omega z x c|.
    """
    omega = scene.spinner.omega_rad_s
    w_abs = abs(omega)
    inner, outer = vane_segments(scene)
    p = inner[0]
    u = (outer[0] - p) / np.linalg.norm(outer[0] - p)
    n = math.copysign(1.0, omega) * np.array([-u[1], u[0]])
    w = p @ n + 0.5 * scene.vanes.thickness_m + 0.5 * diameter
    pu = p @ u
    # Catch where the feed circle meets the face line: |p + s u + w n| = feed radius.
    s0 = math.sqrt(scene.feed.radius_m**2 - w**2) - pu
    c0 = (pu + s0) * u + w * n
    sdot0 = -(omega * np.array([-c0[1], c0[0]])) @ u
    s_p = -(w_abs**2 * pu - mu_d * G + mu_v * w_abs**2 * w) / w_abs**2
    root = math.sqrt(1.0 + mu_v**2)
    l1, l2 = w_abs * (-mu_v + root), w_abs * (-mu_v - root)
    a = (sdot0 - l2 * (s0 - s_p)) / (l1 - l2)
    b = (s0 - s_p) - a
    s_exit = math.sqrt(scene.spinner.radius_m**2 - w**2) - pu
    t_high = 1e-3
    while s_p + a * math.exp(l1 * t_high) + b * math.exp(l2 * t_high) < s_exit:
        t_high *= 2.0
    t_exit = brentq(lambda t: s_p + a * math.exp(l1 * t) + b * math.exp(l2 * t) - s_exit, 0.0, t_high)
    sdot = a * l1 * math.exp(l1 * t_exit) + b * l2 * math.exp(l2 * t_exit)
    c = (pu + s_exit) * u + w * n
    v = sdot * u + omega * np.array([-c[1], c[0]])
    return float(np.linalg.norm(v))


@pytest.mark.parametrize("rpm", [200, 500, 800, 1100])
@pytest.mark.parametrize("pitch_deg", [-30.0, 0.0, 30.0])
@pytest.mark.parametrize("vane_friction", [0.0, 0.3, 0.6])
def test_locked_granule_departs_at_the_exact_sliding_speed(prepare, rpm, pitch_deg, vane_friction):
    scene = large_disc(rpm, pitch_deg, vane_friction)
    granules, contacts = prepare(scene)
    departure = simulate_pymunk(scene, granules, contacts)
    assert np.all(departure.outcome == DEPARTED)
    exact = exact_sliding_departure_speed(scene, contacts.disc_friction, vane_friction, granules.diameter_m[0])
    simulated = departure.speed_m_s.mean()
    assert simulated == pytest.approx(exact, rel=5e-3)


def test_time_step_follows_the_scene_and_is_reported(prepare):
    scene = large_disc(1100, 0.0, 0.3)
    departure = simulate_pymunk(scene, *prepare(scene))
    tip_speed = 1100 * 2 * math.pi / 60 * 0.3
    reach = 0.5 * scene.vanes.thickness_m + 0.5 * departure_min_diameter(scene, prepare)
    assert departure.dt_s <= 0.5 * reach / tip_speed
    assert any("time step" in note for note in departure.notes)


def departure_min_diameter(scene, prepare):
    granules, _ = prepare(scene)
    return float(granules.diameter_m.min())


def test_same_seed_same_result_bit_for_bit(prepare):
    scene = load_scene("paper", {"sim.granules": 60})
    first = simulate_pymunk(scene, *prepare(scene))
    second = simulate_pymunk(scene, *prepare(scene))
    for name in ("position_m", "velocity_m_s", "spin_rad_s", "height_m", "time_s", "outcome"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))


def test_every_granule_ends_departed_or_retained_and_nothing_is_nan(prepare):
    for overrides in ({"spinner.rpm": 200}, {"spinner.rpm": 1100, "vanes.pitch_deg": 30.0},
                      {"spinner.rpm": 40}, {"granule.rotation": "locked", "vanes.pitch_deg": -30.0}):
        scene = load_scene("paper", {"sim.granules": 40, **overrides})
        departure = simulate_pymunk(scene, *prepare(scene))
        assert departure.outcome.shape == (40,)
        assert set(np.unique(departure.outcome)) <= {0, 1, 2}
        for name in ("position_m", "velocity_m_s", "spin_rad_s", "height_m", "vertical_velocity_m_s", "time_s"):
            assert np.all(np.isfinite(getattr(departure, name))), (overrides, name)


def test_slow_disc_retains_granules_as_stuck(prepare):
    """At 40 rpm, omega^2 r at the feed is far below mu g: friction holds the granules."""
    scene = load_scene("paper", {"sim.granules": 20, "spinner.rpm": 40, "feed.drop_height_m": 0.0})
    departure = simulate_pymunk(scene, *prepare(scene))
    assert departure.outcome_counts()["retained: stuck on the disc"] == 20
