"""Deflector plates in pymunk: reflection law, and the closed-form pass-by."""

import math

import numpy as np
import pytest

from spreadgym.config.scene import Deflector
from spreadgym.physics.compiled.plates import segment_distance
from spreadgym.physics.contacts import PlateContact
from spreadgym.physics.departure import DEPARTED, Departure
from spreadgym.physics.stepped.pymunk_deflectors import deflect_pymunk


def one_granule(position, velocity):
    return Departure(
        position_m=np.array([position], dtype=float), velocity_m_s=np.array([velocity], dtype=float),
        spin_rad_s=np.zeros(1), height_m=np.zeros(1), vertical_velocity_m_s=np.zeros(1),
        time_s=np.zeros(1), outcome=np.array([DEPARTED], dtype=np.int8), model="test", dt_s=1e-4,
    )


@pytest.mark.parametrize("incidence_deg", [20.0, 45.0, 70.0])
@pytest.mark.parametrize("restitution", [0.3, 0.6, 1.0])
def test_frictionless_plate_reflects_at_the_mirror_angle_with_restitution(incidence_deg, restitution):
    """Plate along x at y = -0.3 m; the granule comes in at `incidence` from the normal."""
    plate = Deflector(x_m=0.0, y_m=-0.3, angle_deg=0.0, length_m=0.6, material="steel")
    a = math.radians(incidence_deg)
    speed = 10.0
    v_in = np.array([speed * math.sin(a), -speed * math.cos(a)])
    start = np.array([-0.1 * math.tan(a), -0.2])  # hits the plate at x = 0
    out = deflect_pymunk(one_granule(start, v_in), [plate], [PlateContact(0.0, restitution)],
                         np.array([0.0015]), np.array([2.4e-5]), "locked")
    v_out = out.velocity_m_s[0]
    assert v_out[0] == pytest.approx(v_in[0], rel=1e-3)  # tangential kept
    assert v_out[1] == pytest.approx(-restitution * v_in[1], rel=2e-3)  # normal reversed times e
    expected_angle = math.degrees(math.atan2(v_in[0], restitution * -v_in[1]))
    assert math.degrees(math.atan2(v_out[0], v_out[1])) == pytest.approx(expected_angle, abs=0.2)


def test_friction_takes_tangential_speed_off_a_locked_granule():
    plate = Deflector(x_m=0.0, y_m=-0.3, angle_deg=0.0, length_m=0.6, material="steel")
    v_in = np.array([5.0, -5.0])
    out = deflect_pymunk(one_granule([-0.15, -0.15], v_in), [plate], [PlateContact(0.2, 0.5)],
                         np.array([0.0015]), np.array([2.4e-5]), "locked")
    # Coulomb impulse: |dv_t| = mu (1 + e) |v_n| = 0.2 * 1.5 * 5 = 1.5 m/s
    assert out.velocity_m_s[0, 0] == pytest.approx(5.0 - 1.5, rel=0.02)


def test_granules_that_miss_every_plate_go_straight_to_the_zone_edge():
    plate = Deflector(x_m=0.0, y_m=-0.3, angle_deg=0.0, length_m=0.2, material="steel")
    v_in = np.array([0.0, 8.0])  # flying forward, away from the plate behind
    out = deflect_pymunk(one_granule([0.0, 0.16], v_in), [plate], [PlateContact(0.5, 0.5)],
                         np.array([0.0015]), np.array([2.4e-5]), "free")
    np.testing.assert_array_equal(out.velocity_m_s[0], v_in)
    assert out.time_s[0] > 0 and np.hypot(*out.position_m[0]) > 0.3
    # height falls ballistically over the time spent in the zone
    assert out.height_m[0] == pytest.approx(-0.5 * 9.81 * out.time_s[0] ** 2)


def test_segment_distance_matches_brute_force():
    rng = np.random.default_rng(3)
    p0, p1 = rng.normal(size=(40, 2)), rng.normal(size=(40, 2))
    a, b = np.array([0.1, -0.2]), np.array([0.7, 0.5])
    s = np.linspace(0, 1, 401)
    brute = [np.min(np.hypot(*((q0[None] + s[:, None] * (q1 - q0))[:, None] - (a + s[:, None] * (b - a))[None]).T))
             for q0, q1 in zip(p0, p1)]
    got = [segment_distance(*q0, *q1, *a, *b) for q0, q1 in zip(p0, p1)]
    np.testing.assert_allclose(got, brute, atol=6e-3)
