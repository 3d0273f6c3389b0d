"""Field tray tests as they are laid: spaced and irregular kits fitted (the likelihood uses
only the trays present), the measured trays' own CV beside the fitted one, a fit that
has nothing to fit refused, and an estimate at a search bound flagged."""

import numpy as np
import pytest

from spreadgym.config.scene import load_scene
from spreadgym.errors import SpreadgymError
from spreadgym.fit.measured import measured_pattern
from spreadgym.fit.run import fit_tray_test
from spreadgym.fit.space import parse_fit_specs
from spreadgym.fit.trays import TrayTest
from spreadgym.spread import pattern
from spreadgym.spread.pipeline import run_scene

KEY = "contact.vane_restitution"
TRUTH = 0.5


@pytest.fixture(scope="module")
def truth():
    """A locked-rotation paper pass at restitution 0.5 (compiled model, 8192 granules, its own seed): the landings."""
    scene = load_scene("paper", {"granule.rotation": "locked", KEY: TRUTH, "sim.granules": 8192,
                                 "sim.seed": 1_000_003})
    return scene, run_scene(scene, model="compiled", ci=False).sample


def kit(truth, centres, noise_seed=3, catch_sd=0.05):
    """Trays 0.5 m wide at `centres`, each catching the landings inside it (hard edges), with catch noise."""
    scene, sample = truth
    centres = np.asarray(centres, float)
    inside = np.abs(sample.x_m[:, None] - centres[None, :]) < 0.25
    caught = (sample.mass_kg[:, None] * inside).sum(axis=0)
    caught *= np.exp(catch_sd * np.random.default_rng(noise_seed).standard_normal(centres.size))
    return TrayTest(centres, 2.0 * caught / caught.sum(), np.zeros(centres.size, np.int64), 0.5, "kit")


def fit(test, spec=f"{KEY}=0.3:0.7"):
    scene = load_scene("paper", {"granule.rotation": "locked"})
    return fit_tray_test(scene, parse_fit_specs([spec], scene), test, granules=1024)


@pytest.mark.parametrize("centres", [
    np.arange(-6, 7) * 1.0,  # 0.5 m trays every 1 m: how field kits are laid
    np.array([-3.6, -2.9, -2.2, -1.45, -0.6, 0.35, 1.1, 1.95, 2.7, 3.45, 5.0]),  # an irregular kit
])
def test_spaced_and_irregular_kits_recover_the_truth(truth, centres):
    result = fit(kit(truth, centres))
    key = result.space.keys[0]
    assert result.low[0] <= TRUTH <= result.high[0], (result.low, result.estimate, result.high)
    assert result.identifiable[key] and not result.at_bound[0]
    assert result.model.trays == np.count_nonzero(result.model.test.mass_kg)  # every tray that caught something


def test_the_measured_cv_of_a_complete_test_is_simulates_and_gaps_are_filled_linearly():
    scene = load_scene("paper")
    centre = np.arange(-20, 21) * 0.5
    triangle = np.clip(8.0 - np.abs(centre), 0.0, None)  # g per tray, straight between the kit's trays
    complete = TrayTest(centre, 1e-3 * triangle, np.zeros(centre.size, np.int64), 0.5, "complete")
    widths = np.arange(1, 25) * 0.5
    whole = measured_pattern(complete, scene, centre, triangle, widths)
    trays = pattern.Trays(centre, 1e-3 * triangle, 0.5)
    expected = np.array([pattern.cv_percent(trays, w, scene.pattern.driving) for w in widths])
    np.testing.assert_allclose(whole.cv_percent, expected, rtol=1e-12, atol=1e-9)
    assert whole.cv_percent_at_target == pytest.approx(
        pattern.cv_percent(trays, scene.pattern.target_swath_m, scene.pattern.driving), rel=1e-12)
    every_other = TrayTest(centre[::4], 1e-3 * triangle[::4], np.zeros(centre[::4].size, np.int64), 0.5, "spaced")
    spaced = measured_pattern(every_other, scene, centre, triangle, widths)  # trays every 2 m, kinks on trays
    np.testing.assert_allclose(spaced.cv_percent, expected, rtol=1e-12, atol=1e-9)
    one_side = TrayTest(centre[20:], 1e-3 * triangle[20:], np.zeros(21, np.int64), 0.5, "one side")
    half = measured_pattern(one_side, scene, centre, triangle, widths)
    assert half.cv_percent is None and half.spanned_share < 0.95  # half the pattern is not measured


def test_the_fit_reports_the_measured_cv_beside_the_fitted_one(truth):
    from spreadgym.fit.outputs import payload, predict

    result = fit(kit(truth, np.arange(-18, 19) * 0.5))
    data = payload(result, predict(result), None)
    measured, fitted = data["measured_cv_percent_at_target"], data["cv_percent_at_target"]
    assert data["measured_span_share"] > 0.99
    assert abs(measured - fitted) < 3.0, (measured, fitted)  # one noisy test against the model at its estimate


@pytest.mark.parametrize("shift_m", [9.0, 150.0])
def test_trays_where_the_model_throws_nothing_are_refused(truth, shift_m):
    test = kit(truth, np.arange(-9, 10) * 0.5)
    moved = TrayTest(test.x_m + shift_m, test.mass_kg, test.lane, 0.5, "shifted")
    with pytest.raises(SpreadgymError, match="of the measured mass lies in trays the simulated pattern reaches at any "
                                             "point of the start design over the search box; at least 90 % must"):
        fit(moved)


def test_an_estimate_at_a_search_bound_is_flagged_and_not_called_identifiable(truth):
    result = fit(kit(truth, np.arange(-18, 19) * 0.5), spec=f"{KEY}=0.2:0.35")  # the truth (0.5) lies beyond
    assert result.at_bound == [True] and not result.identifiable[KEY]
    assert result.estimate[0] == pytest.approx(0.35)


def test_a_fit_evaluates_in_batches_within_the_landing_point_budget(monkeypatch):
    """`fit --granules` up to what one run may hold: the evaluations are simulated a few at
    a time, each batch's landing points within the budget (here scaled down to 3 runs of
    64 granules x 1 release angle), with the results of one batch of all."""
    from spreadgym.fit import likelihood

    scene = load_scene("paper", {"sim.granules": 64, "sim.angle_copies": 1})
    test = TrayTest(np.arange(-5, 6) * 0.5, np.full(11, 1e-3), np.zeros(11, np.int64), 0.5, "flat")
    space = parse_fit_specs([f"{KEY}=0.3:0.7"], scene)
    points = [[u] for u in np.linspace(0, 1, 7)]
    whole = likelihood.PatternModel(scene, space, test, model="compiled").predict(points)
    batches = []
    real = likelihood.run_batch
    monkeypatch.setattr(likelihood, "run_batch", lambda scenes, **kw: batches.append(len(scenes)) or real(scenes, **kw))
    monkeypatch.setattr(likelihood, "MAX_GRANULE_COPIES", 3 * 64)
    parts = likelihood.PatternModel(scene, space, test, model="compiled").predict(points)
    assert batches == [3, 3, 1]
    for a, b in zip(whole, parts):
        np.testing.assert_array_equal(a.log_mu, b.log_mu)
