"""spreadgym chart without Ray: a small chart end to end, the verification it reports,
resume after an interruption, refusal of a changed chart, and bad input."""

import csv
import json
import math
import os
import shutil

import pytest

from spreadgym.agents.chart import make_spec, run_chart
from spreadgym.agents.chart.spec import cell_seed
from spreadgym.agents.chart.store import ChartStore, record_problem
from spreadgym.cli.main import main
from spreadgym.config.resources import resolve_named
from spreadgym.config.scene import scene_with
from spreadgym.errors import SpreadgymError
from spreadgym.spread.reference import pool_runs, reference_from

FERTILIZER = "compound-10-16-10"
# Small and fast: the closed form searches (drop 0 makes it exact for this scene), the
# full model verifies with 2 pooled runs.
KEYS = ["compound-10-16-10_003000mm", "compound-10-16-10_004000mm"]
DRAWS = {"draws": 4, "verify_draws": 4}  # perturbed batches per candidate and in the p90 verification
SMALL = dict(budget=6, granules=64, search_model="analytic", verify_runs=2, variability=DRAWS)
COLUMNS = ["fertilizer", "width_m", "driving", "rpm", "pitch_deg", "cv_percent", "cv_standard_error_percent",
           "cv_p90_percent", "cv_p90_standard_error_percent", "effective_swath_m", "cv_search_percent", "simulations",
           "wall_s"]


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
    assert names == {"chart.csv", "chart.json", "chart.md", "chart.png", "chart.html"}
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
        assert row["cv_standard_error_percent"] > 0 and row["cv_p90_standard_error_percent"] > 0
    first, second = payload["cells"]
    # 4 candidates searched and, at 3 m, 2 rounds of re-scores of 1 leader; at 4 m the leader and the
    # 3 m settings leave one round each, too few to re-score (each candidate 4 batches); then the
    # 2 nominal and 4 perturbed verification runs
    assert [r["simulations"] for r in payload["rows"]] == [(4 + 2) * 4 + 2 + 4, 4 * 4 + 2 + 4]
    assert (first["rescores"], second["rescores"]) == (2, 0)
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
    ({"steady_tolerance_pp": 1.5}, "steady_tolerance_pp 2.0 -> 1.5"),
    ({"tie_preference": "nearest"}, "tie_preference 'lowest-rpm' -> 'nearest'"),
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
    (["--fertilizers", "guano"], "unknown fertilizer 'guano'"),
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
    (["--address", "127.0.0.1:99999"], "port 99999 is out of range; allowed [1, 65535]"),
    (["--widths", "3,3.000000002"], "3.0 m and 3.000000002 m are one width to the millimetre"),
    (["--widths", "0.5"], "--widths: 0.5 m is narrower than 2 trays of 0.5 m"),
    (["--widths", "1e-10"], "--widths: 1e-10 m is narrower than 2 trays"),
    (["--fertilizers", "all,pellet"], "--fertilizers: 'all' stands alone"),
    (["--granules", "100000"], "--granules: 8 runs x 3200000 landing points per run"),
    (["--workers", "100000"], "--workers: 100000 is more than the"),
    (["--steady-tolerance-pp", "-1"], "--steady-tolerance-pp: -1 is out of range; allowed: [0, 100]"),
    (["--steady-tolerance-pp", "nan"], "--steady-tolerance-pp: nan is out of range"),
    (["--steady-tolerance-pp", "inf"], "--steady-tolerance-pp: inf is out of range"),
    (["--steady-tolerance-pp", "two"], "--steady-tolerance-pp: 'two' is not a number"),
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
    assert message in err[-1] and "Traceback" not in "".join(err)
    assert not out.exists()  # not even an empty folder


def _records(out):
    return [json.loads((out / "cells" / f"{key}.json").read_text(encoding="utf-8")) for key in KEYS]


def _edited(record, **row):
    edited = json.loads(json.dumps(record))
    edited["row"].update(row)
    return edited


def test_a_cell_file_is_reused_only_when_it_is_the_record_of_its_cell(chart):
    out, result = chart
    spec = result.spec
    first, second = _records(out)
    assert record_problem(spec, spec.cells[0], first) is None and record_problem(spec, spec.cells[1], second) is None
    wrong = {
        "no row": {"row": {}},
        "not a mapping": [1, 2],
        "another cell's": second,
        "width 77 m": _edited(first, width_m=77.0),
        "rpm -5": _edited(first, rpm=-5.0),
        "CV NaN": _edited(first, cv_percent=math.nan),
        "CV a string": _edited(first, cv_percent="9"),
        "a column more": _edited(first, extra=1),
        "settings off their unit vector": _edited(first, pitch_deg=first["row"]["pitch_deg"] + 1e-9),
        "simulations": _edited(first, simulations=10**9),
    }
    for name, record in wrong.items():
        assert record_problem(spec, spec.cells[0], record) is not None, name


def test_a_damaged_folder_is_repaired_not_trusted(chart, tmp_path):
    """A cell file that is not its cell's is recomputed, a damaged picture redrawn; the chart
    comes out as the undamaged one."""
    source, full = chart
    out = tmp_path / "damaged"
    shutil.copytree(source, out)
    (out / "cells" / f"{KEYS[0]}.json").write_text(json.dumps(_edited(_records(source)[0], width_m=77.0)))
    (out / "cells" / f"{KEYS[1]}.png").write_bytes(b"\x89PNG\r\n\x1a\n not a picture")
    result = run_chart(small_spec(), out, engine="local", progress=False)
    assert result.computed == [KEYS[0]] and result.reused == [KEYS[1]]
    assert result.replaced == {KEYS[0]: "it is another cell's"}
    assert without_wall(result.payload["rows"]) == without_wall(full.payload["rows"])
    assert ChartStore(out, result.spec).picture_ok(result.spec.cells[1])


@pytest.mark.parametrize("damage, message", [
    (lambda out: (out / "cells" / f"{KEYS[1]}.json").mkdir(parents=True), f"{KEYS[1]}.json is a folder"),
    (lambda out: (out / "cells" / f".{KEYS[1]}.png.partial").mkdir(parents=True), "png.partial is a folder"),
    (lambda out: (out / "chart.json").mkdir(parents=True), "chart.json is a folder"),
    (lambda out: out.mkdir() or (out / "cells").write_text("x"), "cells is a file, not a folder"),
])
def test_a_file_the_chart_writes_after_the_work_is_probed_before_it(damage, message, tmp_path):
    out = tmp_path / "chart"
    damage(out)
    before = sorted(p.relative_to(out) for p in out.rglob("*"))

    def never(cell, record):
        raise AssertionError("a cell ran before the folder was checked")

    with pytest.raises(SpreadgymError, match=message.replace(".", r"\.")):
        run_chart(small_spec(), out, engine="local", progress=False, on_cell=never)
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before  # nothing written


def test_the_embedded_ray_is_private_and_a_failed_start_is_one_line(monkeypatch):
    """Without --address a new local instance is started whatever RAY_ADDRESS says, its
    object store sized to the workers; a start that fails is a SpreadgymError of one line."""
    import ray

    from spreadgym.agents.chart.runner import connect_ray

    calls = []

    def init(**kwargs):
        calls.append(kwargs)
        raise RuntimeError("node timed out during startup\nTraceback ...")

    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:1")
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", init)
    monkeypatch.setattr(ray, "shutdown", lambda: None)
    with pytest.raises(SpreadgymError) as refused:
        connect_ray(2, None)
    assert calls[0]["address"] == "local" and calls[0]["num_cpus"] == 2
    assert 75 * 2**20 <= calls[0]["object_store_memory"] <= 256 * 2**20
    assert str(refused.value) == "the embedded Ray (2 CPUs) did not start: node timed out during startup"


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


def test_chart_materials_runs_the_users_fertilizer_from_its_manifest(copied_fertilizer, tmp_path):
    """chart --materials FILE: the file's fertilizers are chart fertilizers ('all' offers them); the spec records
    their entries, so the cells run them without the file (a cluster's workers) and a changed file is noticed."""
    from spreadgym.config.materials import MATERIALS_ENV, user_materials

    path, name = copied_fertilizer
    with user_materials(path):
        assert name in make_spec("paper", "all", "3", **SMALL)[0].fertilizers
        spec = make_spec("paper", name, "3", **SMALL)[0]
    assert MATERIALS_ENV not in os.environ and set(spec.manifest()["materials"]) == {name}
    result = run_chart(spec, tmp_path / "mine", engine="local", progress=False)  # no file, no variable: the spec
    (row,) = result.payload["rows"]
    assert row["fertilizer"] == name and 0 < row["cv_percent"] < 100
    changed = tmp_path / "changed.yaml"
    changed.write_text(path.read_text().replace("particle_density_kg_m3: 1734.0", "particle_density_kg_m3: 1800.0"))
    with user_materials(changed):
        other = make_spec("paper", name, "3", **SMALL)[0]
    assert other.manifest()["materials"][name]["particle_density_kg_m3"] == 1800.0
    with pytest.raises(SpreadgymError):
        run_chart(other, tmp_path / "mine", engine="local", progress=False)
