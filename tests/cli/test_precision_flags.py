"""`spreadgym simulate --precision` and `reference --precision`: runs pooled to the standard error asked, the JSON's
new keys, a summary that prints no digit its standard error does not support."""

import json
import re

import pytest

from spreadgym.cli.main import main
from spreadgym.report import decimals_supported, with_error


def simulate_json(capsys, *argv) -> dict:
    assert main(["simulate", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_json_reports_the_granules_behind_the_estimate_and_meets_the_precision(capsys):
    out = simulate_json(capsys, "--set", "sim.granules=1024", "--precision", "0.5")
    assert out["precision_percent"] == 0.5 and out["precision_met"] is True
    assert out["cv_standard_error_percent"] <= 0.5
    assert out["granules_simulated"] == 1024 * out["runs"] and out["granules"] == 1024
    assert out["mass"]["released_kg"] > 0 and out["effective_swath_m"] > 0
    tighter = simulate_json(capsys, "--set", "sim.granules=1024", "--precision", "0.25")
    assert tighter["runs"] > out["runs"] and tighter["cv_standard_error_percent"] <= 0.25


def test_the_cap_is_kept_and_reported(capsys):
    out = simulate_json(capsys, "--set", "sim.granules=256", "--precision", "0.01", "--max-runs", "3")
    assert out["runs"] == 3 and out["precision_met"] is False
    assert any("cap of 3 runs" in note for note in out["notes"])


@pytest.mark.parametrize("argv, fragment", [
    (["--precision", "0"], "--precision"),
    (["--precision", "nan"], "--precision"),
    (["--precision", "abc"], "--precision"),
    (["--max-runs", "1"], "--max-runs"),
    (["--max-runs", "100000"], "--max-runs"),
])
def test_bad_precision_flags_exit_2_with_one_line(capsys, argv, fragment):
    assert main(["simulate", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert fragment in err and "Traceback" not in err


def test_summary_shows_the_cv_to_the_place_of_its_standard_error(capsys):
    assert main(["simulate", "--set", "sim.granules=1024", "--precision", "0.3"]) == 0
    line = next(row for row in capsys.readouterr().out.splitlines() if row.startswith("CV at target"))
    value, error = re.search(r"([\d.]+) \+- ([\d.]+) %", line).groups()
    def places(text):
        return len(text.split(".")[1]) if "." in text else 0

    assert places(value) == places(error) == decimals_supported(float(error))


@pytest.mark.parametrize("value, error, shown", [
    (7.406, 0.188, "7.4 +- 0.2 %"), (7.406, 0.05, "7.41 +- 0.05 %"), (12.3, 2.6, "12 +- 3 %"),
    (5.0, 0.096, "5.0 +- 0.1 %"), (7.4, None, "7.4 %"),
])
def test_with_error_rounds_to_the_first_significant_digit_of_the_error(value, error, shown):
    assert with_error(value, error, "%") == shown


def test_a_run_where_nothing_departs_prints_a_summary_not_a_traceback(capsys):
    argv = ["simulate", "--set", "feed.radius_m=0", "--set", "feed.spread_m=0", "--set", "sim.granules=64"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "no granule left the spinner" in text and "nothing landed" in text
    assert main([*argv, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["cv_percent_at_target"] is None


def test_reference_pools_to_its_precision_or_exactly_the_runs_asked(capsys):
    assert main(["reference", "--granules", "512", "--precision", "0.6", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["precision_met"] and out["cv_standard_error_percent"] <= 0.6
    assert out["granules_simulated"] == out["granules"] == 512 * out["runs"]
    assert main(["reference", "--granules", "256", "--replicates", "3", "--json"]) == 0
    fixed = json.loads(capsys.readouterr().out)
    assert fixed["runs"] == 3 and fixed["precision_met"] is None


def test_pooled_tray_masses_give_the_reference_of_pooled_landings():
    """The precision path keeps replicate tray masses, not every landing: same figures."""
    from spreadgym.config.scene import load_scene
    from spreadgym.spread.precision import reference_precisely
    from spreadgym.spread.reference import pool_runs, reference_from

    scene = load_scene("field", {"sim.granules": 256, "sim.seed": 4})
    by_masses = reference_precisely(scene, runs=3).to_json()
    by_landings = reference_from(scene, pool_runs(scene, 3)).to_json()
    for key in ("granules", "landed_granules", "replicates", "effective_swath_m", "effective_swath_interval_m"):
        assert by_masses[key] == by_landings[key], key
    for key in ("cv_percent_at_target", "cv_standard_error_percent", "cv_raw_percent"):
        assert by_masses[key] == pytest.approx(by_landings[key], rel=1e-9), key
    assert by_masses["trays"]["center_m"].tolist() == by_landings["trays"]["center_m"].tolist()


def test_reference_names_its_flag_when_granules_exceed_the_work_bound(capsys):
    assert main(["reference", "--granules", "1000000", "--replicates", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("spreadgym reference: error: --granules:") and "\n" not in err


def test_simulate_gives_the_same_bits_on_any_thread_count(capsys):
    outs = []
    for threads in ("1", "2"):
        out = simulate_json(capsys, "--set", "sim.granules=512", "--precision", "0.5", "--threads", threads)
        out.pop("wall_s")
        outs.append(json.dumps(out, sort_keys=True))
    assert outs[0] == outs[1]
