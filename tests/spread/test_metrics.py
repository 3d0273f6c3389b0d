"""RunMetrics: the JSON of a run and the landed fraction read off its one tray row."""

import numpy as np
import pytest

from spreadgym.config.scene import load_scene
from spreadgym.spread.metrics import RunMetrics
from spreadgym.spread.pattern import Trays
from spreadgym.spread.pipeline import run_scene


def _metrics(released_kg: float, tray_masses_kg: list[float]) -> RunMetrics:
    return RunMetrics(
        model="analytic", model_reason="", dt_s=None, granules=0, angle_copies=1, angle_copies_reason="",
        outcomes={}, departure={},
        target_swath_m=4.0, driving="racetrack", tray_width_m=0.5, cv_threshold_percent=15.0,
        cv_percent_at_target=None, cv_standard_error_percent=None, cv_raw_percent=None, cv_ci_percent=None,
        effective_swath_m=0.0, curve_bout_width_m=np.zeros(0), curve_cv_percent=np.zeros(0),
        trays=Trays(0.5 * np.arange(-1, 2), np.array(tray_masses_kg), 0.5), released_kg=released_kg,
        retained_kg=released_kg - sum(tray_masses_kg),
    )


def test_landed_mass_and_fraction_come_from_the_trays():
    m = _metrics(10.0, [2.0, 4.0, 3.0])
    assert m.landed_kg == 9.0 and m.landed_fraction == 0.9
    assert m.to_json()["mass"] == {"released_kg": 10.0, "landed_kg": 9.0, "retained_kg": 1.0, "intercepted_kg": 0.0}
    assert _metrics(0.0, [0.0, 0.0, 0.0]).landed_fraction is None


def test_json_holds_the_run_and_its_trays():
    result = run_scene(load_scene("paper", {"sim.granules": 64, "feed.drop_height_m": 0.0,
                                            "contact.vane_restitution": 0.0}), ci=False)
    data = result.metrics.to_json()
    assert list(data) == ["model", "model_reason", "dt_s", "granules", "angle_copies", "angle_copies_reason",
                          "outcomes", "departure", "target_swath_m",
                          "driving", "tray_width_m", "cv_threshold_percent", "cv_percent_at_target",
                          "cv_standard_error_percent", "cv_raw_percent", "cv_ci_percent", "effective_swath_m",
                          "cv_curve", "trays", "mass", "notes", "wall_s"]
    assert data["trays"]["mass_kg"] is result.trays.mass_kg  # one tray row, not a copy
    assert data["mass"]["landed_kg"] == pytest.approx(float(result.granules.mass_kg[result.landed].sum()),
                                                      rel=1e-12)
