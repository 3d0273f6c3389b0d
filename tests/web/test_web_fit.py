"""The fit page's API: `POST /api/fit` answers what `spreadgym fit --json` prints for the
same tray file and keys, with the fitted scene's YAML; bad input is 422 naming the key."""

import json
import subprocess
import sys

import pytest
import yaml
from fastapi.testclient import TestClient

from spreadgym.agents.web.app import create_app
from spreadgym.config.scene import load_scene
from spreadgym.fit.synthetic import synthetic_tray_test
from spreadgym.fit.trays import write_trays

KEY = "contact.vane_restitution"


@pytest.fixture(scope="module")
def trays(tmp_path_factory):
    test = synthetic_tray_test(load_scene("paper"), {KEY: 0.5}, model="compiled", granules=4096, noise_seed=3)
    return write_trays(tmp_path_factory.mktemp("fit") / "trays.csv", test, "synthetic, restitution 0.5")


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(tmp_path_factory.mktemp("charts")), base_url="http://127.0.0.1") as test_client:
        yield test_client


def test_fit_is_the_cli_fit(client, trays):
    response = client.post("/api/fit", json={"scene": "paper", "trays": trays.read_text(),
                                             "fit": [f"{KEY}=0.3:0.7"], "granules": 1024})
    assert response.status_code == 200, response.text
    data = response.json()
    done = subprocess.run([sys.executable, "-m", "spreadgym.cli.main", "fit", "--scene", "paper", "--trays",
                           str(trays), "--fit", f"{KEY}=0.3:0.7", "--granules", "1024", "--json"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    printed = json.loads(done.stdout)
    for key in ("parameters", "identifiable", "cv_percent_at_target", "effective_swath_m", "evaluations"):
        assert data["fit"][key] == printed[key], key
    fitted = yaml.safe_load(data["scene_yaml_text"])
    assert fitted["contact"]["vane_restitution"] == data["fit"]["parameters"][KEY]["estimate"]
    plot = data["plot"]
    assert len(plot["measured_g"]) == len(plot["measured_x_m"]) >= 5
    assert len(plot["fitted_g"]) == len(plot["center_m"]) and len(plot["cv_percent"]) == len(plot["widths_m"])


@pytest.mark.parametrize("change, named", [
    ({"fit": ["contact.vane_friction=0.2:3"]}, "contact.vane_friction: "),
    ({"fit": ["sim.granules=1:5"]}, "sim.granules: cannot be fitted"),
    ({"fit": ["contact.nope=0:1"]}, "contact.nope: unknown key"),
    ({"fit": ["contact.vane_friction"]}, "--fit: expected KEY=LO:HI"),
    ({"fit": []}, "--fit: give at least one"),
    ({"trays": "x_m,grams\n0,1\n"}, "--trays: 'uploaded trays' line 1: unknown column 'grams'"),
    ({"trays": "x_m,mass_g\n0,1\n0.5,-2\n"}, "line 3: mass_g -2 is negative"),
    ({"trays": None}, "trays:"),
    ({"granules": 0}, "granules: 0 is out of range"),
    ({"scene": "../paper"}, "scenes: unknown name"),
    ({"set": {"spinner.rpm": -1}}, "spinner.rpm"),
    ({"model": "x"}, "model: unknown model"),
])
def test_bad_fit_input_is_422_naming_it(client, trays, change, named):
    body = {"scene": "paper", "trays": trays.read_text(), "fit": [f"{KEY}=0.3:0.7"], "granules": 64, **change}
    body = {k: v for k, v in body.items() if v is not None}
    response = client.post("/api/fit", json=body)
    assert response.status_code == 422, response.text
    assert named in response.json()["error"]
