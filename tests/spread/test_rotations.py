"""Release-angle copies (spread.rotations): the law they draw from, what they keep, the
turned flight against flying every copy, pooling, and an unbiased, less noisy CV."""

import dataclasses

import numpy as np
import pytest
from scipy.special import i0e, i1e

from spreadgym.config.materials import load_library
from spreadgym.config.scene import load_scene, scene_with
from spreadgym.physics.granules import rotate, sample_granules
from spreadgym.spread import discs, flight, rotations, twin
from spreadgym.spread.pipeline import run_scene
from spreadgym.spread.reference import pool_runs

LIBRARY = load_library()


def paper(**settings):
    return scene_with(load_scene("paper"), {"sim.granules": 4096, **settings})


def sampled(scene):
    return sample_granules(scene, LIBRARY.fertilizer_of(scene), scene.sim.replicates)


def mean_resultant(kappa):
    """E[cos(theta - theta0)] under von Mises(theta0, kappa): I1(kappa) / I0(kappa)."""
    return i1e(kappa) / i0e(kappa)


def shifts(g, scene, copies, seed, first_replicate=0):
    """(copies, N) turns of the copies (rad), from their cosines and sines."""
    turn = rotations.copy_turns(g, scene, copies, seed, first_replicate)
    assert turn.copies == copies
    return np.arctan2(turn.sin, turn.cos).reshape(copies, g.count)


def polar(scene, xy):
    f = scene.feed
    return np.hypot(*xy.T), np.arctan2(xy[:, 1], xy[:, 0]) - f.angle_rad


def test_the_release_angle_given_the_radius_is_von_mises_with_the_derived_concentration():
    # the derivation itself, on the sampler's own release points (no copies involved)
    scene = paper(**{"sim.granules": 65536, "feed.spread_m": 0.03})
    g = sampled(scene)
    r, angle = polar(scene, g.release_xy_m)
    free = r < 0.95 * scene.vane_outer_radius_m * (1 - 1e-12)
    kappa = r[free] * scene.feed.radius_m / scene.feed.spread_m**2
    gap = np.cos(angle[free]) - mean_resultant(kappa)
    assert abs(gap.mean()) < 4.0 * gap.std() / np.sqrt(gap.size)
    gap = np.sin(angle[free])  # symmetric about the feed angle
    assert abs(gap.mean()) < 4.0 * gap.std() / np.sqrt(gap.size)


def test_copies_draw_that_law_and_keep_the_release_radius():
    scene = paper(**{"feed.spread_m": 0.03})
    g = sampled(scene)
    turns = rotations.copy_turns(g, scene, 16, seed=5, first_replicate=0)
    assert np.all(turns.cos[:g.count] == 1.0) and np.all(turns.sin[:g.count] == 0.0)  # copy 0: the granule
    np.testing.assert_allclose(turns.cos**2 + turns.sin**2, 1.0, rtol=0, atol=1e-15)
    turned = np.arctan2(turns.sin, turns.cos)
    r, angle = polar(scene, rotate(np.tile(g.release_xy_m, (16, 1)), turned))
    np.testing.assert_allclose(r, np.tile(np.hypot(*g.release_xy_m.T), 16), rtol=1e-12)
    free = r[g.count:] < 0.95 * scene.vane_outer_radius_m * (1 - 1e-12)
    kappa = r[g.count:][free] * scene.feed.radius_m / scene.feed.spread_m**2
    gap = np.cos(angle[g.count:][free]) - mean_resultant(kappa)
    assert abs(gap.mean()) < 4.0 * gap.std() / np.sqrt(gap.size)
    clipped = ~(np.hypot(*g.release_xy_m.T) < 0.95 * scene.vane_outer_radius_m * (1 - 1e-12))
    assert clipped.any() and np.all(turned.reshape(16, -1)[:, clipped] == 0.0)  # pulled-back points keep their angle


def test_copies_of_a_replicate_depend_on_the_seed_and_that_replicate_only():
    scene = paper(**{"sim.seed": 3})
    one = shifts(sampled(scene), scene, 4, seed=3)
    later = scene_with(scene, {"sim.granules": 2048})
    g = sample_granules(later, LIBRARY.fertilizer(later.fertilizer), 4, first_replicate=4)
    half = shifts(g, later, 4, seed=3, first_replicate=4)
    assert np.array_equal(one[:, 2048:], half)


@pytest.mark.parametrize("settings, copies, why", [
    ({}, 8, "exact"),
    ({"feed.spread_m": 0.0}, 1, "single release angle"),
    ({"sim.angle_copies": 1}, 1, "sim.angle_copies = 1"),
    ({"flight.forward_speed_m_s": 2.0}, 1, "forward speed"),
    ({"flight.wind_m_s": [0.0, 1.0]}, 1, "wind"),
])
def test_copy_count_follows_the_scene(settings, copies, why):
    count, reason = rotations.copies_for(paper(**{"sim.angle_copies": 8, **settings}))
    assert count == copies and why in reason
    plates = scene_with(load_scene("paper-deflectors"), {"sim.angle_copies": 8})
    count, reason = rotations.copies_for(plates)
    assert count == 8 and "plates" in reason
    count, reason = rotations.copies_for(plates, discs=2)
    assert count == 1 and "two discs" in reason


@pytest.mark.parametrize("settings", [{}, {"flight.magnus": True}, {"spinner.rpm": 100.0}])  # last: some retained
def test_copies_land_where_flying_each_turned_copy_lands(settings):
    scene = paper(**{"sim.granules": 512, "sim.angle_copies": 4, "sim.seed": 9, **settings})
    result = run_scene(scene, model="analytic")
    g = sampled(scene)
    assert np.array_equal(g.diameter_m, result.granules.diameter_m)
    turned = shifts(g, scene, 4, scene.sim.seed).ravel()
    launch = result.launch
    gone = np.tile(launch.departed, 4)
    assert settings.get("spinner.rpm") is None or not launch.departed.all()

    def copies(a):
        return np.tile(a, (4,) + (1,) * (a.ndim - 1))[gone]

    flown = flight.fly(rotate(copies(launch.position_m), turned[gone]),
                       np.maximum(scene.spinner.height_m + copies(launch.height_m), 0.0),
                       np.column_stack([rotate(copies(launch.velocity_m_s), turned[gone]),
                                        copies(launch.vertical_velocity_m_s)]),
                       copies(g.diameter_m), g.density_kg_m3, scene.flight, spin_rad_s=copies(launch.spin_rad_s))
    # the adaptive steps differ for a turned launch, each landing within the flight's
    # own tolerance (about 0.01 mm of a tight solve: docs/flight-and-pattern.md)
    np.testing.assert_allclose(result.sample.x_m, flown.position_m[:, 0], rtol=0, atol=1e-6)
    np.testing.assert_allclose(result.sample.mass_kg, copies(g.mass_kg) / 4, rtol=1e-15)
    np.testing.assert_array_equal(result.sample.replicate, copies(g.replicate))


def test_each_copy_thrown_onto_the_other_disc_is_intercepted():
    scene = load_scene("twin-field", {"sim.granules": 1024, "sim.angle_copies": 4, "feed.angle_deg": 100.0})
    result = run_scene(scene, model="analytic")
    first = discs.discs(scene)[0]
    g = sample_granules(first.scene, LIBRARY.fertilizer_of(scene), scene.sim.replicates)
    turned = shifts(g, first.scene, 4, scene.sim.seed).ravel()
    half = result.granules.count // 2
    centre = np.asarray(first.centre_m)
    launch = result.launch
    gone = np.tile(launch.departed[:half], 4)
    position = rotate(np.tile(launch.position_m[:half] - centre, (4, 1)), turned) + centre
    velocity = rotate(np.tile(launch.velocity_m_s[:half], (4, 1)), turned)
    other = -centre  # the mirror disc's axis
    hit = gone & twin._ray_meets_circle(position, velocity, other, scene.spinner.radius_m + np.tile(g.radius_m, 4))
    mass = result.metrics.to_json()["mass"]
    assert mass["intercepted_kg"] == pytest.approx(2.0 * np.tile(g.mass_kg, 4)[hit].sum() / 4, rel=1e-12)
    assert mass["intercepted_kg"] > 0.03 * mass["released_kg"]
    assert mass["released_kg"] == pytest.approx(mass["landed_kg"] + mass["retained_kg"] + mass["intercepted_kg"],
                                                rel=1e-12)
    assert result.sample.x_m.size == 2 * np.count_nonzero(gone & ~hit)


def test_pooled_runs_with_copies_equal_one_long_run():
    scene = paper(**{"sim.granules": 1024, "sim.angle_copies": 4, "sim.seed": 2})
    pooled = pool_runs(scene, 2, model="analytic")
    long = run_scene(scene_with(scene, {"sim.granules": 2048, "sim.replicates": 16}), model="analytic")
    assert pooled.granules == 2048 and pooled.angle_copies == 4
    # to rounding: numpy's vectorised trigonometry may differ in the last bit with the batch length
    np.testing.assert_allclose(np.sort(pooled.x_m), np.sort(long.sample.x_m), rtol=1e-12, atol=1e-12)
    trays, masses = pooled.replicate_masses(scene.pattern.tray_width_m, scene.pattern.target_swath_m)
    np.testing.assert_allclose(masses, long.replicate_masses_kg, rtol=1e-12, atol=1e-15)


def test_same_seed_same_bits_with_copies():
    scene = paper(**{"sim.angle_copies": 8, "sim.seed": 11})
    a, b = run_scene(scene, model="compiled"), run_scene(scene, model="compiled")
    assert np.array_equal(a.replicate_masses_kg, b.replicate_masses_kg)
    assert a.metrics.cv_percent_at_target == b.metrics.cv_percent_at_target


def test_copies_leave_the_cv_unbiased_and_cut_its_spread():
    # same scene, same model: the mean over seeds must not move (beyond 3 SE of the
    # difference) and the seed-to-seed spread must fall
    def cvs(copies):
        return np.array([run_scene(paper(**{"sim.granules": 1024, "sim.angle_copies": copies, "sim.seed": s}),
                                   model="analytic", ci=False).metrics.cv_percent_at_target for s in range(48)])

    plain, copied = cvs(1), cvs(16)
    se = np.hypot(plain.std(ddof=1), copied.std(ddof=1)) / np.sqrt(plain.size)
    assert abs(plain.mean() - copied.mean()) < 3.0 * se
    assert copied.std(ddof=1) < 0.7 * plain.std(ddof=1)


@pytest.mark.slow
def test_plate_copies_keep_the_uncopied_mean_and_cut_the_spread():
    """paper-deflectors with 32 release angles (copies that clear the plates turned, the
    others near a plate through the ray stage) against one angle, over 24 seeds each: the
    same mean CV and the same mean pattern centre (within 3 standard errors), a smaller spread."""
    base = load_scene("paper-deflectors", {"sim.granules": 1024})
    found = {}
    for copies in (32, 1):
        cv, centre = [], []
        for seed in range(24):
            result = run_scene(scene_with(base, {"sim.seed": 500 + seed, "sim.angle_copies": copies}), ci=False)
            assert result.metrics.angle_copies == copies
            cv.append(result.metrics.cv_percent_at_target)
            trays = result.trays
            centre.append(float(np.sum(trays.center_m * trays.mass_kg) / trays.mass_kg.sum()))
        found[copies] = np.array(cv), np.array(centre)
    for k in range(2):
        a, b = found[32][k], found[1][k]
        se = np.hypot(a.std(ddof=1), b.std(ddof=1)) / np.sqrt(a.size)
        assert abs(a.mean() - b.mean()) < 3.0 * se, (k, a.mean(), b.mean(), se)
    assert found[32][0].std(ddof=1) < 0.5 * found[1][0].std(ddof=1)


def test_a_plate_copy_that_clears_the_plates_lands_as_its_granule_turned():
    """Every copy kept without its own plate run is one whose turned straight path passes
    no plate: flying it through the full deflector stage changes nothing."""
    from spreadgym.physics.contacts import resolve_contacts
    from spreadgym.physics.selection import SPINNER_MODELS

    scene = load_scene("paper-deflectors", {"sim.granules": 256, "sim.angle_copies": 4, "sim.seed": 3})
    library = load_library()
    g = sampled(scene)
    contacts = resolve_contacts(scene, library)
    departure = SPINNER_MODELS["compiled"].run(scene, g, contacts)
    free = rotations.straight_paths(departure, scene.deflectors, g.radius_m)
    turn = rotations.copy_turns(g, scene, 4, scene.sim.seed, 0)
    c, s = turn.cos.reshape(4, -1), turn.sin.reshape(4, -1)
    gone = departure.departed
    for k in range(1, 4):  # copy k: the departure turned by s_k
        turned = rotate(departure.position_m, np.arctan2(s[k], c[k]))
        moved = discs.Throw(g, dataclasses.replace(departure, position_m=turned,
                                                  velocity_m_s=rotate(departure.velocity_m_s,
                                                                      np.arctan2(s[k], c[k]))), departure)
        launch = SPINNER_MODELS["compiled"].deflect(moved.departure, scene, contacts, g)
        clear_free = rotations.straight_paths(moved.departure, scene.deflectors, g.radius_m)
        clears = gone & ~rotations.near_own_paths(moved, clear_free, scene.deflectors)
        assert clears.sum() > 0.5 * gone.sum()
        np.testing.assert_allclose(launch.position_m[clears], clear_free.position_m[clears], atol=1e-12)
        np.testing.assert_allclose(launch.position_m[clears], rotate(free.position_m, np.arctan2(s[k], c[k]))[clears],
                                   atol=1e-12)
