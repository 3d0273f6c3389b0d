"""The fidelity study's measures against closed forms, and a model against itself."""

import numpy as np
import pytest

from spreadgym.physics.departure import DEPARTED, Departure
from spreadgym.studies import fidelity
from spreadgym.studies.references import compute_references


def departure(position, velocity):
    n = len(position)
    return Departure(position_m=np.asarray(position, float), velocity_m_s=np.asarray(velocity, float),
                     spin_rad_s=np.zeros(n), height_m=np.zeros(n), vertical_velocity_m_s=np.zeros(n),
                     time_s=np.ones(n), outcome=np.full(n, DEPARTED, dtype=np.int8), model="test", dt_s=0.0)


def test_exit_angle_is_zero_outward_and_plus_ninety_counter_clockwise():
    d = departure([[0.1, 0.0], [0.0, 0.2], [-0.3, 0.0]], [[5.0, 0.0], [-4.0, 0.0], [0.0, -2.0]])
    assert np.degrees(fidelity.exit_angle_rad(d)) == pytest.approx([0.0, 90.0, 90.0])


def test_azimuth_histogram_and_total_variation():
    angles = np.radians([5.0, 15.0, 95.0, -175.0])
    d = departure(np.c_[np.cos(angles), np.sin(angles)], np.zeros((4, 2)))
    h = fidelity.azimuth_histogram(d)
    assert h.sum() == pytest.approx(1.0) and h[18] == h[19] == h[27] == h[0] == 0.25
    moved = fidelity.azimuth_histogram(departure(np.c_[np.cos(angles + np.pi / 4), np.sin(angles + np.pi / 4)],
                                                 np.zeros((4, 2))))
    assert fidelity.total_variation(h, h) == 0.0
    assert fidelity.total_variation(h, moved) == pytest.approx(1.0)  # no bin shared


def test_a_model_against_itself_meets_every_target(tmp_path):
    """Same references and the same granules on both sides: every difference is zero."""
    compute_references(tmp_path, model="analytic", runs=2, names=["paper"], overrides={"sim.granules": 64})
    rows = fidelity.fidelity_rows(tmp_path, model="analytic", full="analytic", granules=256,
                                  figures=tmp_path / "figures")
    assert len(rows) == 1
    row = rows[0]
    assert row["cv_diff_pp"] == 0.0 and row["azimuth_tv"] == 0.0 and row["median_time_ratio"] == 1.0
    assert all(row[k] for k in ("meets_cv", "meets_swath", "meets_azimuth", "meets_time"))
    assert "| paper |" in fidelity.fidelity_markdown(rows, "analytic", "analytic")
    assert (tmp_path / "figures" / "paper.png").stat().st_size > 10_000
