"""`spreadgym advise` end to end on a cheap synthetic tray test (compiled-model truth at known keys): the contract's
JSON, the advice better than the tested settings at the true keys, never worse on the fit, the same bits twice,
the files of --out, bad input in one line, and POST /api/advise answering what the command prints."""

import json

import pytest

from spreadgym.cli.main import main
from spreadgym.config.scene import load_scene, scene_with
from spreadgym.fit.synthetic import synthetic_tray_test
from spreadgym.fit.trays import write_trays

TRUTH = {"contact.vane_restitution": 0.45, "contact.rolling_resistance": 0.05}
FIT = "contact.vane_restitution=0.3:0.7,contact.rolling_resistance=0:0.2"  # the new key is any fit's key
CHEAP = ["--budget", "24", "--granules", "256", "--fit-granules", "512", "--seed", "3"]
WIDTH = 4.0


@pytest.fixture(scope="module")
def trays(tmp_path_factory):
    """A one-pass test of the paper scene as shipped (500 rpm, radial vanes: CV about 20 % at 4 m)."""
    test = synthetic_tray_test(load_scene("paper"), TRUTH, model="compiled", granules=4096, noise_seed=1)
    return write_trays(tmp_path_factory.mktemp("advise") / "trays.csv", test, "synthetic, known keys")


@pytest.fixture(scope="module")
def advised(trays, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "advice"
    argv = ["advise", "--scene", "paper", "--trays", str(trays), "--width", f"{WIDTH:g}", "--fit", FIT, "--json",
            "--out", str(out), *CHEAP]
    return argv, out


def _run(argv, capsys) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_the_advice_keeps_the_contract_and_beats_the_tested_settings(advised, capsys):
    from spreadgym.spread.precision import simulate_precisely

    argv, out = advised
    code, stdout, _ = _run(argv, capsys)
    assert code == 0
    data = json.loads(stdout)
    for key in ("changes", "cv_before_percent", "cv_before_percent_low", "cv_before_percent_high",
                "cv_after_percent", "cv_after_percent_low", "cv_after_percent_high", "instruction"):
        assert key in data, key
    assert set(data["fit"]["parameters"]) == set(TRUTH)
    assert data["changes"], "the shipped settings at 4 m are far from the best: the advice changes them"
    for key, change in data["changes"].items():
        assert change == {"from": data["tested"][key], "to": data["advised"][key]}
    assert data["tested"] == {"spinner.rpm": 500.0, "vanes.pitch_deg": 0.0}
    assert data["cv_after_percent"] < data["cv_before_percent"]
    assert data["cv_after_percent_low"] <= data["cv_after_percent"] <= data["cv_after_percent_high"]
    assert data["instruction"].startswith("Set the disc speed to") or data["instruction"].startswith("Set the vane")
    # at the true keys (the truth's model), the advised settings spread more evenly than the tested ones
    truth = scene_with(load_scene("paper"), {**TRUTH, "pattern.target_swath_m": WIDTH})
    before, after = (simulate_precisely(scene_with(truth, data[k]), 0.2, 16, model="compiled").to_json()
                     ["cv_percent_at_target"] for k in ("tested", "advised"))
    assert after < before - 5.0, (before, after)
    # the files: the same advice, the fitted scene and the advised one (simulate takes it)
    assert json.loads((out / "advice.json").read_text())["changes"] == data["changes"]
    advised_scene = load_scene(str(out / "advised.yaml"))
    assert advised_scene.spinner.rpm == data["advised"]["spinner.rpm"]
    assert advised_scene.pattern.target_swath_m == WIDTH
    assert load_scene(str(out / "fitted.yaml")).spinner.rpm == 500.0
    # the same inputs, the same advice to the bit
    code, again, _ = _run(argv[:-len(CHEAP) - 2] + CHEAP, capsys)
    assert code == 0
    same = json.loads(again)
    assert {k: v for k, v in same.items() if k not in ("wall_s", "fit", "files")} == \
        {k: v for k, v in data.items() if k not in ("wall_s", "fit", "files")}


def test_settings_not_better_on_the_fit_are_kept(trays, monkeypatch):
    """Never worse than the test: where the advised settings' CV on the fitted model is not below the tested
    ones', the advice is to keep them."""
    import spreadgym.agents.advise.run as run
    from spreadgym.fit.trays import read_trays

    def flat(fit, width_m, settings):  # every setting the same CV on the fit
        return (7.0, 6.0, 8.0), (7.0, 6.0, 8.0), 0.2, 0.2

    monkeypatch.setattr(run, "expected_cv", flat)
    advice = run.advise(load_scene("paper"), read_trays(trays, 0.5), WIDTH, fit=[FIT], budget=8, granules=128,
                        fit_granules=256, seed=1)
    assert advice.changes == {} and advice.advised == advice.tested
    assert advice.instruction.startswith("Keep the settings") and "7.0 %" in advice.instruction


@pytest.mark.parametrize("extra, message", [
    (["--width", "4.2"], "--width: 4.2 m is off the tray grid"),
    (["--width", "0.5"], "--width: 0.5 m is narrower than 2 trays"),
    (["--width", "4", "--fit", "sim.granules=1:2"], "sim.granules: cannot be fitted"),
])
def test_bad_input_is_one_line(trays, capsys, extra, message):
    argv = ["advise", "--scene", "paper", "--trays", str(trays), *extra]
    code, _, err = _run(argv, capsys)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


def test_out_never_replaces_the_tray_file(trays, capsys):
    target = trays.parent / "advice.json"
    target.write_text(trays.read_text())
    code, _, err = _run(["advise", "--scene", "paper", "--trays", str(target), "--width", "4", "--out",
                         str(trays.parent)], capsys)
    assert code == 2 and "would replace the input" in err
    assert target.read_text() == trays.read_text()


def test_the_api_answers_what_the_command_prints(trays, capsys):
    from fastapi.testclient import TestClient

    from spreadgym.agents.web.app import create_app

    code, stdout, _ = _run(["advise", "--scene", "paper", "--trays", str(trays), "--width", "4", "--fit",
                            "contact.vane_restitution=0.3:0.7", "--json", *CHEAP], capsys)
    assert code == 0
    cli = json.loads(stdout)
    with TestClient(create_app(), base_url="http://127.0.0.1") as client:  # the Host the app answers
        answer = client.post("/api/advise", json={"scene": "paper", "trays": trays.read_text(), "width": 4,
                                                  "fit": ["contact.vane_restitution=0.3:0.7"], "budget": 24,
                                                  "granules": 256, "fit_granules": 512, "seed": 3})
        assert answer.status_code == 200, answer.text
        page = answer.json()["advice"]
        bad = client.post("/api/advise", json={"scene": "paper", "trays": trays.read_text(), "width": 4.2})
        assert bad.status_code == 422 and "--width: 4.2 m is off the tray grid" in bad.json()["error"]
    drop = ("wall_s", "fit", "files")
    assert {k: v for k, v in page.items() if k not in drop} == {k: v for k, v in cli.items() if k not in drop}
    assert page["fit"]["parameters"] == cli["fit"]["parameters"]



def test_advise_materials_advises_a_users_copy_as_the_original(trays, capsys, copied_fertilizer, tmp_path):
    """advise --materials FILE: a file restating the scene's compound value for value (so the scene carries it
    inline, and the search's batches are drawn from it) gives the library compound's advice to the bit; a
    fertilizer only the file knows is advised on."""
    path, name = copied_fertilizer
    restated = tmp_path / "restated.yaml"
    restated.write_text(path.read_text().replace(name, "compound-10-16-10"))
    argv = ["advise", "--scene", "paper", "--trays", str(trays), "--width", "4", "--fit",
            "contact.vane_restitution=0.3:0.7", "--json", *CHEAP]
    runs = []
    for extra in ([], ["--materials", str(restated)], ["--materials", str(path), "--set", f"fertilizer={name}"]):
        code, stdout, _ = _run(argv + extra, capsys)
        assert code == 0
        runs.append(json.loads(stdout))
    drop = ("wall_s", "fit", "files")
    assert {k: v for k, v in runs[1].items() if k not in drop} == {k: v for k, v in runs[0].items() if k not in drop}
    assert runs[2]["fertilizer"] == name and runs[2]["cv_after_percent"] <= runs[2]["cv_before_percent"]


def test_the_tests_p90_is_reported_only_where_the_test_itself_was_scored():
    """A tested setting outside the settings box is clipped onto its edge when scored: that
    score is not the test's (twin-field's feed angle box is 110-150 deg)."""
    from spreadgym.agents.advise.run import scored_as_tested, tested_settings
    from spreadgym.config.scene import load_scene
    from spreadgym.config.settings import SettingsSpace

    scene = load_scene("twin-field")
    space = SettingsSpace(scene)
    assert scored_as_tested(space, scene, tested_settings(space, scene))
    outside = load_scene("twin-field", {"feed.angle_deg": 100.0})
    assert not scored_as_tested(space, outside, tested_settings(space, outside))
    moved = load_scene("twin-field", {"spinner.rpm": scene.spinner.rpm + 50.0})  # a fitted setting moved the scene
    assert not scored_as_tested(space, moved, tested_settings(space, scene))
