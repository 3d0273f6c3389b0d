"""The web app as hostile input (issue 44): any Host, Origin and fetch headers, any JSON
body, a burst of mixed requests, any tree of links in the charts folder. Every answer is
one JSON line with a 2xx/4xx status (never a 500), nothing is served from outside the
charts folder, and only the server's own names and origin get in; each family within its
own time cap."""

import json
import os
import threading
from pathlib import Path

import pytest
from conftest import time_limit
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from spreadgym.agents.web.access import Addresses, LocalOnly, host_name
from spreadgym.agents.web.app import create_app

LOCAL = "http://127.0.0.1:8050"
NAMES = st.sampled_from(["127.0.0.1", "localhost", "[::1]", "evil.example", "127.0.0.1.evil.example", "10.1.2.3",
                         "LOCALHOST", "", "127.1", "0.0.0.0", "[::ffff:127.0.0.1]"])
HOSTS = st.one_of(st.builds(lambda n, p: n + p, NAMES, st.sampled_from(["", ":8050", ":1", ":x", ":"])),
                  st.text(max_size=40))
ORIGINS = st.one_of(st.none(), st.builds(lambda s, h: s + h, st.sampled_from(["http://", "https://", ""]), HOSTS),
                    st.just("null"))


def _scope(method: str, host, origin, site, media) -> dict:
    headers = [(b"host", host.encode("utf-8", "replace"))] if host is not None else []
    headers += [(name, value.encode("utf-8", "replace")) for name, value in
                ((b"origin", origin), (b"sec-fetch-site", site), (b"content-type", media)) if value is not None]
    return {"type": "http", "method": method, "path": "/api/fit", "headers": headers}


@given(method=st.sampled_from(["GET", "POST", "DELETE", "PUT", "HEAD"]), host=st.one_of(st.none(), HOSTS),
       origin=ORIGINS, site=st.one_of(st.none(), st.sampled_from(["same-origin", "same-site", "cross-site", "none",
                                                                   "x"])),
       media=st.one_of(st.none(), st.sampled_from(["application/json", "text/plain", "application/json; charset=x",
                                                   "multipart/form-data"])),
       bind=st.sampled_from(["127.0.0.1", "0.0.0.0", "192.168.1.5"]))
def test_only_the_servers_names_and_own_origin_get_in(method, host, origin, site, media, bind):
    with time_limit(5):
        guard = LocalOnly(None, Addresses(bind))
        problem = guard.problem(_scope(method, host, origin, site, media))
    assert problem is None or ("\n" not in problem and len(problem) < 400)
    name = host_name(host or "")
    if name is None or not guard.addresses.allows(name):
        assert problem and "is not an address this server was started on" in problem
    if problem is None:
        assert origin is None or origin.lower() == f"http://{host}".lower()
        assert name.lower().strip("[]") in guard.addresses.names() or bind == "0.0.0.0"
        if method not in ("GET", "HEAD"):
            assert site in (None, "same-origin", "none")


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(tmp_path_factory.mktemp("charts")), base_url=LOCAL) as test_client:
        yield test_client


SCALARS = st.none() | st.booleans() | st.integers(-10**40, 10**40) | st.floats() | st.text(max_size=20)
JSON_VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(st.text(max_size=12), inner, max_size=4), max_leaves=30)
BODIES = st.one_of(st.dictionaries(st.sampled_from(["scene", "set", "yaml", "model", "precision", "max_runs", "x"]),
                                   JSON_VALUES, max_size=4).map(lambda d: json.dumps(d, allow_nan=True)),
                   st.text(max_size=200), st.builds(lambda n: "[" * n + "]" * n, st.integers(0, 50_000)))


@settings(max_examples=40, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(body=BODIES, path=st.sampled_from(["/api/scene", "/api/simulate", "/api/fit", "/api/chart-jobs"]))
def test_any_json_body_is_an_answer_or_one_line(client, body, path):
    if path != "/api/scene":
        body = json.dumps({"scene": "../x"}) if body.startswith("{") and '"scene"' not in body else body
    with time_limit(20):
        response = client.post(path, content=body.encode("utf-8", "replace"),
                               headers={"content-type": "application/json"})
    assert response.status_code in (200, 403, 413, 422), (response.status_code, response.text[:300])
    if response.status_code != 200:
        error = response.json()["error"]
        assert "\n" not in error and len(error) < 2000
    assert client.app.state.jobs.status["state"] in ("idle", "failed", "finished", "cancelled", "running")


def test_a_burst_of_mixed_requests_is_answered_and_health_stays(client):
    """80 requests at once from 8 threads (bad bodies, foreign hosts, pages, health): each a
    JSON answer or a page, none a 500; the app answers health after."""
    requests = [("GET", "/api/health", None, {}), ("GET", "/", None, {}), ("GET", "/api/charts", None, {}),
                ("POST", "/api/scene", "{", {}), ("POST", "/api/simulate", '{"max_runs": 1}', {}),
                ("POST", "/api/fit", "{}", {"host": "evil.example"}), ("DELETE", "/api/chart-jobs", None, {}),
                ("POST", "/api/chart-jobs", "{}", {"origin": "http://evil.example"}),
                ("POST", "/api/scene", json.dumps({"scene": "paper"}), {}), ("GET", "/api/charts/..%2f", None, {})]
    statuses, problems = [], []

    def worker(k: int) -> None:
        for i in range(10):
            method, path, body, headers = requests[(k + i) % len(requests)]
            response = client.request(method, path, content=body, headers={"content-type": "application/json",
                                                                            **headers})
            statuses.append(response.status_code)
            if response.status_code >= 500 or (path.startswith("/api") and "json" not in
                                               response.headers.get("content-type", "")):
                problems.append((path, response.status_code, response.text[:200]))

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(8)]
    with time_limit(60):
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert not problems and len(statuses) == 80, problems
    assert client.get("/api/health").json() == {"ok": True}


LINK_TARGETS = st.sampled_from(["outside/secret.md", "outside", "/", "chart.json", "..", "../..", "missing",
                                "cells", "self", "a/chart.md"])


@settings(max_examples=25, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(links=st.lists(st.tuples(st.sampled_from(["a/chart.md", "a/chart.json", "a/chart.png", "a/cells/k.png",
                                                  "a/cells/k.json", "b", "a/manifest.json", "c/chart.json", "a/x.csv",
                                                  "a/b", "loop"]), LINK_TARGETS), max_size=6, unique_by=lambda t: t[0]))
def test_no_link_in_the_charts_folder_reaches_outside_it(tmp_path_factory, links):
    base = tmp_path_factory.mktemp("tree")
    outside = base / "outside"
    outside.mkdir()
    (outside / "secret.md").write_text("SECRET")
    (outside / "chart.json").write_text(json.dumps({"rows": [{"SECRET": 1}]}))
    root = base / "charts"
    (root / "a" / "cells").mkdir(parents=True)
    (root / "a" / "manifest.json").write_text("{}")
    for name, target in links:
        path = root / name
        if path.exists() or path.is_symlink():
            path.unlink() if not path.is_dir() or path.is_symlink() else None
        if path.exists():
            continue
        path.parent.mkdir(parents=True, exist_ok=True)
        path.symlink_to(path if target == "self" else base / target if target.startswith("outside") else Path(target))
    with TestClient(create_app(root), base_url=LOCAL) as local, time_limit(30):
        listed = local.get("/api/charts")
        assert listed.status_code == 200 and "SECRET" not in listed.text
        for chart in listed.json()["charts"]:
            detail = local.get(f"/api/charts/{chart['name']}")
            assert detail.status_code in (200, 404, 422) and "SECRET" not in detail.text, detail.text
            if detail.status_code != 200:
                continue
            shown = detail.json()
            for name in shown["files"] + shown["cell_pictures"]:
                served = local.get(f"/files/charts/{chart['name']}/{name}")
                assert served.status_code == 200 and b"SECRET" not in served.content, (name, served.text[:200])
        for name, _ in links:
            served = local.get(f"/files/charts/{name}")
            assert b"SECRET" not in served.content and served.status_code in (200, 404, 422)
    assert os.path.exists(outside / "secret.md")
