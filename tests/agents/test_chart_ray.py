"""spreadgym chart on Ray: a 2 x 2 chart end to end on an embedded 2-CPU Ray, and the same
chart, row for row, in this process and on a three-node cluster (one machine)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import ray

from spreadgym.agents.chart import make_spec, run_chart
from spreadgym.agents.chart.search import run_cell

SMALL = dict(budget=6, granules=64, search_model="analytic", verify_runs=2, variability={"draws": 4, "verify_draws": 4})


def without_wall(rows):
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


def test_cli_end_to_end_on_an_embedded_two_cpu_ray(tmp_path):
    """With RAY_ADDRESS naming a cluster that is not there, the chart still starts its own
    private Ray: it joins nothing it was not asked to."""
    out = tmp_path / "chart"
    argv = [sys.executable, "-m", "spreadgym.cli.main", "chart", "--scene", "paper", "--fertilizers",
            "compound-10-16-10,pellet", "--widths", "3,4", "--budget", "1", "--granules", "64", "--workers", "2",
            "--objective", "nominal", "--out", str(out), "--json"]
    env = {**os.environ, "RAY_ADDRESS": "127.0.0.1:1"}
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    payload = json.loads(proc.stdout)
    assert [(r["fertilizer"], r["width_m"]) for r in payload["rows"]] == [
        ("compound-10-16-10", 3.0), ("compound-10-16-10", 4.0), ("pellet", 3.0), ("pellet", 4.0)]
    assert all(c["verification"]["model"] == "pymunk" for c in payload["cells"])
    # two levels never multiply: each of the 2 Ray workers' batches ran on its task's CPU alone
    assert all(c["verification"]["threads"] == 1 for c in payload["cells"])
    assert all(r["cv_percent"] is not None for r in payload["rows"])
    assert {p.name for p in out.iterdir()} >= {"chart.csv", "chart.json", "chart.md", "chart.png", "chart.html",
                                               "manifest.json"}
    assert json.loads((out / "chart.json").read_text(encoding="utf-8")) == payload
    # The same seed gives the same cell in this process, one cell at a time, as on two Ray workers
    # (the 4 m cell starts from the 3 m cell's settings).
    spec = make_spec("paper", "compound-10-16-10,pellet", "3,4", budget=1, granules=64, objective="nominal")[0]
    again = run_cell(spec, spec.cells[3], {"detail": payload["cells"][2]})["row"]
    assert without_wall([again]) == without_wall(payload["rows"][3:])


@pytest.mark.slow  # three Ray nodes take about 15 s to start
def test_same_chart_in_process_and_on_a_three_node_cluster(tmp_path):
    from ray.cluster_utils import Cluster

    spec = make_spec("paper", "compound-10-16-10,pellet", "3,4", **SMALL)[0]
    local = run_chart(spec, tmp_path / "local", engine="local", progress=False)
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    session = Path(cluster.head_node.get_session_dir_path())  # in Ray's temp folder: removed after, not left behind
    try:
        for _ in range(2):
            cluster.add_node(num_cpus=1)
        remote = run_chart(spec, tmp_path / "cluster", address=cluster.address, progress=False)  # joins it
        assert not ray.is_initialized()  # left as found: the chart disconnected
    finally:
        ray.shutdown()
        cluster.shutdown()
        shutil.rmtree(session, ignore_errors=True)
    assert without_wall(remote.payload["rows"]) == without_wall(local.payload["rows"])


def test_the_embedded_ray_listens_on_loopback_only_and_keeps_its_session_in_a_user_cache(
        tmp_path, monkeypatch, listening_sockets):
    """While a small chart runs on the embedded Ray, every listening socket of this process
    and its descendants (GCS, raylet, workers, agents) is on 127.0.0.1; the session folder
    lies under the per-user cache, and is gone when the chart ends."""
    import shutil
    import tempfile

    from spreadgym.agents.chart import chart
    from spreadgym.agents.chart.runner import session_root

    cache = Path(tempfile.mkdtemp(prefix="c"))  # a short path: Ray's sockets live in the session folder
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    seen = []

    def snapshot(_cell, _record):
        seen.append(listening_sockets(os.getpid()))
        seen.append(sorted(p.name for p in session_root().iterdir()))

    chart("paper", "pellet", "3,4", tmp_path / "chart", budget=1, granules=64, objective="nominal", workers=1,
          progress=False, on_cell=snapshot, search_model="analytic", verify_runs=2)
    sockets = [row for rows in seen[0::2] for row in rows]
    assert {name for _, _, name, _ in sockets} >= {"gcs_server", "raylet"}, sockets
    assert all(loopback for *_, loopback in sockets), [row for row in sockets if not row[3]]
    assert any(name.startswith("session_2") for name in seen[1]) and session_root() == cache / "spreadgym" / "ray"
    assert (cache / "spreadgym").stat().st_mode & 0o777 == 0o700  # Ray opens its own folder to all: not this one
    assert not [p for p in session_root().iterdir() if p.name.startswith("session_2")]  # removed at the end
    assert not ray.is_initialized() and os.environ.get("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER") is None
    shutil.rmtree(cache)


def test_the_session_folders_lie_in_a_folder_no_other_user_can_enter(tmp_path, monkeypatch):
    """Ray makes the folder it is given writable by all: its parent is this user's own, mode
    700, set again where an older version left it open; a link in the shared temp folder is refused."""
    import tempfile

    from spreadgym.agents.chart.runner import session_root
    from spreadgym.errors import SpreadgymError

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / ("long" * 20)))  # too long for Ray's sockets: the fallback
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "shared"))
    private = tmp_path / "shared" / f"spreadgym-ray-{os.getuid()}"
    private.mkdir(parents=True, mode=0o777)
    private.chmod(0o777)
    assert session_root() == private / "ray"
    assert private.stat().st_mode & 0o777 == 0o700
    private.rename(tmp_path / "elsewhere")
    private.symlink_to(tmp_path / "elsewhere")
    with pytest.raises(SpreadgymError, match="not this user's own"):
        session_root()
