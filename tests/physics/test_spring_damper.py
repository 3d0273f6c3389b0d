"""The spring-damper spinner model: exact slide, isolated impact, pymunk agreement, guards."""

import dataclasses
import math

import numpy as np
import pytest
from test_pymunk_spinner import exact_sliding_departure_speed, large_disc

from spreadgym.config.materials import load_library
from spreadgym.config.scene import load_scene
from spreadgym.errors import ConfigError, MaterialError
from spreadgym.physics.calibration import critical_time_step, spring_dashpot
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.departure import DEPARTED
from spreadgym.physics.stepped import spring_damper as sd
from spreadgym.physics.stepped import vane_contact as vc
from spreadgym.physics.stepped.pymunk_spinner import simulate_pymunk


@pytest.mark.parametrize("rpm, pitch_deg, vane_friction", [(500, 0.0, 0.3), (800, -30.0, 0.6), (1100, 30.0, 0.0)])
def test_locked_granule_departs_at_the_exact_sliding_speed(prepare, rpm, pitch_deg, vane_friction):
    scene = large_disc(rpm, pitch_deg, vane_friction, **{"sim.granules": 3})
    granules, contacts = prepare(scene)
    departure = sd.simulate_spring_damper(scene, granules, contacts)
    assert np.all(departure.outcome == DEPARTED)
    exact = exact_sliding_departure_speed(scene, contacts.disc_friction, vane_friction, granules.diameter_m[0])
    assert departure.speed_m_s.mean() == pytest.approx(exact, rel=0.01)


def vane_overlap(law, angle_rad, position_m, reach_m):
    """Signed overlap of a granule at `position_m` (2,) with its nearest vane: reach - distance (m)."""
    turn = np.array([[math.cos(angle_rad), -math.sin(angle_rad)], [math.sin(angle_rad), math.cos(angle_rad)]])
    inner, direction = law.inner_m @ turn.T, law.direction @ turn.T
    along = np.clip(np.sum((position_m - inner) * direction, axis=1), 0.0, law.length_m)
    return reach_m - np.min(np.hypot(*(position_m - inner - along[:, None] * direction).T))


def amplification_per_step(k, c, mass, dt):
    """Spectral radius of one semi-implicit Euler step of m x'' + c x' + k x = 0 (above 1: the contact grows)."""
    w2h2, ch = k / mass * dt * dt, c / mass * dt
    matrix = np.array([[1.0 - w2h2, dt * (1.0 - ch)], [-w2h2 / dt, 1.0 - ch]])
    return float(np.max(np.abs(np.linalg.eigvals(matrix))))


def vane_impact(rotation="free", rpm=500.0, at_radius_m=0.1):
    """One granule at rest on a frictionless disc, hit by radial vane 0 of the paper
    scene, stepped exactly as the model steps (same kernel, same update order).

    Returns (normal rebound ratio relative to the vane surface, contact duration (s),
    the pair's e and t_c)."""

    scene = load_scene("paper", {"granule.rotation": rotation, "spinner.rpm": rpm, "contact.disc_friction": 0.0})
    contacts = resolve_contacts(scene, load_library())
    law = vc.VaneContactLaw.for_scene(scene, contacts)
    granule_radius = np.array([0.0015])
    dt = sd.choose_spring_damper_step(scene, contacts, float(granule_radius[0])).dt_s
    omega = scene.spinner.omega_rad_s
    rows = vc.GranuleContactData.build(granule_radius, law.half_thickness_m, rotation == "locked")
    start = 0.05  # rad ahead of the vane
    x = at_radius_m * np.array([[math.cos(start)], [math.sin(start)]])
    v, s = np.zeros((2, 1)), np.zeros(1)
    t, previous, t_in, vn_in = 0.0, None, None, None
    for _ in range(100_000):
        angle = omega * t
        overlap = vane_overlap(law, angle, x[:, 0], rows.reach_m[0])
        normal = np.array([-math.sin(angle), math.cos(angle)])
        surface = omega * np.array([-x[1, 0], x[0, 0]])
        vn = float((v[:, 0] - surface) @ normal)
        if previous is not None:
            if previous[0] <= 0.0 < overlap and t_in is None:
                t_in, vn_in = t - dt * overlap / (overlap - previous[0]), previous[1]
            elif previous[0] > 0.0 >= overlap and t_in is not None:
                t_out = t - dt * overlap / (overlap - previous[0])
                return -vn / vn_in, t_out - t_in, contacts.vane_restitution, contacts.vane_contact_time_s
        previous = (overlap, vn)
        step = vc.ContactStep(angle, omega, np.array([True]), np.zeros((2, 1)), dt)
        dv, dspin, _ = vc.vane_contact_change(law, step, x, v, s, rows, False)
        v, s = v + dv, s + dspin
        x = x + dt * v
        t += dt
    raise AssertionError("the impact did not end")


@pytest.mark.parametrize("rotation", ["free", "locked"])
def test_isolated_vane_impact_rebounds_with_the_pair_restitution_and_contact_time(rotation):
    ratio, duration, e, t_c = vane_impact(rotation)
    assert ratio == pytest.approx(e, rel=0.02)
    assert duration == pytest.approx(t_c, rel=0.05)


def test_impact_over_every_entry_phase_at_the_default_step():
    """Averaged over where in a step the contact starts, the rebound is e within 2 %."""
    e, t_c, mass = 0.43, 2.323e-4, 2.45e-5
    contact = spring_dashpot(mass, e, t_c)
    ratio, duration, peak = sd.impact_rebound(contact.stiffness_n_per_m, contact.damping_ns_per_m, mass,
                                              t_c / sd.CONTACT_STEPS, (np.arange(32) + 0.5) / 32)
    assert ratio.mean() == pytest.approx(e, rel=0.02)
    assert np.all(np.abs(ratio / e - 1.0) < 0.03)
    assert np.all(np.abs(duration / t_c - 1.0) < 0.02)
    assert np.all(peak <= 1.0 + 1e-12)


def test_critical_step_is_the_scheme_s_exact_stability_limit():
    for e, t_c, mass in [(0.43, 2.323e-4, 2.45e-5), (0.525, 1.673e-4, 6.6e-4), (0.9, 1e-4, 1e-6)]:
        contact = spring_dashpot(mass, e, t_c)
        k, c = contact.stiffness_n_per_m, contact.damping_ns_per_m
        limit = vc.explicit_critical_step_s(e, t_c)
        assert limit == pytest.approx(critical_time_step(mass, k, c), rel=1e-12)
        assert amplification_per_step(k, c, mass, 0.999 * limit) < 1.0
        assert amplification_per_step(k, c, mass, 1.001 * limit) > 1.0


def test_agrees_with_the_pymunk_model_on_the_paper_scene(prepare):
    scene = load_scene("paper", {"sim.granules": 40, "feed.spread_m": 0.0})
    granules, contacts = prepare(scene)
    spring = sd.simulate_spring_damper(scene, granules, contacts)
    impulse = simulate_pymunk(scene, granules, contacts)
    assert np.all(spring.departed) and np.all(impulse.departed)
    assert spring.speed_m_s.mean() == pytest.approx(impulse.speed_m_s.mean(), rel=0.01)
    assert spring.spin_rad_s.mean() == pytest.approx(impulse.spin_rad_s.mean(), rel=0.02)
    assert spring.time_s.mean() == pytest.approx(impulse.time_s.mean(), rel=0.02)


def test_default_step_resolves_the_contact_and_is_reported(prepare):
    scene = load_scene("paper", {"sim.granules": 4, "feed.spread_m": 0.0})
    granules, contacts = prepare(scene)
    departure = sd.simulate_spring_damper(scene, granules, contacts)
    t_c = contacts.vane_contact_time_s
    assert departure.model == "spring-damper"
    assert departure.dt_s == pytest.approx(t_c / sd.CONTACT_STEPS)
    assert departure.dt_s <= 0.5 * vc.explicit_critical_step_s(contacts.vane_restitution, t_c)
    assert any("time step" in note and "critical" in note for note in departure.notes)


def test_hand_set_step_beyond_the_critical_step_is_refused(prepare):
    scene = load_scene("paper", {"sim.granules": 2, "sim.dt_s": 2e-4})
    granules, contacts = prepare(scene)
    limit = vc.explicit_critical_step_s(contacts.vane_restitution, contacts.vane_contact_time_s)
    with pytest.raises(ConfigError) as info:
        sd.simulate_spring_damper(scene, granules, contacts)
    assert info.value.key == "sim.dt_s"
    assert f"{limit:.3g}" in str(info.value)
    with pytest.raises(ConfigError, match="sim.dt_s"):
        sd.simulate_spring_damper(load_scene("paper", {"sim.granules": 2}), granules, contacts, dt_s=1.5 * limit)
    # Below the limit a hand-set step is used as given.
    ok = sd.simulate_spring_damper(load_scene("paper", {"sim.granules": 2, "feed.spread_m": 0.0}), granules,
                                   contacts, dt_s=1e-5)
    assert ok.dt_s == 1e-5


def test_unchecked_step_past_the_limit_runs_and_shows_the_blow_up(prepare):
    scene = load_scene("paper", {"sim.granules": 32, "feed.spread_m": 0.0})
    granules, contacts = prepare(scene)
    limit = vc.explicit_critical_step_s(contacts.vane_restitution, contacts.vane_contact_time_s)
    departure = sd.simulate_spring_damper(scene, granules, contacts, dt_s=1.3 * limit, unchecked=True)
    good = sd.simulate_spring_damper(scene, granules, contacts)
    assert np.all(np.isfinite(departure.velocity_m_s))
    # Energy gained in the contacts: far faster than the disc could throw them.
    assert departure.speed_m_s.max() > 1.5 * good.speed_m_s.max()


def test_missing_contact_time_names_the_pair_and_the_scene_key(prepare):
    scene = load_scene("paper", {"sim.granules": 2})
    granules, contacts = prepare(scene)
    with pytest.raises(MaterialError, match="compound-10-16-10/mc.*contact.vane_contact_time_s"):
        sd.simulate_spring_damper(scene, granules, dataclasses.replace(contacts, vane_contact_time_s=None))


def test_bookkeeping_no_nan_and_deterministic(prepare):
    for overrides, repeat in (({"spinner.rpm": 1100, "vanes.pitch_deg": 30.0}, True),
                              ({"granule.rotation": "locked", "vanes.pitch_deg": -30.0}, False)):
        scene = load_scene("paper", {"sim.granules": 12, "feed.spread_m": 0.0, **overrides})
        granules, contacts = prepare(scene)
        first = sd.simulate_spring_damper(scene, granules, contacts, track_count=2)
        assert set(np.unique(first.outcome)) <= {0, 1, 2}
        for name in ("position_m", "velocity_m_s", "spin_rad_s", "height_m", "vertical_velocity_m_s", "time_s"):
            assert np.all(np.isfinite(getattr(first, name))), (overrides, name)
        assert np.allclose(np.hypot(*first.position_m[first.departed].T), scene.spinner.radius_m)
        assert len(first.tracks) == 2
        if repeat:
            second = sd.simulate_spring_damper(scene, granules, contacts)
            np.testing.assert_array_equal(first.velocity_m_s, second.velocity_m_s)
            np.testing.assert_array_equal(first.time_s, second.time_s)
        else:  # locked: no spin
            assert np.all(first.spin_rad_s == 0.0)


def test_slow_disc_retains_granules_as_stuck(prepare):
    scene = load_scene("paper", {"sim.granules": 6, "spinner.rpm": 40, "feed.drop_height_m": 0.0,
                                 "feed.spread_m": 0.0})
    departure = sd.simulate_spring_damper(scene, *prepare(scene))
    assert departure.outcome_counts()["retained: stuck on the disc"] == 6
