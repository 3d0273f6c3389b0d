"""Flight to the ground: exact cases, a tight-tolerance reference and edge cases."""

import math

import numpy as np
import pytest
from scipy.stats import qmc

from spreadgym.config.scene import Flight
from spreadgym.errors import ConfigError
from spreadgym.spread.flight import Landing, drag_constant, fly, reference_landing, terminal_speed_m_s

G = 9.81


def launches(n, seed, elevation_deg=(-10.0, 30.0)):
    """Realistic launches: 5-50 m/s, -10..30 deg, 0.5-1.5 m, 2-4 mm, 877-1734 kg/m3."""
    rng = np.random.default_rng(seed)
    speed = rng.uniform(5.0, 50.0, n)
    el = np.radians(rng.uniform(*elevation_deg, n))
    az = rng.uniform(0.0, 2 * np.pi, n)
    vel = np.stack([speed * np.cos(el) * np.cos(az), speed * np.cos(el) * np.sin(az), speed * np.sin(el)], axis=1)
    r = rng.uniform(0.2, 0.4, n)
    pos = np.stack([r * np.cos(az), r * np.sin(az)], axis=1)
    return pos, rng.uniform(0.5, 1.5, n), vel, rng.uniform(2e-3, 4e-3, n), rng.uniform(877.0, 1734.0, n)


def parabola(pos, height, vel, flight):
    vx, vy, vz = vel[:, 0], vel[:, 1] + flight.forward_speed_m_s, vel[:, 2]
    t = (vz + np.sqrt(vz**2 + 2 * G * height)) / G
    return np.stack([pos[:, 0] + vx * t, pos[:, 1] + vy * t], axis=1), t


@pytest.mark.parametrize(
    "flight",
    [
        Flight(drag_coefficient=0.0, forward_speed_m_s=3.0, wind_m_s=(4.0, -2.0)),
        Flight(air_density_kg_m3=0.0, forward_speed_m_s=12.0, wind_m_s=(-5.0, 5.0)),
    ],
)
@pytest.mark.parametrize("dt_s", [None, 0.01])
def test_no_drag_is_the_parabola(flight, dt_s):
    pos, height, vel, d, rho = launches(3000, seed=1, elevation_deg=(-60.0, 80.0))
    landing = fly(pos, height, vel, d, rho, flight, dt_s=dt_s)
    xy, t = parabola(pos, height, vel, flight)
    np.testing.assert_allclose(landing.position_m, xy, rtol=0, atol=1e-9)
    np.testing.assert_allclose(landing.time_s, t, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "flight",
    [
        Flight(),
        Flight(forward_speed_m_s=4.0, wind_m_s=(5.0, -3.0)),
        Flight(forward_speed_m_s=15.0, wind_m_s=(-6.0, 6.0)),
    ],
)
def test_default_matches_tight_reference_within_a_millimetre(flight):
    args = launches(150, seed=2)
    ref = reference_landing(*args, flight)
    got = fly(*args, flight)
    error = np.hypot(*(got.position_m - ref.position_m).T)
    assert error.max() < 1e-3, error.max()
    assert error.max() < 1e-4  # the default has a wide margin (measured ~0.01 mm)
    np.testing.assert_allclose(got.time_s, ref.time_s, rtol=0, atol=1e-5)
    # drag matters at these speeds: the no-drag parabola would be metres off
    xy, _ = parabola(args[0], args[1], args[2], flight)
    assert np.max(np.hypot(*(xy - ref.position_m).T)) > 1.0


def test_fixed_step_rk4_matches_reference():
    flight = Flight(forward_speed_m_s=3.0, wind_m_s=(2.0, 1.0))
    args = launches(100, seed=3)
    ref = reference_landing(*args, flight)
    got = fly(*args, flight, dt_s=0.005)
    assert np.hypot(*(got.position_m - ref.position_m).T).max() < 1e-3


def test_throw_distances_match_the_literature_figures():
    # horizontal launch from 0.8 m, 3 mm granule: ~6.5 m at 20, ~9 m at 30, ~11 m at 40 m/s
    speeds = np.array([20.0, 30.0, 40.0])
    vel = np.stack([speeds, np.zeros(3), np.zeros(3)], axis=1)
    landing = fly(np.zeros((3, 2)), 0.8, vel, 3e-3, 1500.0, Flight())
    np.testing.assert_allclose(landing.position_m[:, 0], [6.5, 9.0, 11.0], rtol=0.03)
    assert np.all(np.abs(landing.position_m[:, 1]) < 1e-12)


def test_terminal_velocity_range():
    v_t = terminal_speed_m_s(np.array([2e-3, 4e-3]), np.array([877.0, 1734.0]), Flight())
    assert 6.0 < v_t[0] < v_t[1] < 14.0
    assert np.isinf(terminal_speed_m_s(3e-3, 1500.0, Flight(drag_coefficient=0.0)))
    # a long drop ends at the terminal speed: fall time ~ h / v_t
    k = drag_constant(3e-3, 1500.0, Flight())
    v_t = math.sqrt(G / k)
    t = fly(np.zeros((1, 2)), 200.0, np.zeros((1, 3)), 3e-3, 1500.0, Flight()).time_s[0]
    exact = math.acosh(math.exp(200.0 * k)) / math.sqrt(G * k)  # 1-D quadratic drag from rest
    assert t == pytest.approx(exact, rel=1e-6)
    assert t == pytest.approx(200.0 / v_t, rel=0.1)


def test_galilean_wind_and_forward_speed():
    """Air moving with the machine: same flight relative to the machine, shifted by
    forward speed x time over the ground."""
    pos, height, vel, d, rho = launches(200, seed=5)
    still = fly(pos, height, vel, d, rho, Flight())
    moving = fly(pos, height, vel, d, rho, Flight(forward_speed_m_s=5.0, wind_m_s=(0.0, 5.0)))
    np.testing.assert_allclose(moving.time_s, still.time_s, rtol=0, atol=1e-6)
    shifted = still.position_m + np.stack([np.zeros(200), 5.0 * still.time_s], axis=1)
    np.testing.assert_allclose(moving.position_m, shifted, rtol=0, atol=1e-4)


def test_forward_speed_is_added_to_the_launch_velocity():
    pos, height, vel, d, rho = launches(100, seed=6)
    a = fly(pos, height, vel, d, rho, Flight(forward_speed_m_s=4.0, wind_m_s=(1.0, 2.0)))
    b = fly(pos, height, vel + [0.0, 4.0, 0.0], d, rho, Flight(wind_m_s=(1.0, 2.0)))
    np.testing.assert_allclose(a.position_m, b.position_m, rtol=0, atol=1e-12)


def test_edge_cases_land_without_nan():
    pos = np.array([[0.1, 0.2]] * 5)
    height = np.array([1.0, 1.0, 0.0, 0.0, 0.7])
    vel = np.array([[0, 0, 0], [0, 0, 20.0], [10.0, 0, 0], [0, 0, 0], [3.0, 0, -60.0]])
    flight = Flight(wind_m_s=(1.0, 0.0))
    got = fly(pos, height, vel, 3e-3, 1500.0, flight)
    assert isinstance(got, Landing)
    assert np.all(np.isfinite(got.position_m)) and np.all(np.isfinite(got.time_s))
    # zero height: lands at once, where it was launched
    np.testing.assert_array_equal(got.time_s[2:4], 0.0)
    np.testing.assert_array_equal(got.position_m[2:4], pos[2:4])
    ref = reference_landing(pos, height, vel, 3e-3, 1500.0, flight)
    np.testing.assert_allclose(got.position_m, ref.position_m, rtol=0, atol=1e-4)
    np.testing.assert_allclose(got.time_s, ref.time_s, rtol=0, atol=1e-4)
    assert got.time_s[1] > got.time_s[0] > 0  # the upward one is in the air longer
    assert got.position_m[0, 0] > pos[0, 0]  # the wind carries a dropped granule


def test_empty_and_scalar_inputs():
    empty = fly(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3)), 3e-3, 1500.0, Flight())
    assert empty.position_m.shape == (0, 2) and empty.time_s.shape == (0,)
    pos, height, vel, _, _ = launches(20, seed=7)
    a = fly(pos, height, vel, 3e-3, 1500.0, Flight())
    b = fly(pos, height, vel, np.full(20, 3e-3), np.full(20, 1500.0), Flight())
    np.testing.assert_array_equal(a.position_m, b.position_m)


def test_bad_inputs_name_their_keys():
    with pytest.raises(ConfigError) as e:
        fly(np.zeros((2, 2)), [1.0, -0.1], np.zeros((2, 3)), 3e-3, 1500.0, Flight())
    assert e.value.key == "spinner.height_m"
    with pytest.raises(ConfigError) as e:
        fly(np.zeros((2, 2)), 1.0, np.zeros((2, 3)), 0.0, 1500.0, Flight())
    assert e.value.key == "granule.diameter_m"
    with pytest.raises(ConfigError):
        fly(np.zeros((2, 2)), 1.0, np.zeros((2, 2)), 3e-3, 1500.0, Flight())
    with pytest.raises(ConfigError):
        fly(np.zeros((2, 2)), 1.0, np.zeros((2, 3)), 3e-3, 1500.0, Flight(), dt_s=0.0)


def scene_launches(m, seed):
    """Scrambled Sobol launch states (2^m) covering what the compiled spinner launches on the
    paper (6.5-10 m/s, 0.8 m), field (20-29 m/s, 0.9 m) and twin-field (28-42 m/s, 1.0 m)
    scenes: speed 6-43 m/s, elevation -10..10 deg, any azimuth, radius 0.15-0.3 m, height
    0.8-1.02 m, diameter 1.5-5.3 mm, density 877-1734 kg/m3, spin 0-35000 rad/s either sense."""
    u = qmc.Sobol(9, scramble=True, seed=seed).random_base2(m)
    speed = 6.0 + 37.0 * u[:, 0]
    el = np.radians(-10.0 + 20.0 * u[:, 1])
    az = 2.0 * np.pi * u[:, 2]
    vel = np.stack([speed * np.cos(el) * np.cos(az), speed * np.cos(el) * np.sin(az), speed * np.sin(el)], axis=1)
    pos = (0.15 + 0.15 * u[:, 3, None]) * np.stack([np.cos(az), np.sin(az)], axis=1)
    height = 0.8 + 0.22 * u[:, 4]
    diameter = 1.5e-3 + 3.8e-3 * u[:, 5]
    density = 877.0 + (1734.0 - 877.0) * u[:, 6]
    spin = np.where(u[:, 7] < 0.5, -1.0, 1.0) * 35000.0 * u[:, 8]
    return (pos, height, vel, diameter, density), spin


@pytest.mark.parametrize("magnus", [False, True])
@pytest.mark.parametrize("air", [{}, {"forward_speed_m_s": 4.0, "wind_m_s": (5.0, -3.0)}])
@pytest.mark.parametrize("dt_s", [None, 0.002])
def test_scene_launches_land_within_a_millimetre_of_the_tight_reference(magnus, air, dt_s):
    flight = Flight(magnus=magnus, **air)
    args, spin = scene_launches(7, seed=11)
    ref = reference_landing(*args, flight, spin_rad_s=spin)  # DOP853, rtol 1e-10
    got = fly(*args, flight, dt_s=dt_s, spin_rad_s=spin)
    error = np.hypot(*(got.position_m - ref.position_m).T)
    assert error.max() < 1e-3, error.max()
    if dt_s is None:
        assert error.max() < 1e-4  # the default's margin, as in the drag-only test above
        np.testing.assert_allclose(got.time_s, ref.time_s, rtol=0, atol=1e-5)


def test_same_input_same_bits_whatever_the_batch():
    """Each granule flies on its own: repeating a call, shuffling the batch or flying a
    granule alone gives the same bits (so a seed's landing points do not depend on how
    many granules fly with it)."""
    args, spin = scene_launches(8, seed=12)
    args = (args[0], np.where(np.arange(256) % 37 == 0, 0.0, args[1])) + args[2:]  # a few on the ground
    for flight, dt_s in ((Flight(), None), (Flight(magnus=True, wind_m_s=(2.0, -1.0)), None),
                         (Flight(magnus=True), 0.005)):
        a = fly(*args, flight, dt_s=dt_s, spin_rad_s=spin)
        b = fly(*args, flight, dt_s=dt_s, spin_rad_s=spin)
        assert np.array_equal(a.position_m, b.position_m) and np.array_equal(a.time_s, b.time_s)
        perm = np.random.default_rng(0).permutation(256)
        c = fly(*(x[perm] for x in args), flight, dt_s=dt_s, spin_rad_s=spin[perm])
        assert np.array_equal(c.position_m, a.position_m[perm]) and np.array_equal(c.time_s, a.time_s[perm])
        for i in (1, 100, 255):
            alone = fly(*(x[i:i + 1] for x in args), flight, dt_s=dt_s, spin_rad_s=spin[i:i + 1])
            assert np.array_equal(alone.position_m[0], a.position_m[i]) and alone.time_s[0] == a.time_s[i]


def test_a_column_major_launch_lands_as_a_row_major_one():
    """Launch positions in Fortran order land at the same points, in a C-ordered array (the
    landing kernel's one compiled signature)."""
    args, spin = scene_launches(6, seed=3)
    flight = Flight(magnus=True)
    row_major = fly(*args, flight, spin_rad_s=spin)
    column_major = fly(np.asfortranarray(args[0]), *args[1:], flight, spin_rad_s=spin)
    assert column_major.position_m.flags.c_contiguous
    np.testing.assert_array_equal(column_major.position_m, row_major.position_m)
    np.testing.assert_array_equal(column_major.time_s, row_major.time_s)
