"""The core CLI commands `calibrate` (and the shared exit-code behaviour)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from spreadgym.cli.main import main
from spreadgym.physics import calibration as cal

REPO = Path(__file__).resolve().parents[2]
CONTACT_KEYS = {"stiffness_n_per_m", "damping_ns_per_m", "damping_ratio"}
ROW_KEYS = {"fertilizer", "surface", "mass_from_stiffness_kg", "mass_from_damping_kg", "consistent"}


def run_json(capsys, argv):
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


def test_calibrate_json(capsys):
    argv = ["calibrate", "--mass", "2.45e-5", "--restitution", "0.43", "--contact-time", "2.323e-4"]
    data = run_json(capsys, argv + ["--json"])
    assert CONTACT_KEYS <= set(data)
    assert set(data) - CONTACT_KEYS <= {"critical_time_step_s"}
    # independent of the library code: Eqs. 8-10 written out
    zeta = -math.log(0.43) / math.sqrt(math.pi**2 + math.log(0.43) ** 2)
    k = math.pi**2 * 2.45e-5 / ((1 - zeta**2) * 2.323e-4**2)
    assert data["damping_ratio"] == pytest.approx(zeta, rel=1e-12)
    assert data["stiffness_n_per_m"] == pytest.approx(k, rel=1e-12)
    assert data["damping_ns_per_m"] == pytest.approx(2 * zeta * math.sqrt(k * 2.45e-5), rel=1e-12)
    assert 0 < data["critical_time_step_s"] < 2.323e-4


def test_calibrate_table(capsys):
    assert main(["calibrate", "--mass", "2e-5", "--restitution", "0.5", "--contact-time", "2e-4"]) == 0
    out = capsys.readouterr().out
    assert "stiffness_n_per_m" in out and "N/m" in out and "{" not in out


def test_paper_table_json(capsys):
    data = run_json(capsys, ["calibrate", "--paper-table", "--json"])
    assert set(data) == {"rows"}
    assert len(data["rows"]) == 6
    for row in data["rows"]:
        assert ROW_KEYS <= set(row)
        assert isinstance(row["consistent"], bool)
    flagged = {(r["fertilizer"], r["surface"]) for r in data["rows"] if not r["consistent"]}
    assert ("pellet", "steel") in flagged
    assert ("compound-10-16-10", "mc") not in flagged


def test_paper_table_text(capsys):
    assert main(["calibrate", "--paper-table"]) == 0
    out = capsys.readouterr().out
    assert "pellet" in out and "NO" in out and "median" in out


def test_pair_mode(capsys):
    data = run_json(capsys, ["calibrate", "--fertilizer", "compound-10-16-10", "--surface", "mc", "--json"])
    assert CONTACT_KEYS <= set(data)
    assert data["paper_row_flagged"] is False
    assert data["mass_kg"] == pytest.approx(math.pi / 6 * 0.003**3 * 1734.0)
    expected = cal.spring_dashpot(data["mass_kg"], 0.43, 2.323e-4)
    assert data["stiffness_n_per_m"] == pytest.approx(expected.stiffness_n_per_m)


def test_pair_mode_flagged_row_prints_a_note(capsys):
    code = main(["calibrate", "--fertilizer", "pellet", "--surface", "steel", "--mass", "2e-5", "--json"])
    captured = capsys.readouterr()
    assert code == 0
    assert json.loads(captured.out)["paper_row_flagged"] is True
    assert "pellet/steel" in captured.err and "flagged" in captured.err


BASE = ["calibrate", "--mass", "2e-5", "--restitution", "0.5", "--contact-time", "2e-4"]


def _with(flag, value):
    argv = list(BASE)
    argv[argv.index(flag) + 1] = value
    return argv


@pytest.mark.parametrize(
    "argv, text",
    [
        (_with("--restitution", "0"), r"--restitution: 0 outside (0, 1]"),
        (_with("--restitution", "1.3"), r"--restitution: 1.3 outside (0, 1]"),
        (_with("--restitution", "-0.1"), r"--restitution: -0.1 outside (0, 1]"),
        (_with("--restitution", "nan"), r"--restitution: nan is not a finite number"),
        (_with("--mass", "0"), r"--mass: 0 outside (0, 0.01] kg"),
        (_with("--mass", "-1"), r"--mass: -1 outside (0, 0.01] kg"),
        (_with("--mass", "0.5"), r"--mass: 0.5 outside (0, 0.01] kg"),
        (_with("--contact-time", "0"), r"--contact-time: 0 outside [1e-07, 0.01] s"),
        (_with("--contact-time", "0.05"), r"--contact-time: 0.05 outside [1e-07, 0.01] s"),  # materials' cap
        (["calibrate", "--mass", "2e-5", "--restitution", "0.5"], "--contact-time"),
        (["calibrate"], "--mass"),
        (["calibrate", "--paper-table", "--mass", "1e-5"], "--paper-table"),
        (["calibrate", "--fertilizer", "pellet"], "--surface"),
        (["calibrate", "--fertilizer", "pellet", "--surface", "mc", "--restitution", "0.5"], "--restitution"),
        (["calibrate", "--fertilizer", "guano", "--surface", "mc"], "unknown fertilizer 'guano'"),
        (["calibrate", "--fertilizer", "pellet", "--surface", "glass"], "unknown surface material 'glass'"),
        (["calibrate", "--fertilizer", "pellet", "--surface", "rubber"], "pellet/rubber"),
        (["calibrate", "--fertilizer", "pellet", "--surface", "mc", "--mass", "0"], r"--mass: 0 outside"),
    ],
)
def test_bad_input_exits_2_with_message(capsys, argv, text):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "spreadgym calibrate: error:" in captured.err
    assert text in captured.err
    assert "Traceback" not in captured.err


def test_non_numeric_flag_is_an_argparse_error(capsys):
    assert main(_with("--mass", "heavy")) == 2  # argparse's usage error, returned
    assert "--mass" in capsys.readouterr().err


@pytest.mark.parametrize("argv, text", [
    (["simulate", "--precision", "-1"], "spreadgym simulate: error: argument --precision: -1.0 must be"),
    (["calibrate", "--mass", "heavy"], "spreadgym calibrate: error: argument --mass:"),
    (["simulate", "--no-such-flag"], "spreadgym: error: unrecognized arguments: --no-such-flag"),
    ([], "spreadgym: error: the following arguments are required: COMMAND"),
    (["simulate", "--set", "spinner.rpm=nan"], "spinner.rpm: Input should be a valid number (got 'nan'); allowed:"),
])
def test_a_usage_error_is_one_line_without_the_usage_block(capsys, argv, text):
    """argparse printed its whole usage block before the error; the error is one line, and a
    number that is not one names its allowed range ('nan' is a string in YAML)."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and text in err and "usage:" not in err, err


def test_subprocess_exit_code_and_no_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "spreadgym.cli.main", "calibrate",
         "--mass", "-1", "--restitution", "0.5", "--contact-time", "2e-4"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "--mass: -1" in proc.stderr


def test_an_output_folder_is_probed_before_any_work_and_not_created(tmp_path):
    import argparse

    from spreadgym.cli.arguments import output_folder

    assert output_folder(str(tmp_path / "a" / "b")) == tmp_path / "a" / "b"
    assert not list(tmp_path.iterdir())  # nothing made: the command makes it when it writes; the probe file is gone
    (tmp_path / "f").write_text("x")
    for bad, words in ((tmp_path / "f", "is a file, not a folder"), (tmp_path / "f" / "x", "f is a file, not a folder"),
                       ("/proc/spreadgym-probe", "cannot write in")):  # root passes permission bits; procfs does not
        with pytest.raises(argparse.ArgumentTypeError, match=words):
            output_folder(str(bad))


@pytest.mark.parametrize("argv, text", [
    (["compare", "--seeds", "100000000", "--out", "x"], "--seeds: 100000000 is out of range; allowed: in [1, 1000]"),
    (["compare", "--episodes", "0", "--out", "x"], "--episodes: 0 is out of range; allowed: in [1, 1000]"),
    (["serve", "--charts", __file__], "is a file, not a folder"),
])
def test_counts_and_folders_that_cannot_work_are_refused_at_the_flag(capsys, argv, text):
    assert main(argv) == 2
    assert text in capsys.readouterr().err
