"""The web app's API through FastAPI's test client: the simulate contract (the CLI's own
JSON), bad input as 422 naming the key, chart folders confined to --charts, the body cap,
and a cancelled chart job that leaves the server working."""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from spreadgym.agents.web.app import MAX_BODY_BYTES, create_app

ROOT = Path(__file__).resolve().parents[2]
SMALL = {"sim.granules": 256}
LOCAL = "http://127.0.0.1"  # the Host the app answers (TestClient says "testserver" otherwise)


@pytest.fixture(scope="module")
def charts_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("charts")
    shutil.copytree(ROOT / "docs" / "charts" / "paper", root / "paper")
    (root / "notes.txt").write_text("not a chart")
    (root / "outside").symlink_to("/")
    return root


@pytest.fixture(scope="module")
def client(charts_dir):
    with TestClient(create_app(charts_dir), base_url=LOCAL) as test_client:
        yield test_client


def cli_json(scene: str, sets: list[str]) -> dict:
    argv = [sys.executable, "-m", "spreadgym.cli.main", "simulate", "--scene", scene, "--json"]
    for assignment in sets:
        argv += ["--set", assignment]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_health_and_pages(client):
    assert client.get("/api/health").json() == {"ok": True}
    assert "plotly.min.js" in client.get("/").text
    assert client.get("/charts").status_code == 200
    js = client.get("/static/plotly.min.js")
    assert js.status_code == 200 and len(js.content) > 1_000_000  # the package's bundle, no CDN


@pytest.mark.parametrize("scene, sets", [
    ("paper", {"spinner.rpm": 700, "vanes.pitch_deg": "10", "sim.granules": 512}),
    ("paper-deflectors", {"deflectors.0.angle_deg": 70.5, "sim.granules": 128, "sim.angle_copies": 4}),
])
def test_simulate_is_the_cli_json(client, scene, sets):
    response = client.post("/api/simulate", json={"scene": scene, "set": sets})
    assert response.status_code == 200, response.text
    served = response.json()
    printed = cli_json(scene, [f"{k}={v}" for k, v in sets.items()])
    served.pop("wall_s")
    printed.pop("wall_s")
    assert served == printed


def test_pattern_view_has_the_pictures_and_the_cli_digits(client):
    response = client.post("/api/pattern", json={"scene": "paper", "set": SMALL})
    assert response.status_code == 200, response.text
    data = response.json()
    m = data["metrics"]
    from spreadgym.report import with_error

    assert data["cv_text"] == with_error(m["cv_percent_at_target"], m["cv_standard_error_percent"], "%")
    plot = data["plot"]
    assert plot["plan"]["tracks"] and plot["plan"]["rays"] and len(plot["plan"]["vanes"]) == 4
    assert len(plot["trays"]["single_percent"]) == len(m["trays"]["center_m"])
    assert plot["trays"]["overlap_percent"] and plot["landing"][0]


def test_scene_controls(client):
    info = client.post("/api/scene", json={"scene": "paper-deflectors"}).json()
    keys = [c["key"] for c in info["controls"]]
    assert keys[:2] == ["spinner.rpm", "vanes.pitch_deg"]
    assert {"feed.radius_m", "feed.angle_deg", "deflectors.0.angle_deg", "deflectors.1.angle_deg",
            "pattern.target_swath_m"} <= set(keys)
    assert "pellet" in info["fertilizers"]


@pytest.mark.parametrize("body, named", [
    ({"scene": "nope"}, "scenes: unknown name 'nope'"),
    ({"scene": "../../etc/passwd.yaml"}, "scenes: unknown name"),  # a name, never a path
    ({"set": {"spinner.rpm": 1e6}}, "spinner.rpm"),
    ({"set": {"spinner.rpm": "fast"}}, "spinner.rpm"),
    ({"set": {"spinner.rpmm": 500}}, "spinner.rpmm: unknown key"),
    ({"set": {"vanes.pitch_deg": 90}}, "vanes.pitch_deg"),
    ({"set": {"pattern.target_swath_m": 0.5}}, "pattern.target_swath_m"),
    ({"set": {"pattern.target_swath_m": 3.2}}, "pattern.target_swath_m"),
    ({"set": {"fertilizer": "sand"}}, "unknown fertilizer 'sand'"),
    ({"set": {"sim.granules": 10**9}}, "sim.granules"),
    ({"set": {"spinner.rpm": "[1"}}, "spinner.rpm: value '[1' is not valid YAML"),
    ({"set": [1, 2]}, "set:"),
    ({"scene": 5}, "scene:"),
    ({"precision": 0}, "precision:"),
    ({"max_runs": 1}, "max_runs: 1 is out of range"),
    ({"model": "magic"}, "model: unknown model 'magic'"),
    ({"colour": "red"}, "colour: Extra inputs"),
    ({"yaml": "name: [unclosed"}, "uploaded scene: not valid YAML"),
    ({"yaml": "- a list"}, "uploaded scene: does not hold a mapping"),
    ({"yaml": "name: x\n"}, "missing (required)"),
    ({"yaml": "a: &a [1]\n" + "".join(f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, "
                                       f"*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}]\n"
                                       for i in range(10))}, "uploaded scene: YAML"),
])
def test_bad_input_is_422_naming_the_key(client, body, named):
    for path in ("/api/simulate", "/api/pattern"):
        response = client.post(path, json=body)
        assert response.status_code == 422, response.text
        error = response.json()["error"]
        assert named in error and "\n" not in error


def test_the_cli_says_the_same(client):
    sets = ["spinner.rpm=1000000", "spinner.rpmm=5", "pattern.target_swath_m=0.5"]
    for assignment in sets:
        key, value = assignment.split("=")
        done = subprocess.run([sys.executable, "-m", "spreadgym.cli.main", "simulate", "--set", assignment],
                              capture_output=True, text=True, timeout=120)
        served = client.post("/api/simulate", json={"set": {key: value}}).json()["error"]
        assert done.stderr.strip() == f"spreadgym simulate: error: {served}"


def test_oversized_bodies_are_refused(client):
    text = "name: x\n" + "#" * MAX_BODY_BYTES
    response = client.post("/api/scene", json={"yaml": text})
    assert response.status_code == 413 and "at most 1000000 bytes" in response.json()["error"]
    chunks = (b"x" * 100_000 for _ in range(20))  # no Content-Length: counted as it streams
    response = client.post("/api/simulate", content=chunks, headers={"content-type": "application/json"})
    assert response.status_code == 413
    broken = client.post("/api/simulate", content=b"{not json", headers={"content-type": "application/json"})
    assert broken.status_code == 422 and broken.json()["error"].startswith("body: not valid JSON")
    assert client.get("/api/health").json() == {"ok": True}


def test_the_fertilizers_offered_are_those_that_can_run(client):
    """A fertilizer whose surface pairs on the scene are not measured is not offered (the paper scene's disc
    material has no measured restitution for the mixture): the page lists what chart --fertilizers all takes."""
    from spreadgym.agents.chart.spec import resolve_fertilizers
    from spreadgym.config.materials import load_library
    from spreadgym.config.scene import load_scene

    offered = client.post("/api/scene", json={"scene": "paper"}).json()["fertilizers"]
    runnable, left_out = resolve_fertilizers("all", load_scene("paper"), load_library())
    assert offered == sorted(runnable) and left_out
    assert all(name.split(" ")[0] not in offered for name in left_out)
    for name in offered:  # each one offered does run
        answer = client.post("/api/simulate", json={"set": {**SMALL, "fertilizer": name}, "max_runs": 2})
        assert answer.status_code == 200, (name, answer.text)


def test_chart_folders_and_files(client):
    listed = client.get("/api/charts").json()["charts"]
    assert [c["name"] for c in listed] == ["paper"] and listed[0]["finished"]
    detail = client.get("/api/charts/paper").json()
    assert detail["rows"] and "Spreading chart" in detail["markdown"] and "chart.png" in detail["files"]
    picture = client.get("/files/charts/paper/chart.png")
    assert picture.status_code == 200 and picture.content.startswith(b"\x89PNG")


@pytest.mark.parametrize("path", [
    "/api/charts/%2e%2e", "/api/charts/%2e%2e/%2e%2e/etc", "/api/charts/paper%2f%2e%2e%2f%2e%2e",
    "/api/charts/.hidden", "/api/charts/outside/etc", "/api/charts/notes.txt", "/api/charts/missing",
    "/files/charts/%2e%2e/%2e%2e/etc/passwd", "/files/charts/outside/etc/passwd", "/files/charts/notes.txt",
    "/files/charts/paper/manifest.json%00.png", "/files/charts//etc/passwd", "/static/..%2fapp.py",
])
def test_no_path_leaves_the_charts_folder(client, path):
    response = client.get(path)
    assert response.status_code in (404, 422), (path, response.text)
    assert "error" in response.json() and "root:" not in response.text


def test_a_cancelled_chart_job_leaves_the_server_working(client, charts_dir):
    bad = client.post("/api/chart-jobs", json={"scene": "paper", "fertilizers": "pellet", "widths": "3.2",
                                               "out": "job"})
    assert bad.status_code == 422 and "3.2" in bad.json()["error"]
    bad = client.post("/api/chart-jobs", json={"scene": "paper", "fertilizers": "pellet", "widths": "3",
                                               "out": "../job"})
    assert bad.status_code == 422 and "--out" in bad.json()["error"]
    # enough cells (a second each on an idle machine) that the cancel lands while they run
    job = {"scene": "paper", "fertilizers": "pellet,compound-10-16-10", "widths": "3:6:0.5", "out": "job",
           "budget": 5, "granules": 128, "workers": 1}
    started = client.post("/api/chart-jobs", json=job)
    assert started.status_code == 200, started.text
    assert started.json()["state"] == "running" and started.json()["total"] == 14
    assert started.json()["elapsed_s"] >= 0.0 and started.json()["done"] == 0
    assert client.post("/api/chart-jobs", json=job).status_code == 422  # one at a time
    listed = {c["name"]: c for c in client.get("/api/charts").json()["charts"]}
    assert listed["job"]["running"]  # listed from its start
    deadline = time.monotonic() + 120
    while client.get("/api/chart-jobs").json()["left_s"] is None and time.monotonic() < deadline:
        time.sleep(0.2)  # the estimate: one timed run per model
    status = client.get("/api/chart-jobs").json()
    assert status["left_s"] > 0 and (status["estimate_s"] or 0) > 0
    deadline = time.monotonic() + 180
    while client.get("/api/chart-jobs").json()["done"] < 1 and time.monotonic() < deadline:
        time.sleep(0.5)  # cancelled while Ray runs its cells
    leader = client.app.state.jobs.process.pid
    cancelled = client.delete("/api/chart-jobs")
    assert cancelled.status_code == 200 and cancelled.json()["state"] == "cancelled"
    assert client.delete("/api/chart-jobs").status_code == 422  # nothing left to cancel
    with pytest.raises(ProcessLookupError):  # nothing of the job's process group is left (Ray's helpers)
        os.killpg(leader, 0)
    assert client.get("/api/health").json() == {"ok": True}
    assert client.post("/api/simulate", json={"set": SMALL}).status_code == 200
    assert not (charts_dir / "job" / "chart.json").exists()
    listed = {c["name"]: c for c in client.get("/api/charts").json()["charts"]}
    assert not listed["job"]["finished"] and listed["job"]["cells"] >= 1  # finished cells kept
    # the cancelled job's folder can be removed (only it: a finished chart stays)
    assert client.delete("/api/charts/paper").status_code == 422 and (charts_dir / "paper" / "chart.json").exists()
    (charts_dir / "job" / "mine.txt").write_text("a user's file")
    kept = client.delete("/api/charts/job")
    assert kept.status_code == 422 and "holds other files (mine.txt)" in kept.json()["error"]
    (charts_dir / "job" / "mine.txt").unlink()
    assert client.delete("/api/charts/job").json() == {"removed": "job"}
    assert not (charts_dir / "job").exists() and client.get("/api/chart-jobs").json()["state"] == "idle"


def test_serve_materials_offers_and_runs_the_users_fertilizer(copied_fertilizer, monkeypatch, tmp_path):
    """serve --materials FILE sets SPREADGYM_MATERIALS for the server and its workers: the page offers the
    file's fertilizers, and a simulation of one is what `simulate --materials FILE --json` prints."""
    from spreadgym.config.materials import MATERIALS_ENV

    path, name = copied_fertilizer
    monkeypatch.setenv(MATERIALS_ENV, str(path))
    sets = {"sim.granules": 256, "fertilizer": name}
    with TestClient(create_app(tmp_path), base_url=LOCAL) as mine:
        assert name in mine.post("/api/scene", json={"scene": "paper"}).json()["fertilizers"]
        response = mine.post("/api/simulate", json={"scene": "paper", "set": sets})
    assert response.status_code == 200, response.text
    served = response.json()
    monkeypatch.delenv(MATERIALS_ENV)
    argv = [sys.executable, "-m", "spreadgym.cli.main", "simulate", "--scene", "paper", "--json",
            "--materials", str(path)] + [f"--set={k}={v}" for k, v in sets.items()]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    printed = json.loads(done.stdout)
    served.pop("wall_s")
    printed.pop("wall_s")
    assert served["cv_percent_at_target"] is not None and served == printed


def test_the_pages_plan_view_of_a_twin_machine_is_its_first_disc():
    """The page's plan view (plot_data) draws a twin machine's first disc about that disc's axis, as
    simulate --plot does (tests/viz/test_plots.py): every path on the disc, every ray from its rim."""
    import numpy as np

    from spreadgym.agents.web.pattern import plot_data
    from spreadgym.config.scene import load_scene
    from spreadgym.spread.pipeline import run_scene

    scene = load_scene("twin-field", {"sim.granules": 256, "sim.angle_copies": 4})
    result = run_scene(scene, ci=False, tracks=10)
    radius = scene.spinner.radius_m

    class Precise:  # what the page's plot_data reads of simulate's pooled estimate
        def as_result(self):
            return result

    plan = plot_data(scene, Precise())["plan"]
    assert plan["tracks"] and all(np.hypot(*np.asarray(path)).max() <= radius * (1 + 1e-3) for path in plan["tracks"])
    assert all(np.hypot(path[0][0], path[1][0]) == pytest.approx(radius, rel=1e-2) for path in plan["rays"])


def test_the_running_jobs_folder_is_neither_removed_nor_missing_under_another_spelling(tmp_path):
    """While a job runs (its status as `ChartJobs.start` sets it; no Ray here), its folder
    is refused for removal however the path spells it, and answers (nothing yet) before its
    first file, as the list shows it from the start."""
    app = create_app(tmp_path)
    client = TestClient(app, base_url=LOCAL)  # no lifespan: no simulation worker needed
    app.state.jobs.status = {"state": "running", "out": "job", "done": 0, "total": 4, "message": "",
                             "started": time.time(), "estimate_s": None}
    listed = client.get("/api/charts").json()["charts"]
    assert [c["name"] for c in listed] == ["job"]
    early = client.get("/api/charts/job")
    assert early.status_code == 200 and early.json()["files"] == [] and not early.json()["finished"]
    assert client.get("/api/charts/other").status_code == 404
    (tmp_path / "job" / "cells").mkdir(parents=True)
    (tmp_path / "job" / "manifest.json").write_text("{}")
    for path in ("/api/charts/job", "/api/charts/job/"):
        refused = client.delete(path)
        assert refused.status_code == 422 and "its job is running" in refused.json()["error"], path
    assert (tmp_path / "job" / "manifest.json").exists()
