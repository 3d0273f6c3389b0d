"""Who may talk to the app (agents.web.access): a Host the server was not started on and a
foreign Origin are refused (403, one line) before any work starts; chart folders are read
through one confinement check, links included; JSON the parser would fail without naming
a key is refused naming it."""

import json

import pytest
from fastapi.testclient import TestClient

from spreadgym.agents.web.access import Addresses, LocalOnly, host_name
from spreadgym.agents.web.app import MAX_INT_DIGITS, MAX_JSON_DEPTH, create_app, json_problem

LOCAL = "http://127.0.0.1:8050"
JOB = {"scene": "paper", "fertilizers": "pellet", "widths": "3", "out": "job", "budget": 1, "granules": 64}
NESTED = 1
for _ in range(40):
    NESTED = [NESTED]
FIT = {"scene": "paper", "trays": "x_m,mass_g\n0,1\n", "fit": ["contact.vane_restitution=0.3:0.7"]}


@pytest.fixture(scope="module")
def charts_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("charts")
    secret = tmp_path_factory.mktemp("outside") / "secret.md"
    secret.write_text("# not for the page")
    linked = root / "linked"  # a chart whose chart.md and chart.json are links out of the folder
    (linked / "cells").mkdir(parents=True)
    (linked / "manifest.json").write_text("{}")
    (linked / "chart.md").symlink_to(secret)
    (linked / "chart.json").symlink_to(secret.parent / "secret.json")
    (secret.parent / "secret.json").write_text(json.dumps({"rows": [{"secret": 1}]}))
    (linked / "chart.png").symlink_to(secret)
    (linked / "cells" / "a.png").symlink_to(secret)
    (linked / "cells" / "b.json").symlink_to(secret.parent / "secret.json")
    only_link = root / "only-link"  # its only chart file is a link out: not a chart folder here
    only_link.mkdir()
    (only_link / "chart.json").symlink_to(secret.parent / "secret.json")
    (root / "loop").symlink_to(root / "loop")
    return root


@pytest.fixture(scope="module")
def client(charts_dir):
    with TestClient(create_app(charts_dir), base_url=LOCAL) as test_client:
        yield test_client


@pytest.mark.parametrize("host", ["evil.example", "evil.example:8050", "127.0.0.1.evil.example:8050",
                                  "localhost.evil.example", "10.0.0.5:8050", "", "a b", "[::1", "127.0.0.1:x"])
def test_a_foreign_host_is_refused_before_anything_runs(client, host):
    for method, path, body in (("GET", "/api/health", None), ("POST", "/api/chart-jobs", JOB),
                               ("POST", "/api/fit", FIT), ("POST", "/api/simulate", {}), ("DELETE", "/api/chart-jobs",
                                                                                      None), ("GET", "/", None)):
        response = client.request(method, path, json=body, headers={"host": host})
        assert response.status_code == 403, (method, path, response.text)
        error = response.json()["error"]
        assert "is not an address this server was started on" in error and "\n" not in error
    assert client.app.state.jobs.status["state"] == "idle"  # no chart job started


@pytest.mark.parametrize("origin", ["http://evil.example", "http://127.0.0.1:9999", "null", "https://127.0.0.1:8050",
                                    "http://localhost:8050"])
def test_a_foreign_origin_is_refused_on_every_endpoint_that_starts_work(client, origin):
    for method, path, body in (("POST", "/api/chart-jobs", JOB), ("POST", "/api/fit", FIT),
                               ("POST", "/api/simulate", {}), ("POST", "/api/pattern", {}),
                               ("DELETE", "/api/chart-jobs", None)):
        response = client.request(method, path, json=body, headers={"origin": origin})
        assert response.status_code == 403 and "is another site" in response.json()["error"], response.text
    assert client.app.state.jobs.status["state"] == "idle"


def test_the_pages_own_requests_pass_and_cross_site_ones_do_not(client):
    own = {"origin": LOCAL, "sec-fetch-site": "same-origin"}
    assert client.post("/api/scene", json={"scene": "paper"}, headers=own).status_code == 200
    assert client.get("/api/health", headers={"host": "localhost:8050"}).status_code == 200
    assert client.get("/api/health", headers={"host": "[::1]:8050"}).status_code == 200
    for headers in ({"sec-fetch-site": "cross-site"}, {"sec-fetch-site": "same-site"}):
        response = client.post("/api/scene", json={"scene": "paper"}, headers=headers)
        assert response.status_code == 403 and "may not change anything" in response.json()["error"]
    form = client.post("/api/scene", content=b"scene=paper", headers={"content-type": "text/plain"})
    assert form.status_code == 403 and "a request body here is JSON" in form.json()["error"]


def test_addresses_on_every_interface_take_address_literals_and_this_machines_names():
    import socket

    everywhere = Addresses("0.0.0.0")
    for name in ("192.168.1.5", "::1", "localhost", socket.gethostname()):
        assert everywhere.allows(name), name
    assert not everywhere.allows("evil.example")
    one = Addresses("192.168.1.5")
    assert one.allows("192.168.1.5") and not one.allows("localhost") and not one.allows("192.168.1.6")
    assert [host_name(h) for h in ("a:1", "[::1]:80", "[::1]", "a:", "a:b", "[::1]x")] == [
        "a", "::1", "::1", "a", None, None]


def test_the_middleware_refuses_without_reading_the_body():
    import asyncio

    sent = []

    async def app(scope, receive, send):
        raise AssertionError("the app saw a refused request")

    async def receive():
        raise AssertionError("the body was read")

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "method": "POST", "path": "/api/fit", "headers": [(b"host", b"evil.example")]}
    asyncio.run(LocalOnly(app, Addresses())(scope, receive, send))
    assert sent[0]["status"] == 403


def test_chart_files_are_read_through_one_confinement_check(client):
    """Links out of the charts folder are neither read nor listed: the listing shows only
    what the file route serves."""
    listed = {c["name"] for c in client.get("/api/charts").json()["charts"]}
    assert "linked" in listed and "only-link" not in listed and "loop" not in listed
    detail = client.get("/api/charts/linked").json()
    assert detail["markdown"] is None and detail["rows"] == [] and not detail["finished"]
    assert detail["files"] == ["manifest.json"] and detail["cell_pictures"] == []  # chart.png, cells/a.png: links out
    for path in ("/files/charts/linked/chart.md", "/files/charts/linked/chart.png", "/files/charts/linked/cells/a.png",
                 "/api/charts/only-link", "/api/charts/loop"):
        response = client.get(path)
        assert response.status_code in (404, 422) and "not for the page" not in response.text, path
    assert "secret" not in json.dumps(client.get("/api/charts").json())


@pytest.mark.parametrize("body, named", [
    ('{"set": {"spinner.rpm": 1%s}}' % ("0" * 40), f"set.spinner.rpm: an integer of 41 digits; allowed: at most "
                                                  f"{MAX_INT_DIGITS}"),
    ('{"max_runs": -1%s}' % ("0" * 5000), "max_runs: an integer of 5001 digits"),
    ('{"precision": 1e400}', "precision: 1e400 is beyond the range of a number"),
    ('{"set": {"spinner.rpm": NaN}}', "set.spinner.rpm: NaN is not a number JSON allows"),
    ({"set": {"deflectors": NESTED}}, "set.deflectors." + ".".join(["0"] * (MAX_JSON_DEPTH - 1))
     + f": nested deeper than {MAX_JSON_DEPTH}"),
])
def test_json_the_parser_would_refuse_blindly_is_refused_naming_the_key(client, body, named):
    for path in ("/api/simulate", "/api/fit", "/api/scene"):
        text = body if isinstance(body, str) else json.dumps(body)
        response = client.post(path, content=text, headers={"content-type": "application/json"})
        assert response.status_code == 422 and response.json()["error"].startswith(named), response.text
    deep = b'{"set": ' + b"[" * 100_000 + b"]" * 100_000 + b"}"
    assert json_problem(deep).startswith("body: nested deeper than")


def test_a_malformed_content_length_is_one_json_line():
    import asyncio

    from spreadgym.agents.web.app import BodyLimit

    sent = []

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "method": "POST", "path": "/api/simulate", "headers": [(b"content-length", b"12x")]}
    asyncio.run(BodyLimit(None)(scope, None, send))
    assert sent[0]["status"] == 400 and json.loads(sent[1]["body"]) == {
        "error": "Content-Length '12x' is not a whole number of bytes"}


def test_the_upload_limits_the_docs_state_are_the_loaders():
    from pathlib import Path

    from spreadgym.config.resources import MAX_YAML_DEPTH, MAX_YAML_NODES

    doc = (Path(__file__).resolve().parents[2] / "docs" / "web.md").read_text(encoding="utf-8")
    assert f"(1 MB, {MAX_YAML_DEPTH} levels, {MAX_YAML_NODES:_} values".replace("_", " ") in doc

