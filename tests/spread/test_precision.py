"""The precision rule: runs pooled until the stated standard error reaches the one asked,
with that standard error still honest (coverage on patterns with a known exact CV)."""

import numpy as np
import pytest
from test_estimate import HALF_WIDTH_M, PATTERNS, TRAY_M, exact_cv

from spreadgym.config.scene import load_scene, scene_with
from spreadgym.errors import SpreadgymError
from spreadgym.spread import estimate, precision
from spreadgym.spread.pipeline import run_scene

GRANULES_PER_RUN = 4000
REPLICATES_PER_RUN = 8


def precise_draw(name: str, seed: int, precision_pp: float, max_runs: int = 400):
    """The rule on a synthetic pattern: each run draws GRANULES_PER_RUN landings in
    REPLICATES_PER_RUN replicates; returns (final estimate, runs)."""
    sample, _, width, driving = PATTERNS[name]
    rng = np.random.default_rng(seed)
    pooled = precision.PooledMasses(TRAY_M)

    def add_runs(count):
        for _ in range(count):
            x = np.clip(sample(rng, GRANULES_PER_RUN), -HALF_WIDTH_M, HALF_WIDTH_M)
            replicate = np.arange(GRANULES_PER_RUN) % REPLICATES_PER_RUN
            _, masses = estimate.replicate_tray_masses(x, 1.0, replicate, REPLICATES_PER_RUN, TRAY_M, HALF_WIDTH_M)
            pooled.add(masses)
        return estimate.estimate_cv(pooled.masses(), TRAY_M, width, driving).standard_error_percent

    runs = precision.pool_until_precise(add_runs, precision_pp, max_runs)
    return estimate.estimate_cv(pooled.masses(), TRAY_M, width, driving), runs


@pytest.mark.parametrize("name", ["gaussian", "skewed"])
def test_intervals_after_the_rule_cover_the_exact_cv(name):
    exact = exact_cv(name)
    draws = [precise_draw(name, seed, precision_pp=0.8) for seed in range(300)]
    covered = np.mean([e.interval_percent[0] <= exact <= e.interval_percent[1] for e, _ in draws])
    assert 0.90 <= covered <= 0.99, covered
    cvs = np.array([e.cv_percent for e, _ in draws])
    stated = np.array([e.standard_error_percent for e, _ in draws])
    assert np.all(stated <= 0.8)  # the rule stops only there (no draw reached the cap)
    assert abs(cvs.mean() - exact) < 3 * cvs.std(ddof=1) / np.sqrt(cvs.size)  # unbiased
    assert np.sqrt(np.mean(stated**2)) == pytest.approx(cvs.std(ddof=1), rel=0.25)  # honest
    assert len({runs for _, runs in draws}) > 1  # the count follows the pilot: a real rule, not a constant


def test_runs_needed_follows_the_inverse_square_law_within_the_cap():
    assert precision.runs_needed(0.4, 2, 0.2, 64) == 8
    assert precision.runs_needed(0.2, 2, 0.2, 64) == 2
    assert precision.runs_needed(0.21, 8, 0.2, 64) == 9  # always at least one more run while above
    assert precision.runs_needed(5.0, 2, 0.2, 64) == 64
    assert precision.runs_needed(None, 2, 0.2, 64) == 2  # no standard error: nothing to aim at


def test_a_loose_precision_stops_after_the_pilot_and_a_cap_is_kept():
    _, runs = precise_draw("gaussian", 1, precision_pp=50.0)
    assert runs == precision.PILOT_RUNS
    estimate_, runs = precise_draw("gaussian", 1, precision_pp=0.001, max_runs=5)
    assert runs == 5 and estimate_.standard_error_percent > 0.001


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), 1e-9])
def test_bad_precision_is_one_line_naming_the_flag(bad):
    with pytest.raises(SpreadgymError, match="--precision"):
        precision.check_precision(bad)


def test_pooled_runs_are_the_one_run_of_all_their_granules():
    """n runs of N granules pooled = one run of n N granules in n R replicates, to rounding
    (tray sums in another order): the rule pools the replicates the scene would draw."""
    scene = scene_with(load_scene("paper"), {"sim.granules": 512, "sim.replicates": 4, "sim.seed": 5})
    result = precision.simulate_precisely(scene, precision_pp=100.0)  # the pilot alone
    assert result.runs == precision.PILOT_RUNS
    whole = run_scene(scene_with(scene, {"sim.granules": 1024, "sim.replicates": 8}), ci=False)
    assert result.masses.shape == whole.replicate_masses_kg.shape
    np.testing.assert_allclose(result.masses, whole.replicate_masses_kg, rtol=1e-12, atol=1e-18)
    assert result.at_target.cv_percent == pytest.approx(whole.metrics.cv_percent_at_target, rel=1e-9)
    assert result.to_json()["granules_simulated"] == 1024


def test_runs_in_batches_equal_runs_one_by_one_and_the_first_keeps_its_paths():
    """simulate pools its runs through spread.batch: the same bits as run_scene run by run."""
    scene = scene_with(load_scene("paper"), {"sim.granules": 512, "sim.seed": 9})
    result = precision.simulate_precisely(scene, precision_pp=0.001, max_runs=4, tracks=3)
    one_by_one = precision.PooledMasses(scene.pattern.tray_width_m)
    for j in range(4):
        one_by_one.add(run_scene(scene, ci=False, first_replicate=8 * j).replicate_masses_kg)
    assert np.array_equal(result.masses, one_by_one.masses())
    assert len(result.first.departure.tracks) == 3


def test_simulate_precisely_reaches_the_precision_asked_and_is_deterministic():
    scene = scene_with(load_scene("paper"), {"sim.granules": 1024, "sim.seed": 2})
    a = precision.simulate_precisely(scene, precision_pp=0.4)
    b = precision.simulate_precisely(scene, precision_pp=0.4)
    assert a.precision_met and a.at_target.standard_error_percent <= 0.4
    assert a.to_json()["cv_percent_at_target"] == b.to_json()["cv_percent_at_target"]
    assert np.array_equal(a.masses, b.masses)
