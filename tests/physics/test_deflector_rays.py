"""Exact plan-view plate reflections (spreadgym.physics.analytic.deflector_rays)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spreadgym.config.scene import Deflector
from spreadgym.physics.analytic.deflector_rays import deflect
from spreadgym.physics.compiled.plates import capsule_entry, pack_plates
from spreadgym.physics.contacts import PlateContact
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, Departure
from spreadgym.physics.geometry import zone_radius_m
from spreadgym.physics.stepped.pymunk_deflectors import deflect_pymunk

R_GRANULE = 0.0015
FLOOR = Deflector(x_m=0.0, y_m=-0.3, angle_deg=0.0, length_m=0.6, material="steel")  # along x at y = -0.3


def granules(positions, velocities, spins=None, outcome=None, height=None, vz=None):
    positions = np.atleast_2d(np.asarray(positions, dtype=float))
    n = positions.shape[0]
    return Departure(
        position_m=positions, velocity_m_s=np.atleast_2d(np.asarray(velocities, dtype=float)),
        spin_rad_s=np.zeros(n) if spins is None else np.asarray(spins, dtype=float),
        height_m=np.zeros(n) if height is None else np.asarray(height, dtype=float),
        vertical_velocity_m_s=np.zeros(n) if vz is None else np.asarray(vz, dtype=float),
        time_s=np.full(n, 0.05), outcome=np.full(n, DEPARTED, dtype=np.int8) if outcome is None else outcome,
        model="test", dt_s=0.0,
    )


def incoming(incidence_deg, speed=10.0):
    """Start above the floor plate, aimed at x = 0 on it, `incidence` from the normal."""
    a = math.radians(incidence_deg)
    v = np.array([speed * math.sin(a), -speed * math.cos(a)])
    return np.array([-0.1 * math.tan(a), -0.2]), v


@pytest.mark.parametrize("incidence_deg", [20.0, 45.0, 70.0])
@pytest.mark.parametrize("restitution", [0.3, 0.6, 1.0])
@pytest.mark.parametrize("rotation", ["free", "locked"])
def test_frictionless_plate_reflects_at_the_mirror_angle(incidence_deg, restitution, rotation):
    p, v = incoming(incidence_deg)
    out = deflect(granules(p, v), [FLOOR], [PlateContact(0.0, restitution)], R_GRANULE, rotation)
    v_out = out.velocity_m_s[0]
    assert v_out[0] == pytest.approx(v[0], rel=1e-14)
    assert v_out[1] == pytest.approx(-restitution * v[1], rel=1e-14)
    assert math.degrees(math.atan2(v_out[0], v_out[1] / restitution)) == pytest.approx(incidence_deg, rel=1e-12)
    assert out.spin_rad_s[0] == 0.0
    # the hit is where the path meets the plate face (grown by the granule radius)
    t_hit = (0.1 - 0.5 * FLOOR.thickness_m - R_GRANULE) / -v[1]
    t_rest = out.time_s[0] - 0.05 - t_hit
    hit = p + v * t_hit
    np.testing.assert_allclose(out.position_m[0], hit + v_out * t_rest, rtol=1e-12, atol=1e-14)
    assert np.hypot(*out.position_m[0]) == pytest.approx(zone_radius_m([FLOOR], R_GRANULE), rel=1e-12)


@pytest.mark.parametrize("mu, e", [(0.1, 0.5), (0.2, 0.3), (0.05, 1.0)])
def test_friction_takes_exactly_mu_one_plus_e_vn_off_a_locked_granule(mu, e):
    p, v = incoming(45.0, speed=math.sqrt(50.0))  # v = (5, -5)
    out = deflect(granules(p, v), [FLOOR], [PlateContact(mu, e)], R_GRANULE, "locked")
    assert out.velocity_m_s[0, 0] == pytest.approx(5.0 - mu * (1 + e) * 5.0, rel=1e-13)
    assert out.velocity_m_s[0, 1] == pytest.approx(e * 5.0, rel=1e-13)
    assert out.spin_rad_s[0] == 0.0


def test_friction_never_reverses_the_slip():
    p, v = incoming(20.0)
    v_t = v[0]
    out = deflect(granules(p, v), [FLOOR], [PlateContact(2.0, 0.5)], R_GRANULE, "locked")
    assert out.velocity_m_s[0, 0] == pytest.approx(0.0, abs=1e-15)  # stuck: slip stopped, not reversed
    out = deflect(granules(p, v), [FLOOR], [PlateContact(2.0, 0.5)], R_GRANULE, "free")
    # a free sphere stops slipping after losing (2/7) of the slip: it rolls off the plate
    assert out.velocity_m_s[0, 0] == pytest.approx(v_t * 5 / 7, rel=1e-13)
    # rolling on the face below it (normal +y): contact point velocity v_t - r * spin... zero
    tangent = np.array([-1.0, 0.0])  # z x n
    assert float(out.velocity_m_s[0] @ tangent) - R_GRANULE * out.spin_rad_s[0] == pytest.approx(0.0, abs=1e-12)
    assert v_t > 0 and out.spin_rad_s[0] < 0  # rolling to +x on a floor below: clockwise


def test_free_granule_friction_and_spin_from_the_impulse():
    p, v = incoming(45.0, speed=math.sqrt(50.0))
    mu, e, spin0 = 0.1, 0.5, 300.0
    out = deflect(granules(p, v, spins=[spin0]), [FLOOR], [PlateContact(mu, e)], R_GRANULE, "free")
    # tangent z x n = (-1, 0): v_t = -5, slip = v_t - r spin < 0, so J_t = +mu (1 + e) 5 along the tangent
    jt = mu * (1 + e) * 5.0
    assert out.velocity_m_s[0, 0] == pytest.approx(5.0 - jt, rel=1e-13)
    assert out.spin_rad_s[0] == pytest.approx(spin0 - jt / (0.4 * R_GRANULE), rel=1e-13)


@pytest.mark.parametrize("e", [1.0, 0.5])
def test_two_plate_corner_sends_the_granule_back(e):
    top = Deflector(x_m=0.6, y_m=0.5, angle_deg=0.0, length_m=0.4, material="steel")
    side = Deflector(x_m=0.8, y_m=0.3, angle_deg=90.0, length_m=0.4, material="steel")
    v = np.array([3.0, 1.5])
    out = deflect(granules([0.5, 0.2], v), [top, side], [PlateContact(0.0, e), PlateContact(0.0, e)],
                  R_GRANULE, "locked")
    np.testing.assert_allclose(out.velocity_m_s[0], -e * v, rtol=1e-13)
    assert any("2 bounces" in note for note in out.notes)


def test_end_cap_hit_head_on():
    plate = Deflector(x_m=0.5, y_m=0.0, angle_deg=0.0, length_m=0.2, material="steel")  # x from 0.4 to 0.6
    out = deflect(granules([0.2, 0.0], [4.0, 0.0]), [plate], [PlateContact(0.3, 0.6)], R_GRANULE, "free")
    np.testing.assert_allclose(out.velocity_m_s[0], [-2.4, 0.0], atol=1e-14)
    # an off-centre hit on the cap: the normal goes through the cap centre
    reach = 0.5 * plate.thickness_m + R_GRANULE
    b = 0.6 * reach
    out = deflect(granules([0.2, b], [4.0, 0.0]), [plate], [PlateContact(0.0, 1.0)], R_GRANULE, "locked")
    nx, ny = -math.sqrt(1 - 0.36), 0.6
    v_in = np.array([4.0, 0.0])
    vn = v_in @ np.array([nx, ny])
    np.testing.assert_allclose(out.velocity_m_s[0], v_in - 2 * vn * np.array([nx, ny]), rtol=1e-12, atol=1e-12)


def test_capsule_hit_against_brute_force():
    rng = np.random.default_rng(7)
    n = 400
    P = rng.uniform(-0.5, 0.5, (n, 2))
    V = rng.normal(size=(n, 2))
    a, b = np.array([-0.1, 0.05]), np.array([0.2, -0.1])
    reach = np.full(n, 0.03)
    plate = Deflector(x_m=0.05, y_m=-0.025, angle_deg=math.degrees(math.atan2(-0.15, 0.3)),
                      length_m=math.hypot(0.3, 0.15), material="steel")
    table = pack_plates([plate], [0.0], [1.0])
    a, b = table[0, :2], table[0, 2:4]  # (-0.1, 0.05) and (0.2, -0.1) to rounding
    hits = [capsule_entry(*P[i], *V[i], table, 0, reach[i]) for i in range(n)]
    t, normal = np.array([h[0] for h in hits]), np.array([h[1:] for h in hits])
    ts = np.linspace(0, 2, 20001)
    for i in range(n):
        path = P[i] + ts[:, None] * V[i]
        d = path - a
        s = np.clip((d @ (b - a)) / ((b - a) @ (b - a)), 0, 1)
        dist = np.hypot(*(d - s[:, None] * (b - a)).T)
        inside = np.nonzero(dist <= reach[i])[0]
        if inside.size == 0 or inside[0] == 0:
            continue  # missed, or started inside (handled elsewhere)
        assert abs(t[i] - ts[inside[0]]) <= 2 * (ts[1] - ts[0])
        hit = P[i] + t[i] * V[i]
        assert float(normal[i] @ V[i]) < 0  # approaching
        assert np.hypot(*normal[i]) == pytest.approx(1.0)
        # the normal points from the segment's nearest point to the hit point
        d = hit - a
        s = np.clip((d @ (b - a)) / ((b - a) @ (b - a)), 0, 1)
        np.testing.assert_allclose(normal[i], (d - s * (b - a)) / reach[i], atol=1e-9)


def test_passing_granules_are_advanced_to_the_zone_circle():
    plate = Deflector(x_m=0.0, y_m=-0.3, angle_deg=0.0, length_m=0.2, material="steel")
    v = np.array([0.0, 8.0])
    dep = granules([[0.0, 0.16], [0.1, 0.12]], [v, [6.0, 1.0]], height=[0.0, 0.01], vz=[0.0, 1.0])
    out = deflect(dep, [plate], [PlateContact(0.5, 0.5)], R_GRANULE, "free")
    zone = zone_radius_m([plate], R_GRANULE)
    np.testing.assert_array_equal(out.velocity_m_s, dep.velocity_m_s)
    np.testing.assert_allclose(np.hypot(*out.position_m.T), zone, rtol=1e-13)
    dt = out.time_s - dep.time_s
    assert np.all(dt > 0)
    np.testing.assert_allclose(out.height_m, dep.height_m + dep.vertical_velocity_m_s * dt - 0.5 * 9.81 * dt**2)
    np.testing.assert_allclose(out.vertical_velocity_m_s, dep.vertical_velocity_m_s - 9.81 * dt)


def test_no_plates_returns_the_departure_itself():
    dep = granules([0.15, 0.0], [1.0, 2.0])
    assert deflect(dep, [], [], R_GRANULE, "free") is dep


def test_retained_granules_are_left_alone():
    outcome = np.array([DEPARTED, RETAINED_STUCK], dtype=np.int8)
    p, v = incoming(30.0)
    dep = granules([p, [0.05, 0.0]], [v, [0.0, 1.5]], outcome=outcome)
    out = deflect(dep, [FLOOR], [PlateContact(0.2, 0.5)], R_GRANULE, "free")
    np.testing.assert_array_equal(out.position_m[1], dep.position_m[1])
    np.testing.assert_array_equal(out.velocity_m_s[1], dep.velocity_m_s[1])
    assert out.time_s[1] == dep.time_s[1]
    np.testing.assert_array_equal(out.outcome, outcome)


@pytest.mark.parametrize("rotation", ["free", "locked"])
def test_many_granules_many_plates_no_nan(rotation):
    rng = np.random.default_rng(11)
    n = 3000
    angle = rng.uniform(0, 2 * np.pi, n)
    pos = 0.15 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    heading = angle + rng.uniform(-1.2, 1.2, n)
    vel = rng.uniform(0.0, 30.0, n)[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    vel[:5] = 0.0  # at rest: nothing to do, stays finite
    plates = [
        Deflector(x_m=0.3, y_m=0.0, angle_deg=80.0, length_m=0.3, material="steel"),
        Deflector(x_m=-0.25, y_m=0.2, angle_deg=-30.0, length_m=0.25, material="steel", thickness_m=0.01),
        Deflector(x_m=0.0, y_m=-0.35, angle_deg=5.0, length_m=0.4, material="steel"),
        Deflector(x_m=0.2, y_m=0.3, angle_deg=120.0, length_m=0.2, material="steel"),
    ]
    contacts = [PlateContact(0.4, 0.35), PlateContact(0.0, 1.0), PlateContact(1.5, 0.0), PlateContact(0.2, 0.8)]
    radius = rng.uniform(0.001, 0.003, n)
    dep = granules(pos, vel, spins=rng.normal(0, 500, n))
    out = deflect(dep, plates, contacts, radius, rotation)
    for arr in (out.position_m, out.velocity_m_s, out.spin_rad_s, out.time_s, out.height_m):
        assert np.all(np.isfinite(arr))
    # every granule still moving ends on the zone circle; a locked granule stopped dead
    # by the e = 0, mu = 1.5 plate (or at rest from the start) stays where it is
    moving = np.hypot(*out.velocity_m_s.T) > 0
    zone = zone_radius_m(plates, float(radius.max()))
    np.testing.assert_allclose(np.hypot(*out.position_m[moving].T), zone, rtol=1e-9)
    assert np.all(np.hypot(*out.position_m[~moving].T) <= zone)
    assert any("did not leave the zone" in note for note in out.notes)
    # energy never grows at a bounce (restitution <= 1, friction dissipates)
    mass_free = 1.0 if rotation == "free" else 0.0
    e_in = np.sum(vel**2, axis=1) + mass_free * 0.4 * (radius * dep.spin_rad_s) ** 2
    e_out = np.sum(out.velocity_m_s**2, axis=1) + mass_free * 0.4 * (radius * out.spin_rad_s) ** 2
    assert np.all(e_out <= e_in * (1 + 1e-12) + 1e-12)
    if rotation == "locked":
        np.testing.assert_array_equal(out.spin_rad_s[out.spin_rad_s != dep.spin_rad_s], 0.0)


def test_agrees_with_the_pymunk_stage():

    plate = Deflector(x_m=0.0, y_m=-0.3, angle_deg=10.0, length_m=0.6, material="steel")
    rng = np.random.default_rng(2)
    n = 12
    pos = np.column_stack([rng.uniform(-0.15, 0.05, n), np.full(n, -0.15)])
    vel = np.column_stack([rng.uniform(-3, 6, n), rng.uniform(-12, -6, n)])
    contacts = [PlateContact(0.3, 0.45)]
    radius = np.full(n, R_GRANULE)
    for rotation in ("free", "locked"):
        ours = deflect(granules(pos, vel), [plate], contacts, radius, rotation)
        theirs = deflect_pymunk(granules(pos, vel), [plate], contacts, radius, np.full(n, 2.4e-5), rotation)
        np.testing.assert_allclose(ours.velocity_m_s, theirs.velocity_m_s, rtol=0.02, atol=0.05)
        np.testing.assert_allclose(ours.position_m, theirs.position_m, atol=2e-3)
