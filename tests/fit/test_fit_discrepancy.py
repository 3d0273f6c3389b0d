"""The fit model's discrepancy from the full model, carried into the intervals: a known
offset between the model that made the test and the one that fits it is covered, the
widening is the stated quadrature sum, and the stored calibration is found and read."""

import numpy as np
import pytest
from scipy.stats import t as t_distribution

from spreadgym.config.scene import load_scene, scene_with
from spreadgym.fit.discrepancy import Discrepancy, paired_log_ratio, stored_discrepancy
from spreadgym.fit.run import fit_tray_test
from spreadgym.fit.space import parse_fit_specs
from spreadgym.fit.synthetic import simulated_pass, synthetic_tray_test
from spreadgym.fit.uncertainty import LEVEL

KEY = "contact.vane_restitution"
OFFSET = 0.04  # the "full model" here: the compiled model with restitution 0.04 higher
CALIBRATION = (0.35, 0.45, 0.6)  # restitution at the calibration points (the truth is 0.5)


def _shifted_discrepancy(scene):
    """log(compiled at r + OFFSET) - log(compiled at r) at the calibration points, paired
    seeds: a model difference that is exactly a restitution offset."""
    measured = [paired_log_ratio(*(simulated_pass(scene_with(scene, {KEY: value, "sim.granules": 16384,
                                                                      "sim.seed": 77 + i, "sim.replicates": 16}),
                                                  "compiled") for value in (r + OFFSET, r)))
                for i, r in enumerate(CALIBRATION)]
    return Discrepancy(*(list(column) for column in zip(*measured)))


@pytest.fixture(scope="module")
def offset_fits():
    scene = load_scene("paper", {"granule.rotation": "locked"})
    test = synthetic_tray_test(scene, {KEY: 0.5 + OFFSET}, model="compiled", granules=65536, noise_seed=4)
    space = parse_fit_specs([f"{KEY}=0.3:0.8"], scene)
    return tuple(fit_tray_test(scene, space, test, model="compiled", granules=2048, seed=4, discrepancy=d)
                 for d in (None, _shifted_discrepancy(scene)))


def test_a_known_offset_is_measured_and_covered(offset_fits):
    """Without the discrepancy the interval sits around 0.54 and misses the truth 0.5; the
    measured offset moves the estimate by about OFFSET, and the widened interval holds 0.5."""
    bare, carried = offset_fits
    assert not bare.low[0] <= 0.5 <= bare.high[0], (bare.low, bare.high)
    assert carried.discrepancy_points == len(CALIBRATION)
    assert carried.model_sd[0] == pytest.approx(OFFSET, rel=0.3)
    assert carried.low[0] <= 0.5 <= carried.high[0]
    assert carried.identifiable[KEY]


def test_the_widening_is_the_quadrature_sum(offset_fits):
    """Same estimate; each half-width grows to hypot(half-width, t_C(0.95) x model s.d.)."""
    bare, carried = offset_fits
    assert carried.estimate[0] == bare.estimate[0]
    q = t_distribution.ppf(0.5 + LEVEL / 2, len(CALIBRATION)) * carried.model_sd[0]
    for bare_half, carried_half in ((bare.estimate[0] - bare.low[0], carried.estimate[0] - carried.low[0]),
                                    (bare.high[0] - bare.estimate[0], carried.high[0] - carried.estimate[0])):
        assert carried_half == pytest.approx(np.hypot(bare_half, q), rel=1e-9)


def test_stored_discrepancy_is_found_for_the_calibrated_scenes_only():
    for name in ("paper", "field"):
        for fertilizer in ("compound-10-16-10", "pellet"):
            for rotation in ("locked", "free"):
                found = stored_discrepancy(load_scene(name, {"fertilizer": fertilizer, "granule.rotation": rotation}))
                assert found is not None and found.points >= 3
                assert all(np.all(v >= 0) and d.size == x.size == v.size
                           for x, d, v in zip(found.x_m, found.delta, found.variance))
    assert stored_discrepancy(load_scene("paper", {"name": "my-spreader"})) is None


def test_discrepancy_on_trays_maps_by_tray_and_leaves_unmeasured_trays_at_zero():
    d = Discrepancy([np.array([-0.5, 0.0, 0.5])], [np.array([0.1, 0.2, 0.3])], [np.array([1e-4, 2e-4, 3e-4])])
    delta, variance = d.on_trays(np.array([0.5, -0.5, 1.0]), 0.5)
    assert delta.tolist() == [[0.3, 0.1, 0.0]] and variance.tolist() == [[3e-4, 1e-4, 0.0]]
