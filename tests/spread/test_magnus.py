"""Spin in flight (Magnus lift, spin decay): off is today's flight to the bit; on matches a
tight solve_ivp of the same equations; the spin's closed form matches its ODE."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.stats import qmc

from spreadgym.config.scene import Flight, load_scene
from spreadgym.errors import ConfigError
from spreadgym.physics import magnus
from spreadgym.spread.flight import fly, reference_landing

MU = 1.81e-5


def launch_states(m, seed):
    """Scrambled Sobol launch states (2^m) covering the paper (~9-10 m/s, 0.8 m) and field
    (~24-29 m/s, 0.9 m) scenes: speed 8-32 m/s, elevation -10..25 deg, any azimuth, spin
    2000-17000 rad/s of either sense, diameter 2-4 mm, density 877-1734 kg/m3, height 0.8-0.9 m."""
    u = qmc.Sobol(8, scramble=True, seed=seed).random_base2(m)
    speed = 8.0 + 24.0 * u[:, 0]
    el = np.radians(-10.0 + 35.0 * u[:, 1])
    az = 2.0 * np.pi * u[:, 2]
    spin = np.where(u[:, 3] < 0.5, -1.0, 1.0) * (2000.0 + 15000.0 * u[:, 4])
    diameter = 2e-3 + 2e-3 * u[:, 5]
    density = 877.0 + (1734.0 - 877.0) * u[:, 6]
    height = 0.8 + 0.1 * u[:, 7]
    vel = np.stack([speed * np.cos(el) * np.cos(az), speed * np.cos(el) * np.sin(az), speed * np.sin(el)], axis=1)
    pos = 0.3 * np.stack([np.cos(az), np.sin(az)], axis=1)
    return (pos, height, vel, diameter, density), spin


@pytest.mark.parametrize("dt_s", [None, 0.01])
@pytest.mark.parametrize("flight", [Flight(), Flight(forward_speed_m_s=4.0, wind_m_s=(5.0, -3.0))])
def test_magnus_off_is_todays_flight_to_the_bit(flight, dt_s):
    args, spin = launch_states(9, seed=1)
    today = fly(*args, flight, dt_s=dt_s)
    off = fly(*args, flight, dt_s=dt_s, spin_rad_s=spin)
    assert flight.magnus is False
    assert np.array_equal(off.position_m, today.position_m) and np.array_equal(off.time_s, today.time_s)
    # on, but nothing for the lift to act on: exactly the drag-only flight as well
    on = flight.model_copy(update={"magnus": True})
    for quiet in (fly(*args, on, dt_s=dt_s), fly(*args, on, dt_s=dt_s, spin_rad_s=np.zeros_like(spin)),
                  fly(*args, on.model_copy(update={"lift_coefficient_max": 0.0}), dt_s=dt_s, spin_rad_s=spin)):
        assert np.array_equal(quiet.position_m, today.position_m) and np.array_equal(quiet.time_s, today.time_s)


@pytest.mark.parametrize(
    "flight",
    [Flight(magnus=True), Flight(magnus=True, forward_speed_m_s=4.0, wind_m_s=(5.0, -3.0)),
     Flight(magnus=True, forward_speed_m_s=12.0, wind_m_s=(-6.0, 6.0))],
)
def test_magnus_flight_matches_a_tight_solve_ivp_within_a_millimetre(flight):
    args, spin = launch_states(6, seed=2)
    ref = reference_landing(*args, flight, spin_rad_s=spin)  # DOP853, rtol 1e-10, spin as a state
    got = fly(*args, flight, spin_rad_s=spin)
    error = np.hypot(*(got.position_m - ref.position_m).T)
    assert error.max() < 1e-3, error.max()
    np.testing.assert_allclose(got.time_s, ref.time_s, rtol=0, atol=1e-5)
    # the lift matters at these spins, so the check has teeth: metres against the drag-only flight
    plain = reference_landing(*args, flight.model_copy(update={"magnus": False}))
    shift = np.hypot(*(plain.position_m - ref.position_m).T)
    assert np.median(shift) > 0.3 and shift.max() > 1.0


def test_fixed_step_rk4_with_magnus_matches_the_reference():
    flight = Flight(magnus=True, forward_speed_m_s=3.0, wind_m_s=(2.0, 1.0))
    args, spin = launch_states(5, seed=3)
    ref = reference_landing(*args, flight, spin_rad_s=spin)
    got = fly(*args, flight, dt_s=0.002, spin_rad_s=spin)
    assert np.hypot(*(got.position_m - ref.position_m).T).max() < 1e-3


def test_lift_points_along_omega_cross_v_and_mirrors_with_the_spin():
    # thrown along +x from 0.9 m: a ccw spin (+z) pushes towards +y (z x x = y), cw towards -y
    n = 3
    pos = np.zeros((n, 2))
    vel = np.tile([25.0, 0.0, 0.0], (n, 1))
    spin = np.array([8000.0, -8000.0, 0.0])
    land = fly(pos, 0.9, vel, 3e-3, 1734.0, Flight(magnus=True), spin_rad_s=spin).position_m
    assert land[0, 1] > 0.2 and land[1, 1] < -0.2 and land[2, 1] == 0.0
    assert land[0, 0] == pytest.approx(land[1, 0], abs=1e-9) and land[0, 1] == pytest.approx(-land[1, 1], abs=1e-9)
    # a whole sample mirrored in the x axis with its spins reversed lands mirrored
    args, spin = launch_states(7, seed=4)
    pos, height, vel, d, rho = args
    flip = np.array([1.0, -1.0])
    a = fly(pos, height, vel, d, rho, Flight(magnus=True), spin_rad_s=spin).position_m
    b = fly(pos * flip, height, vel * np.array([1.0, -1.0, 1.0]), d, rho, Flight(magnus=True),
            spin_rad_s=-spin).position_m
    np.testing.assert_allclose(b, a * flip, rtol=0, atol=1e-9)


@pytest.mark.parametrize("spin0", [15000.0, -3000.0, 400.0, 60.0])
def test_spin_closed_form_solves_the_torque_law(spin0):
    d, rho_p = np.array([2e-3]), np.array([877.0])
    table = magnus.spin_table(np.array([spin0]), d, rho_p, 1.2, MU)
    t_end = 60.0  # long enough for the larger spins to reach the Stokes branch (Re_R < 32)
    sol = solve_ivp(lambda _t, w: magnus.spin_rate(w, d, rho_p, 1.2, MU), (0.0, t_end), [spin0],
                    method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    times = np.linspace(0.0, t_end, 241)
    got = np.array([magnus.spin_at(np.array([t]), table)[0] for t in times])
    want = sol.sol(times)[0]
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-9 * abs(spin0))
    assert abs(got[-1]) < abs(spin0) and np.sign(got[-1]) == np.sign(spin0)


@pytest.mark.parametrize("spin0", [15000.0, -3000.0, 60.0])
def test_one_closed_form_spin_per_step_serves_every_stage(spin0):
    # the flight's stages take 1/|omega| from a series around the step's start: it must
    # equal the closed form at every stage fraction, and hand back to it where the step
    # reaches the Stokes branch (60 rad/s is on it from the start) or q h is too large
    d, rho_p = np.array([2e-3]), np.array([877.0])
    table = magnus.spin_table(np.array([spin0]), d, rho_p, 1.2, MU)
    fractions = [0.0, 0.2, 0.3, 0.8, 8 / 9, 1.0]
    served = 0
    for t, h in [(0.0, 0.05), (0.7, 0.01), (30.0, 0.05), (0.0, 2.0)]:
        u, growth, qh = magnus.step_spin_base(t, h, table, 0)
        for f in fractions:
            exact = magnus.inverse_spin_size(t + f * h, table, 0)
            assert exact == pytest.approx(1.0 / abs(magnus.spin_at(np.array([t + f * h]), table)[0]), rel=1e-14)
            if qh >= 0.0:
                assert magnus.step_inverse_spin(u, growth, qh, f) == pytest.approx(exact, rel=1e-13)
        served += qh >= 0.0
        if qh >= 0.0:
            assert t + h < table[4, 0] and qh <= magnus.STEP_SERIES_LIMIT
    assert served == (0 if spin0 == 60.0 else 2)  # (0, 2 s) is too long a step for the series


def test_lift_factor_is_the_lift_law_written_out():
    # f (-r_y, r_x) must be (3/8)(rho/rho_p) C_L(S) |r|^2 / r along the horizontal normal,
    # S = r |omega| r_h / |r|^2: check the division-free form against the law term by term
    rng = np.random.default_rng(3)
    rho, rho_p, c_max, s_sat = 1.2, 1300.0, 0.37, 0.34
    for _ in range(200):
        r = rng.uniform(0.5e-3, 2.5e-3)
        omega = rng.choice([-1.0, 1.0]) * rng.uniform(10.0, 2e4)
        rel = rng.normal(size=3) * rng.uniform(0.1, 30.0)
        speed2 = float(rel @ rel)
        r_h = math.hypot(rel[0], rel[1])
        s = r * abs(omega) * r_h / speed2
        want = 0.375 * rho / rho_p * magnus.lift_coefficient(s, c_max, s_sat) * speed2 / r
        lift = math.copysign(0.375 * rho / rho_p * c_max / s_sat, omega)
        f = magnus.lift_factor(lift, (r / s_sat) ** 2, 1.0 / abs(omega), rel[0], rel[1], speed2)
        assert abs(f) * r_h == pytest.approx(want, rel=1e-12)
        assert math.copysign(1.0, f) == math.copysign(1.0, omega)
    assert magnus.lift_factor(1.0, 1e-6, 1e-3, 0.0, 0.0, 0.0) == 0.0  # at rest in the wind: no lift, no NaN


def test_spin_loses_a_quarter_to_a_third_in_the_first_second_at_spreader_spins():
    # as docs/magnus.md states: a 3 mm compound granule at 5000-12000 rad/s
    table = magnus.spin_table(np.array([5000.0, 12000.0]), np.array([3e-3, 3e-3]), 1734.0, 1.2, MU)
    left = magnus.spin_at(np.ones(2), table) / np.array([5000.0, 12000.0])
    assert np.all((left > 0.65) & (left < 0.8)), left


def test_coefficients_hold_their_stated_limits():
    s = np.linspace(0.0, 5.0, 2001)
    c_l = magnus.lift_coefficient(s, 0.37, 0.34)
    assert c_l[0] == 0.0 and np.all(np.diff(c_l) > 0) and c_l.max() < 0.37
    assert np.all(c_l[s >= 0.5] > 0.95 * 0.37)  # within 5 % of the plateau from Rr = 2 S = 1 on
    assert np.all(c_l <= 2.0 * s)  # below the Stokes-flow lift C_L = Rr (Rubinow & Keller)
    # torque: the Stokes torque 8 pi mu r^3 omega below Re_R = 32, continuous at 32
    r, omega = 1e-4, 50.0
    re_r = 1.2 * (2 * r) ** 2 * omega / MU
    assert re_r < 32
    torque = 0.5 * 1.2 * r**5 * magnus.torque_coefficient(re_r) * omega**2
    assert torque == pytest.approx(8 * math.pi * MU * r**3 * omega, rel=1e-12)
    below, above = magnus.torque_coefficient([32.0 * (1 - 1e-12), 32.0])
    assert below == pytest.approx(above, rel=2e-3)


def test_bad_magnus_input_is_named():
    for key, value in (("flight.lift_coefficient_max", -0.1), ("flight.lift_saturation_spin_parameter", 0.0),
                       ("flight.air_viscosity_pa_s", -1e-5), ("flight.magnus", "yes")):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            load_scene("paper", {key: value})
    args, spin = launch_states(3, seed=5)
    with pytest.raises(ConfigError, match="spin_rad_s"):
        fly(*args, Flight(magnus=True), spin_rad_s=spin[:-1])
    with pytest.raises(ConfigError, match="spin_rad_s"):
        fly(*args, Flight(magnus=True), spin_rad_s=np.full_like(spin, np.nan))


def test_granules_on_the_ground_land_at_once_with_the_lift_on():
    # a launch at height 0 (the pipeline clips launches below the ground to 0) lands where
    # it is at time 0, spinning or not; the others in the batch still feel the lift
    args, spin = launch_states(4, seed=6)
    pos, height, vel, d, rho = args
    height = np.where(np.arange(16) % 3 == 0, 0.0, height)
    got = fly(pos, height, vel, d, rho, Flight(magnus=True), spin_rad_s=spin)
    ground = height == 0.0
    np.testing.assert_array_equal(got.time_s[ground], 0.0)
    np.testing.assert_array_equal(got.position_m[ground], pos[ground])
    plain = fly(pos, height, vel, d, rho, Flight(), spin_rad_s=spin)
    assert np.all(np.hypot(*(got.position_m - plain.position_m)[~ground].T) > 0.05)
    with pytest.raises(ConfigError, match="spinner.height_m"):
        fly(pos, np.where(ground, -1e-3, height), vel, d, rho, Flight(magnus=True), spin_rad_s=spin)
