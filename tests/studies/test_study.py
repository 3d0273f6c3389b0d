"""The paper study (`spreadgym.studies.paper`, `spreadgym study paper`) on a reduced case list."""

from __future__ import annotations

import csv
import json

import pytest

from spreadgym.cli.main import main
from spreadgym.errors import SpreadgymError
from spreadgym.out_folder import STAMP
from spreadgym.studies import paper as study

ROW_KEYS = {
    "sweep", "material", "rpm", "diameter_m", "rotation", "speed_mean_m_s", "speed_std_m_s", "spin_mean_rad_s",
    "spin_std_rad_s", "angle_mean_deg", "time_on_spinner_mean_s", "departed", "radial_mean_m_s",
    "tangential_mean_m_s", "closed_form_speed_m_s",
}
PNGS = {"fig6-speed-by-material.png", "fig7-spin-by-material.png", "fig8-speed-vs-rpm.png",
        "fig9-speed-vs-diameter.png", "departure-angle.png"}


def quick_cases() -> list[study.Case]:
    """A reduced set: two materials, two speeds, two diameters."""
    return [
        study.Case("material", "mc", study.BASE_RPM, study.BASE_DIAMETER_M),
        study.Case("material", "steel", study.BASE_RPM, study.BASE_DIAMETER_M),
        study.Case("rpm", study.BASE_MATERIAL, 200.0, study.BASE_DIAMETER_M),
        study.Case("rpm", study.BASE_MATERIAL, 800.0, study.BASE_DIAMETER_M),
        study.Case("diameter", study.BASE_MATERIAL, study.BASE_RPM, 0.2),
        study.Case("diameter", study.BASE_MATERIAL, study.BASE_RPM, 0.4),
    ]


@pytest.fixture(scope="module")
def rows():
    return study.paper_study(granules=10, cases=quick_cases())


def _speed(rows, sweep, rotation, **match):
    picked = [r for r in rows if r["sweep"] == sweep and r["rotation"] == rotation
              and all(r[k] == v for k, v in match.items())]
    assert len(picked) == 1
    return picked[0]["speed_mean_m_s"]


def test_paper_cases_cover_the_paper():
    cases = study.paper_cases()
    assert {c.material for c in cases if c.sweep == "material"} == {"mc", "pvc", "steel"}
    assert sorted(c.rpm for c in cases if c.sweep == "rpm") == [200, 500, 800, 1100]
    assert sorted(c.diameter_m for c in cases if c.sweep == "diameter") == [0.2, 0.3, 0.4]
    scene = study.study_scene(cases[-1], granules=5, rotation="locked")
    assert scene.feed.spread_m == 0.0 and scene.feed.radius_m == pytest.approx(0.043)
    assert scene.vane_outer_radius_m == pytest.approx(0.2) and scene.vanes.inner_radius_m == pytest.approx(0.025)
    assert scene.granule.rotation == "locked"


def test_rows_have_the_keys_and_every_granule_departs(rows):
    assert len(rows) == 2 * len(quick_cases())
    for row in rows:
        assert ROW_KEYS <= set(row)
        assert row["departed"] == 10
        assert row["speed_mean_m_s"] > 0 and row["time_on_spinner_mean_s"] > 0
        assert 0 < row["angle_mean_deg"] < 90
    assert [r["rotation"] for r in rows[:2]] == ["free", "locked"]


def test_free_differs_from_locked(rows):
    for free, locked in zip(rows[0::2], rows[1::2]):
        assert (free["rotation"], locked["rotation"]) == ("free", "locked")
        assert locked["spin_mean_rad_s"] == 0.0
        assert abs(free["spin_mean_rad_s"]) > 100.0
        # rolling along the face loses less than sliding: faster and more radial
        assert free["speed_mean_m_s"] > 1.02 * locked["speed_mean_m_s"]
        assert free["angle_mean_deg"] > locked["angle_mean_deg"] + 2.0


def test_speed_increases_with_rpm_and_diameter(rows):
    for rotation in study.ROTATIONS:
        assert _speed(rows, "rpm", rotation, rpm=800.0) > 3.0 * _speed(rows, "rpm", rotation, rpm=200.0)
        assert _speed(rows, "diameter", rotation, diameter_m=0.4) > 1.8 * _speed(rows, "diameter", rotation,
                                                                                  diameter_m=0.2)


def test_closed_form_tracks_the_simulation(rows):
    for row in rows:
        assert row["speed_mean_m_s"] == pytest.approx(row["closed_form_speed_m_s"], rel=0.06)


def test_progress_and_bad_input():
    calls = []
    study.paper_study(granules=2, cases=quick_cases()[:1], rotations=("locked",),
                      progress=lambda done, total: calls.append((done, total)))
    assert calls == [(1, 1)]
    with pytest.raises(SpreadgymError):
        study.paper_study(granules=0)
    with pytest.raises(SpreadgymError):
        study.paper_study(granules=2, rotations=("spinning",))


def test_write_and_plot(rows, tmp_path):
    csv_path = study.write_study(rows, tmp_path)
    with open(csv_path, encoding="utf-8") as handle:
        read = list(csv.DictReader(handle))
    assert len(read) == len(rows) and ROW_KEYS <= set(read[0])
    written = study.plot_paper_study(rows, tmp_path)
    assert {p.name for p in written} == PNGS
    for path in written:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_writes_the_files(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(study, "paper_cases", quick_cases)
    assert main(["study", "paper", "--granules", "3", "--out", str(tmp_path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"rows"} and len(data["rows"]) == 2 * len(quick_cases())
    assert {p.name for p in tmp_path.iterdir()} == PNGS | {study.CSV_NAME, STAMP}  # STAMP: whose outputs they are


def test_cli_rejects_zero_granules(tmp_path, capsys):
    assert main(["study", "paper", "--granules", "0", "--out", str(tmp_path)]) == 2
    assert "--granules" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_the_committed_study_is_what_the_code_gives():
    """docs/paper-study.md says `spreadgym study paper` reproduces docs/study/paper-study.csv
    (seed 0); the base case, free and locked, rerun here as written there. (The CSV went
    stale for a week of physics changes before this test.)"""
    from pathlib import Path

    committed = Path(__file__).resolve().parents[2] / "docs" / "study" / study.CSV_NAME
    with open(committed, newline="", encoding="utf-8") as handle:
        stored = [r for r in csv.DictReader(handle) if r["sweep"] == "material" and r["material"] == "mc"]
    base = study.Case("material", "mc", study.BASE_RPM, study.BASE_DIAMETER_M)
    fresh = study.paper_study(cases=[base])
    assert len(stored) == len(fresh) == 2
    for want, got in zip(stored, fresh):
        assert {k: str(study._csv_value(v)) for k, v in got.items()} == want
