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
        (["--trays", trays, "--fit", f"{KEY}=0.3:0.7", "--set", "pattern.tray_width_m=1.0"],
         "overlap: their centres are closer than pattern.tray_width_m = 1 m"),
        (["--trays", trays, "--fit", f"{KEY}=0.3:0.7", "--set", f"{KEY}=0.5"],
         f"{KEY}: is set by --set and fitted by --fit; give it one way"),
        (["--trays", trays, "--fit", "vanes.count=2:6"], "vanes.count: is a whole number (vanes.count = 4)"),
        (["--trays", trays, "--fit", "spinner.radius_m=0.1:0.3,feed.radius_m=0.05:0.14"],
         "--fit: the search box's corner spinner.radius_m=0.1, feed.radius_m=0.14 is not a valid scene"),
        (["--trays", "/dev/zero", "--fit", f"{KEY}=0.3:0.7"], "is not a regular file"),
        (["--trays", trays, "--fit", f"{KEY}=0.3:0.7", "--granules", "1000000"],
         "landing points per run; allowed: at most 4000000"),
    ):
        code = main(["fit", *argv])
        err = capsys.readouterr().err
        assert code == 2 and expected in err and err.count("\n") == 1, (argv, err)
    code = main(["fit", "--trays", trays, "--fit", f"{KEY}=0.3:0.7", "--threads", "5000"])  # as simulate caps it
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 2 and last.endswith("argument --threads: 5000 is out of range; allowed: in [1, 4096]")


def test_the_summary_says_why_a_key_is_not_identifiable():
    from spreadgym.cli.fit import summary

    data = {"scene": "paper", "trays_file": "t.csv", "trays_used": 21, "evaluations": 9, "wall_s": 1.0,
            "catch_noise_sd": 0.05, "discrepancy_points": 4,
            "parameters": {k: {"estimate": 0.3, "low": 0.25, "high": 0.35} for k in ("a", "b", "c", "d")},
            "identifiable": {"a": True, "b": False, "c": False, "d": False},
            "regime_switch": {"a": 0.0, "b": 0.4, "c": 0.0, "d": 0.0}, "trade_offs": [], "cv_percent_at_target": None,
            "cv_percent_at_target_band": None, "scene_yaml": None, "measured_cv_percent_at_target": None,
            "measured_span_share": 0.5, "estimate_at_search_bound": {"a": False, "b": False, "c": False, "d": True}}
    text = summary(data)
    assert "turns 40 % of the granules between sliding and rolling" in text
    assert "no: the test does not determine it" in text
    assert "d    0.3       [0.25, 0.35]   no: the estimate is at the search bound" in text
    assert "measured trays' own CV: not given (the trays span 50 % of the fitted pattern's mass" in text


def test_out_never_replaces_an_input_nor_an_earlier_fit(tmp_path, capsys):
    """fit --trays d/pattern.csv --scene d/scene.yaml --out d would replace both inputs with
    outputs of the same names: refused before the fit, --force or not; an earlier fit's
    outputs need --force; a refused or failed run leaves no folder behind."""
    import shutil

    trays = tmp_path / "d" / "pattern.csv"
    trays.parent.mkdir()
    shutil.copy(_trays(tmp_path), trays)
    scene = tmp_path / "d" / "scene.yaml"
    assert main(["fit", "--trays", str(trays), "--fit", f"{KEY}=0.3:0.7", "--set", "granule.rotation=locked",
                 "--out", str(tmp_path / "x"), "--granules", "256"]) == 0
    capsys.readouterr()
    shutil.copy(tmp_path / "x" / "scene.yaml", scene)
    before = {p: p.read_bytes() for p in (trays, scene)}
    for extra in ([], ["--force"]):
        for argv in (["--trays", str(trays)], ["--trays", str(tmp_path / "trays.csv"), "--scene", str(scene)]):
            code = main(["fit", *argv, "--fit", f"{KEY}=0.3:0.7", "--out", str(trays.parent), *extra])
            err = capsys.readouterr().err
            assert code == 2 and "would replace the input" in err and err.count("\n") == 1, err
    assert {p: p.read_bytes() for p in (trays, scene)} == before
    code = main(["fit", "--trays", str(trays), "--fit", f"{KEY}=0.3:0.7", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2 and "holds an earlier `spreadgym fit`'s outputs" in err and "--force" in err, err
    far = tmp_path / "far.csv"  # trays 100 m off: the fit refuses after its start design
    far.write_text("x_m,mass_g\n" + "".join(f"{100 + 0.5 * i},{1 + i % 3}\n" for i in range(9)))
    code = main(["fit", "--trays", str(far), "--fit", f"{KEY}=0.3:0.7", "--out", str(tmp_path / "new" / "deeper"),
                 "--granules", "64"])
    capsys.readouterr()
    assert code == 2 and not (tmp_path / "new").exists()  # the fit failed: no folder left behind



def test_a_fit_at_few_granules_says_its_intervals_understate_the_noise(tmp_path, capsys):
    from spreadgym.cli.fit import HONEST_FIT_GRANULES

    trays = _trays(tmp_path)
    for granules, said in ((256, True), (HONEST_FIT_GRANULES, False)):
        assert main(["fit", "--trays", trays, "--set", "granule.rotation=locked", "--fit", f"{KEY}=0.3:0.7",
                     "--granules", str(granules), "--json"]) == 0
        assert ("the intervals understate the simulation's own noise" in capsys.readouterr().err) == said


def test_the_estimate_is_the_centre_of_its_intervals_when_a_profile_keeps_meeting_lower_points(monkeypatch):
    """A profile that meets a lower point moves the fit there and the profiles are redone;
    on the last allowed pass the fit stays, so the estimate is the point its intervals were
    walked from (it moved after them before)."""
    import dataclasses

    from spreadgym.fit import uncertainty
    from spreadgym.fit.optimise import Minimum
    from spreadgym.fit.run import RECENTRES, fit_tray_test
    from spreadgym.fit.space import parse_fit_specs

    scene = load_scene("paper", {"granule.rotation": "locked"})
    test = synthetic_tray_test(scene, {KEY: 0.5}, model="compiled", granules=2048, noise_seed=3)
    real, centres = uncertainty.profile_interval, []

    def always_lower(objective, best, j, level, info):  # every profile "meets" a point far below, at its end
        centres.append(best.unit.copy())
        found = real(objective, best, j, level, info)
        return dataclasses.replace(found, lowest=Minimum(found.low_point.copy(), -1e9))

    monkeypatch.setattr(uncertainty, "profile_interval", always_lower)
    fit = fit_tray_test(scene, parse_fit_specs([f"{KEY}=0.3:0.7"], scene), test, model="compiled", granules=256,
                        discrepancy=None)
    assert len(centres) == RECENTRES + 1  # one key: a profile per pass
    assert np.allclose(fit.space.unit(fit.estimate), centres[-1], rtol=0, atol=1e-12)  # unit -> value -> unit
