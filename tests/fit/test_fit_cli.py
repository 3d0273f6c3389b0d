"""`spreadgym fit` end to end: the JSON contract, the files, the fitted scene read back by
`simulate`, the same bits from the same seed, and one-line errors for bad input."""

import json

import numpy as np
import yaml

from spreadgym.cli.main import main
from spreadgym.config.scene import load_scene
from spreadgym.fit.synthetic import synthetic_tray_test
from spreadgym.fit.trays import write_trays

KEY = "contact.vane_restitution"


def _trays(tmp_path):
    scene = load_scene("paper", {"granule.rotation": "locked"})
    test = synthetic_tray_test(scene, {KEY: 0.5}, model="compiled", granules=4096, noise_seed=3)
    return str(write_trays(tmp_path / "trays.csv", test, "synthetic, restitution 0.5"))


def _fit(capsys, *extra):
    assert main(["fit", *extra, "--set", "granule.rotation=locked", "--fit", f"{KEY}=0.3:0.7", "--granules", "1024",
                 "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_fit_writes_a_scene_simulate_reads(tmp_path, capsys):
    trays = _trays(tmp_path)
    out = tmp_path / "out"
    data = _fit(capsys, "--trays", trays, "--out", str(out), "--threads", "1")
    estimate = data["parameters"][KEY]
    assert estimate["low"] <= 0.5 <= estimate["high"] and estimate["low"] < estimate["estimate"] < estimate["high"]
    assert data["identifiable"] == {KEY: True}
    assert data["regime_switch"] == {KEY: 0.0}  # locked rotation: no granule rolls
    assert 0.0 < data["cv_percent_at_target"] < 100.0
    assert data["scene_yaml"] == str(out / "scene.yaml")
    for name in ("fit.json", "parameters.csv", "pattern.csv", "cv_curve.csv", "fit.png"):
        assert (out / name).stat().st_size > 0
    assert json.loads((out / "fit.json").read_text())["parameters"] == data["parameters"]
    fitted = load_scene(data["scene_yaml"])
    assert fitted == load_scene("paper", {"granule.rotation": "locked", KEY: estimate["estimate"]})
    assert yaml.safe_load((out / "scene.yaml").read_text())["contact"]["vane_restitution"] == estimate["estimate"]
    assert main(["simulate", "--scene", data["scene_yaml"], "--json", "--max-runs", "2"]) == 0
    simulated = json.loads(capsys.readouterr().out)
    assert simulated["cv_percent_at_target"] > 0
    band = np.loadtxt(out / "pattern.csv", delimiter=",", skiprows=1)
    assert np.all(band[:, 2] <= band[:, 1] + 1e-12) and np.all(band[:, 1] <= band[:, 3] + 1e-12)
    again = _fit(capsys, "--trays", trays)  # same seed, default threads: the same bits
    assert again["parameters"] == data["parameters"]
    assert again["scene_yaml"] is None


def test_bad_input_exits_2_with_one_line(tmp_path, capsys):
    trays = _trays(tmp_path)
    for argv, expected in (
        (["--trays", trays, "--fit", "contact.vane_friction=0.2:3"], "contact.vane_friction: "),
        (["--trays", trays, "--fit", "contact.vane_friction=0.5:0.2"], "must be finite with LO < HI"),
        (["--trays", trays, "--fit", "sim.granules=1:5"], "sim.granules: cannot be fitted"),
        (["--trays", trays, "--fit", "contact.nope=0:1"], "contact.nope: unknown key"),
        (["--trays", str(tmp_path / "missing.csv"), "--fit", f"{KEY}=0.3:0.7"], "cannot read"),
        (["--trays", trays, "--fit", f"{KEY}=0.3:0.7", "--set", "pattern.tray_width_m=0.25"],
         "the closest trays are 0.5 m apart but pattern.tray_width_m is 0.25 m"),
    ):
        code = main(["fit", *argv])
        err = capsys.readouterr().err
        assert code == 2 and expected in err and err.count("\n") == 1, (argv, err)


def test_the_summary_says_why_a_key_is_not_identifiable():
    from spreadgym.cli.fit import summary

    data = {"scene": "paper", "trays_file": "t.csv", "trays_used": 21, "evaluations": 9, "wall_s": 1.0,
            "catch_noise_sd": 0.05, "discrepancy_points": 4,
            "parameters": {k: {"estimate": 0.3, "low": 0.25, "high": 0.35} for k in ("a", "b", "c")},
            "identifiable": {"a": True, "b": False, "c": False},
            "regime_switch": {"a": 0.0, "b": 0.4, "c": 0.0}, "trade_offs": [], "cv_percent_at_target": None,
            "cv_percent_at_target_band": None, "scene_yaml": None}
    text = summary(data)
    assert "turns 40 % of the granules between sliding and rolling" in text
    assert "no: the test does not determine it" in text
