"""The web app of `spreadgym serve`: the pattern, chart and fit pages and their JSON API.

Every error is `{"error": "..."}`: bad input 422 with the CLI's one-line message, a
missing chart 404, a body over MAX_BODY_BYTES 413, a request from elsewhere 403
(`agents.web.access`), a busy server or a request past its time limit 503. The app
serves its own files and plotly.min.js from the plotly package, so the pages need no
network.

Simulations and fits run in worker processes (`agents.web.workers`: one lane each, a
request whose client leaves stops its work); every route that does not simulate answers
from the event loop or its thread pool, never behind a simulation.
"""

from __future__ import annotations

import asyncio
import json
import math
from contextlib import asynccontextmanager
from importlib import resources
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from starlette.exceptions import HTTPException

from spreadgym.agents.web import charts, fit, pattern
from spreadgym.agents.web.access import Addresses, LocalOnly
from spreadgym.agents.web.workers import Busy, Lane, Left, TimeLimit
from spreadgym.errors import SpreadgymError

MAX_BODY_BYTES = 1_000_000  # a request body (an uploaded scene is about 1.5 kB)
MAX_JSON_DEPTH = 32  # a request's JSON nests 3 levels; deeper is not a request of this app
MAX_INT_DIGITS = 30  # far beyond any count or seed the app takes (seeds are < 2^32: 10 digits)
TIME_LIMIT_S = 300.0  # a request's wait and work together (serve --time-limit)
MAX_WAITING = 100  # simulations running or waiting; more are refused at once (503)
LOOPBACK = Addresses("127.0.0.1")
STATIC = Path(str(resources.files("spreadgym.agents.web") / "static"))


def plotly_js() -> Path:
    """plotly.min.js as the plotly package ships it."""
    import plotly

    return Path(plotly.__file__).parent / "package_data" / "plotly.min.js"


class BodyLimit:
    """Refuse a request body over `limit` bytes (413), by its Content-Length or as it streams in
    (the body is read whole, at most `limit` bytes, before the app sees it); a JSON body is
    read once here as the app will read it, and one the app's parser would turn into a
    bare error (nesting beyond MAX_JSON_DEPTH, an integer of more than MAX_INT_DIGITS
    digits, a number beyond the float range, NaN) is refused (422) naming its key."""

    def __init__(self, app, limit: int = MAX_BODY_BYTES):
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        length = dict(scope["headers"]).get(b"content-length", b"0")
        if not length.isdigit():
            return await JSONResponse({"error": f"Content-Length {length[:40].decode('latin-1')!r} is not a whole "
                                                "number of bytes"}, status_code=400)(scope, receive, send)
        if int(length) > self.limit:
            return await self._refuse(scope, receive, send)
        body, more = [], True
        while more:
            message = await receive()
            if message["type"] != "http.request":
                return
            body.append(message.get("body", b""))
            more = message.get("more_body", False)
            if sum(map(len, body)) > self.limit:
                return await self._refuse(scope, receive, send)
        whole = {"type": "http.request", "body": b"".join(body), "more_body": False}
        problem = json_problem(whole["body"]) if _is_json(scope) else None
        if problem:
            return await JSONResponse({"error": problem}, status_code=422)(scope, receive, send)

        async def replay():
            nonlocal whole
            message, whole = whole, None
            return message if message is not None else await receive()

        await self.app(scope, replay, send)

    async def _refuse(self, scope, receive, send):
        text = f"request body: larger than {self.limit} bytes (1 MB); allowed: at most {self.limit} bytes"
        await JSONResponse({"error": text}, status_code=413)(scope, receive, send)


def _is_json(scope) -> bool:
    media = dict(scope["headers"]).get(b"content-type", b"").split(b";")[0].strip().lower()
    return media == b"application/json"


class _Refused:
    """A JSON value the app's parser would not take, where it stood (`json_problem`)."""

    def __init__(self, why: str):
        self.why = why


def json_problem(body: bytes) -> str | None:
    """Why a JSON body would fail the app's parser without naming where, as 'key: why'; None
    when it parses (or fails plainly: the app says where, as for any bad JSON)."""
    def integer(text: str) -> Any:
        digits = len(text.lstrip("-"))
        return int(text) if digits <= MAX_INT_DIGITS else _Refused(
            f"an integer of {digits} digits; allowed: at most {MAX_INT_DIGITS}")

    def real(text: str) -> Any:
        value = float(text)
        return value if math.isfinite(value) else _Refused(f"{text[:30]} is beyond the range of a number")

    try:
        value = json.loads(body, parse_int=integer, parse_float=real,
                           parse_constant=lambda name: _Refused(f"{name} is not a number JSON allows"))
    except RecursionError:
        return f"body: nested deeper than {MAX_JSON_DEPTH} levels; allowed: at most {MAX_JSON_DEPTH}"
    except (ValueError, UnicodeDecodeError):
        return None
    return _first_refused(value, "body", 0)


def _first_refused(value: Any, where: str, depth: int) -> str | None:
    if isinstance(value, _Refused):
        return f"{where}: {value.why}"
    if depth > MAX_JSON_DEPTH and isinstance(value, (dict, list)):
        return f"{where}: nested deeper than {MAX_JSON_DEPTH} levels; allowed: at most {MAX_JSON_DEPTH}"
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        found = _first_refused(item, str(key) if where == "body" else f"{where}.{key}", depth + 1)
        if found:
            return found
    return None


def _one_line(exc: RequestValidationError) -> str:
    """The first problem of a request body, as 'key: message'."""
    first = exc.errors()[0]
    if first.get("type") == "json_invalid":
        return f"body: not valid JSON ({first.get('ctx', {}).get('error', 'decode error')} at character " \
               f"{first.get('loc', ('', '?'))[-1]})"
    where = ".".join(str(part) for part in first.get("loc", ()) if part != "body") or "body"
    return f"{where}: {first.get('msg', 'invalid')}"


def create_app(charts_dir: Path = Path("out/charts"), addresses: Addresses = LOOPBACK,
               time_limit_s: float = TIME_LIMIT_S) -> FastAPI:
    """The app, with chart folders under `charts_dir`, answering the names of `addresses`;
    a request's wait and work stopped after `time_limit_s`."""
    jobs = charts.ChartJobs(Path(charts_dir))
    lanes = {"simulate": Lane("simulate", time_limit_s, MAX_WAITING, warm="spreadgym.agents.web.pattern:warm_up"),
             "fit": Lane("fit", time_limit_s, 1)}  # one fit at a time: a second is refused, not queued

    @asynccontextmanager
    async def lifespan(_app):
        loop = asyncio.get_running_loop()
        app.state.stop_work = lambda: loop.call_soon_threadsafe(lambda: [lane.shutdown() for lane in lanes.values()])
        lanes["simulate"].start()  # its worker warms up now, so the first page answers at once
        try:
            yield
        finally:
            for lane in lanes.values():
                lane.shutdown()
            await run_in_threadpool(jobs.shutdown)

    app = FastAPI(title="spreadgym", lifespan=lifespan, docs_url=None, redoc_url=None, openapi_url=None)
    app.add_middleware(BodyLimit)
    app.add_middleware(LocalOnly, addresses=addresses)  # the outermost: nothing reads a request from elsewhere
    app.state.jobs = jobs
    app.state.lanes = lanes
    app.state.stop_work = lambda: None  # set when the app runs: the server's SIGTERM handler calls it

    async def work(lane: str, task: str, request, http: Request) -> Response:
        text = await lanes[lane].run(task, request.model_dump(), http.is_disconnected)
        return Response(text, media_type="application/json")

    @app.exception_handler(HTTPException)
    async def http_error(_request: Request, exc: HTTPException):
        return JSONResponse({"error": str(exc.detail)}, status_code=exc.status_code)

    @app.exception_handler(charts.NotFound)
    async def not_found(_request: Request, exc: charts.NotFound):
        return JSONResponse({"error": str(exc)}, status_code=404)

    @app.exception_handler(Busy)
    @app.exception_handler(TimeLimit)
    async def unavailable(_request: Request, exc: SpreadgymError):
        return JSONResponse({"error": str(exc)}, status_code=503)

    @app.exception_handler(Left)
    async def left(_request: Request, _exc: Left):  # nobody reads it: the client closed the connection
        return JSONResponse({"error": "the client left; its work was stopped"}, status_code=499)

    @app.exception_handler(SpreadgymError)
    async def bad_input(_request: Request, exc: SpreadgymError):
        return JSONResponse({"error": str(exc)}, status_code=422)

    @app.exception_handler(RequestValidationError)
    async def bad_request(_request: Request, exc: RequestValidationError):
        return JSONResponse({"error": _one_line(exc)}, status_code=422)

    @app.exception_handler(Exception)
    async def failed(_request: Request, exc: Exception):  # a bug's one line; the server carries on
        return JSONResponse({"error": f"internal error: {type(exc).__name__}: {exc}"}, status_code=500)

    @app.get("/api/health")
    async def health():
        return {"ok": True}

    @app.get("/api/scenes")
    def scenes():
        from spreadgym import __version__
        from spreadgym.config.resources import available

        return {"scenes": available("scenes"), "precise": pattern.PRECISE, "version": __version__}

    @app.post("/api/scene")
    def scene(request: pattern.SimulateRequest):
        return pattern.scene_info(pattern.scene_of(request))

    @app.post("/api/simulate")
    async def simulate(request: pattern.SimulateRequest, http: Request):
        await run_in_threadpool(pattern.check_request, request)  # a bad input is answered at once, not in turn
        return await work("simulate", "spreadgym.agents.web.pattern:simulate_task", request, http)

    @app.post("/api/pattern")
    async def pattern_view(request: pattern.SimulateRequest, http: Request):
        await run_in_threadpool(pattern.check_request, request)
        return await work("simulate", "spreadgym.agents.web.pattern:pattern_task", request, http)

    @app.post("/api/fit")
    async def fit_view(request: fit.FitRequest, http: Request):
        await run_in_threadpool(fit.fit_inputs, request)
        return await work("fit", "spreadgym.agents.web.fit:fit_task", request, http)

    @app.post("/api/advise")
    async def advise_view(request: fit.AdviseRequest, http: Request):
        await run_in_threadpool(fit.advise_inputs, request)  # a bad input is answered at once, not in turn
        return await work("fit", "spreadgym.agents.web.fit:advise_task", request, http)

    @app.get("/api/charts")
    def chart_list():
        listed = charts.chart_folders(jobs.root)
        status = jobs.report()
        if status["state"] == "running":  # the running job's folder, listed from its start (before its manifest)
            mine = next((c for c in listed if c["name"] == status["out"]), None)
            if mine is None:
                listed.insert(0, mine := {"name": status["out"], "finished": False, "cells": 0})
            mine["running"] = True
        return {"charts": listed}

    @app.delete("/api/charts/{name:path}")
    def chart_remove(name: str):
        return jobs.remove(name)

    @app.get("/api/charts/{name:path}")
    def chart_detail(name: str):
        try:
            return charts.chart_detail(jobs.root, name)
        except charts.NotFound:
            if not jobs.is_running_folder(name):
                raise
            return charts.waiting_detail(name)  # listed from its start (chart_list), before its first file

    @app.get("/files/charts/{name:path}")
    def chart_file(name: str):
        path, media = charts.chart_file(jobs.root, name)
        return FileResponse(path, media_type=media)

    @app.post("/api/chart-jobs")
    def start_job(request: charts.ChartJobRequest):
        return jobs.start(request)

    @app.get("/api/chart-jobs")
    def job_status():
        return jobs.report()

    @app.delete("/api/chart-jobs")
    def cancel_job():
        return jobs.cancel()

    @app.get("/static/plotly.min.js")
    async def plotly():
        return FileResponse(plotly_js(), media_type="text/javascript")

    @app.get("/static/{name}")
    async def static(name: str):
        path = STATIC / name
        if not charts.NAME.fullmatch(name) or not path.is_file():
            raise charts.NotFound(f"static file {name!r}: not there")
        return FileResponse(path)

    @app.get("/")
    async def pattern_page():
        return FileResponse(STATIC / "pattern.html")

    @app.get("/charts")
    async def chart_page():
        return FileResponse(STATIC / "charts.html")

    @app.get("/fit")
    async def fit_page():
        return FileResponse(STATIC / "fit.html")

    return app
