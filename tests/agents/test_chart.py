"""spreadgym chart without Ray: a small chart end to end, the verification it reports,
resume after an interruption, refusal of a changed chart, and bad input."""

import csv
import json

import pytest

from spreadgym.agents.chart import make_spec, run_chart
from spreadgym.agents.chart.spec import cell_seed
from spreadgym.cli.main import main
from spreadgym.config.resources import resolve_named
from spreadgym.config.scene import scene_with
from spreadgym.errors import SpreadgymError
from spreadgym.spread.reference import pool_runs, reference_from

FERTILIZER = "compound-10-16-10"
# Small and fast: the closed form searches (drop 0 makes it exact for this scene), the
# full model verifies with 2 pooled runs.
SMALL = dict(budget=6, granules=64, search_model="analytic", verify_runs=2)
COLUMNS = ["fertilizer", "width_m", "driving", "rpm", "pitch_deg", "cv_percent", "cv_standard_error_percent",
           "effective_swath_m", "cv_search_percent", "simulations", "wall_s"]


def small_spec(**changes):
    return make_spec("paper", FERTILIZER, "3,4", **{**SMALL, **changes})[0]


def without_wall(rows):
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


@pytest.fixture(scope="module")
def chart(tmp_path_factory):
    out = tmp_path_factory.mktemp("chart")
    return out, run_chart(small_spec(), out, engine="local", progress=False)


def test_small_chart_writes_every_output(chart):
    out, result = chart
    names = {p.name for p in result.files}
    assert names == {"chart.csv", "chart.json", "chart.md", "chart.png"}
    with open(out / "chart.csv", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        assert reader.fieldnames == COLUMNS
        rows = list(reader)
    assert [(r["fertilizer"], float(r["width_m"])) for r in rows] == [(FERTILIZER, 3.0), (FERTILIZER, 4.0)]
    payload = json.loads((out / "chart.json").read_text(encoding="utf-8"))
    assert payload["columns"] == COLUMNS and len(payload["rows"]) == 2
    assert set(payload["widest_width_m"]) == {FERTILIZER}
    for row in payload["rows"]:
        assert 200.0 <= row["rpm"] <= 1100.0 and -30.0 <= row["pitch_deg"] <= 30.0
        assert row["simulations"] == SMALL["budget"] + SMALL["verify_runs"]
        assert row["cv_standard_error_percent"] > 0
    for key in ("compound-10-16-10_003000mm", "compound-10-16-10_004000mm"):
        assert (out / "cells" / f"{key}.json").is_file() and (out / "cells" / f"{key}.png").stat().st_size > 0
    md = (out / "chart.md").read_text(encoding="utf-8")
    assert "| 3 m |" in md and "| 4 m |" in md and "rpm" in md
    assert result.computed == ["compound-10-16-10_003000mm", "compound-10-16-10_004000mm"] and result.reused == []


def test_reported_cv_is_the_full_model_on_the_reported_settings(chart):
    """Rebuild the verification from the row alone (settings, cell seed): the same CV and SE."""
    out, result = chart
    spec = result.spec
    row = result.payload["rows"][1]
    cell = spec.cells[1]
    scene = spec.cell_scene(cell)
    seed = int(cell_seed(spec.seed, cell).spawn(3)[2].generate_state(1)[0])
    scene = scene_with(scene, {"spinner.rpm": row["rpm"], "vanes.pitch_deg": row["pitch_deg"], "sim.seed": seed})
    reference = reference_from(scene, pool_runs(scene, SMALL["verify_runs"], model="pymunk"))
    assert reference.pooled.model == "pymunk"
    assert row["cv_percent"] == reference.at_target.cv_percent
    assert row["cv_standard_error_percent"] == reference.at_target.standard_error_percent
    assert row["effective_swath_m"] == reference.effective_swath_m


def test_another_seed_gives_another_chart(chart, tmp_path):
    """(The same seed gives the same chart: tests/agents/test_chart_ray.py, across engines and workers.)"""
    _, result = chart
    other = run_chart(small_spec(seed=1), tmp_path / "b", engine="local", progress=False)
    assert without_wall(other.payload["rows"]) != without_wall(result.payload["rows"])


def test_interrupted_chart_keeps_finished_cells_and_resumes_without_redoing_them(chart, tmp_path):
    _, full = chart
    out = tmp_path / "resume"

    def stop(cell, record):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_chart(small_spec(), out, engine="local", progress=False, on_cell=stop)
    assert sorted(p.name for p in (out / "cells").iterdir()) == ["compound-10-16-10_003000mm.json",
                                                                 "compound-10-16-10_003000mm.png"]
    assert not (out / "chart.csv").exists() and not (out / "chart.json").exists()
    resumed = run_chart(small_spec(), out, engine="local", progress=False)
    assert resumed.reused == ["compound-10-16-10_003000mm"] and resumed.computed == ["compound-10-16-10_004000mm"]
    assert without_wall(resumed.payload["rows"]) == without_wall(full.payload["rows"])
    done = run_chart(small_spec(), out, engine="local", progress=False)
    assert done.computed == [] and len(done.reused) == 2


@pytest.mark.parametrize("changes, message", [
    ({"budget": 7}, "budget 6 -> 7"),
    ({"driving": "back-and-forth"}, "driving 'racetrack' -> 'back-and-forth'"),
    ({"widths": "3,4,5"}, "widths_m"),
])
def test_a_changed_flag_is_refused_not_mixed(chart, changes, message):
    out, _ = chart
    before = sorted(p.name for p in (out / "cells").iterdir())
    widths = changes.pop("widths", "3,4")
    spec = make_spec("paper", FERTILIZER, widths, **{**SMALL, **changes})[0]
    with pytest.raises(SpreadgymError, match=message):
        run_chart(spec, out, engine="local", progress=False)
    assert sorted(p.name for p in (out / "cells").iterdir()) == before


def test_a_changed_scene_is_refused(chart, tmp_path):
    out, _ = chart
    scene = tmp_path / "paper.yaml"
    text = resolve_named("scenes", "paper").read_text(encoding="utf-8")
    scene.write_text(text.replace("height_m: 0.8", "height_m: 0.9"))
    spec = make_spec(str(scene), FERTILIZER, "3,4", **SMALL)[0]
    with pytest.raises(SpreadgymError, match="the scene"):
        run_chart(spec, out, engine="local", progress=False)


BASE = ["chart", "--scene", "paper", "--fertilizers", FERTILIZER, "--widths", "3,4", "--budget", "2",
        "--granules", "64"]


@pytest.mark.parametrize("argv, message", [
    (["--fertilizers", "urea"], "unknown fertilizer 'urea'"),
    (["--fertilizers", "mixture-17-21-17"], "mixture-17-21-17/mc was not measured"),
    (["--widths", "3,3.2"], "3.2 m is off the tray grid"),
    (["--widths", "3,60"], "60 m is beyond what the scene can throw"),
    (["--widths", "3:2:1"], "LO <= HI"),
    (["--widths", "three"], "expected W1,W2"),
    (["--budget", "0"], "--budget: 0 is out of range"),
    (["--workers", "0"], "--workers: 0 is out of range"),
    (["--driving", "spiral"], "--driving: invalid choice"),
    (["--address", "127.0.0.1:1"], "--address 127.0.0.1:1: no Ray cluster reachable"),
    (["--address", "nowhere"], "expected HOST:PORT"),
])
def test_bad_input_is_one_line_and_exit_2_with_nothing_written(argv, message, tmp_path, capsys):
    out = tmp_path / "out"
    args = BASE + argv + ["--out", str(out)]
    try:
        code = main(args)
    except SystemExit as exc:  # argparse
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert message in err[-1]
    assert not (out / "chart.csv").exists() and not (out / "cells").exists()
    assert not (out / "manifest.json").exists()


def test_the_search_objective_charges_mass_that_missed_the_trays():
    from types import SimpleNamespace

    from spreadgym.agents.chart.search import objective

    def metrics(landed_fraction, swath=24.0):
        return SimpleNamespace(cv_percent_at_target=6.0, cv_standard_error_percent=0.5, effective_swath_m=swath,
                               landed_fraction=landed_fraction)

    assert objective(metrics(1.0), 24.0) == (6.0, 6.0, 0.5)
    assert objective(metrics(0.95), 24.0)[0] == pytest.approx(6.0 + 5.0)  # 5 % intercepted or retained
    assert objective(metrics(0.95, swath=18.0), 24.0)[0] == pytest.approx(6.0 + 25.0 + 5.0)
    assert objective(metrics(None), 24.0)[0] == pytest.approx(106.0)  # nothing released
