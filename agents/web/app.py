"""The web app of `spreadgym serve`: the pattern, chart and fit pages and their JSON API.

Every error is `{"error": "..."}`: bad input 422 with the CLI's one-line message, a
missing chart 404, a body over MAX_BODY_BYTES 413. The app serves its own files and
plotly.min.js from the plotly package, so the pages need no network.
"""

from __future__ import annotations

import threading
from contextlib import asynccontextmanager
from importlib import resources
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from starlette.exceptions import HTTPException

from spreadgym.agents.web import charts, fit, pattern
from spreadgym.errors import SpreadgymError

MAX_BODY_BYTES = 1_000_000  # a request body (an uploaded scene is about 1.5 kB)
STATIC = Path(str(resources.files("spreadgym.agents.web") / "static"))


def plotly_js() -> Path:
    """plotly.min.js as the plotly package ships it."""
    import plotly

    return Path(plotly.__file__).parent / "package_data" / "plotly.min.js"


class BodyLimit:
    """Refuse a request body over `limit` bytes (413), by its Content-Length or as it streams in
    (the body is read whole, at most `limit` bytes, before the app sees it)."""

    def __init__(self, app, limit: int = MAX_BODY_BYTES):
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        length = dict(scope["headers"]).get(b"content-length", b"0")
        if not length.isdigit() or int(length) > self.limit:
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

        async def replay():
            nonlocal whole
            message, whole = whole, None
            return message if message is not None else await receive()

        await self.app(scope, replay, send)

    async def _refuse(self, scope, receive, send):
        text = f"request body: larger than {self.limit} bytes (1 MB); allowed: at most {self.limit} bytes"
        await JSONResponse({"error": text}, status_code=413)(scope, receive, send)


def _one_line(exc: RequestValidationError) -> str:
    """The first problem of a request body, as 'key: message'."""
    first = exc.errors()[0]
    if first.get("type") == "json_invalid":
        return f"body: not valid JSON ({first.get('ctx', {}).get('error', 'decode error')} at character " \
               f"{first.get('loc', ('', '?'))[-1]})"
    where = ".".join(str(part) for part in first.get("loc", ()) if part != "body") or "body"
    return f"{where}: {first.get('msg', 'invalid')}"


def create_app(charts_dir: Path = Path("out/charts")) -> FastAPI:
    """The app, with chart folders under `charts_dir`."""
    jobs = charts.ChartJobs(Path(charts_dir))

    @asynccontextmanager
    async def lifespan(_app):
        warm = threading.Thread(target=pattern.warm_up, daemon=True)  # the first page answers at once
        warm.start()
        yield
        await run_in_threadpool(warm.join)
        await run_in_threadpool(jobs.shutdown)

    app = FastAPI(title="spreadgym", lifespan=lifespan, docs_url=None, redoc_url=None, openapi_url=None)
    app.add_middleware(BodyLimit)
    app.state.jobs = jobs

    @app.exception_handler(HTTPException)
    async def http_error(_request: Request, exc: HTTPException):
        return JSONResponse({"error": str(exc.detail)}, status_code=exc.status_code)

    @app.exception_handler(charts.NotFound)
    async def not_found(_request: Request, exc: charts.NotFound):
        return JSONResponse({"error": str(exc)}, status_code=404)

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
    def health():
        return {"ok": True}

    @app.get("/api/scenes")
    def scenes():
        from spreadgym.config.resources import available

        return {"scenes": available("scenes"), "precise": pattern.PRECISE}

    @app.post("/api/scene")
    def scene(request: pattern.SimulateRequest):
        return pattern.scene_info(pattern.scene_of(request))

    @app.post("/api/simulate")
    def simulate(request: pattern.SimulateRequest):
        _scene, precise = pattern.simulate(request)
        return Response(pattern.json_text(precise.to_json()), media_type="application/json")

    @app.post("/api/pattern")
    def pattern_view(request: pattern.SimulateRequest):
        return Response(pattern.pattern_payload(request), media_type="application/json")

    @app.post("/api/fit")
    def fit_view(request: fit.FitRequest):
        return Response(fit.fit_payload(request), media_type="application/json")

    @app.get("/api/charts")
    def chart_list():
        return {"charts": charts.chart_folders(jobs.root)}

    @app.get("/api/charts/{name:path}")
    def chart_detail(name: str):
        return charts.chart_detail(jobs.root, name)

    @app.get("/files/charts/{name:path}")
    def chart_file(name: str):
        path, media = charts.chart_file(jobs.root, name)
        return FileResponse(path, media_type=media)

    @app.post("/api/chart-jobs")
    def start_job(request: charts.ChartJobRequest):
        return jobs.start(request)

    @app.get("/api/chart-jobs")
    def job_status():
        with jobs.lock:
            return dict(jobs.status)

    @app.delete("/api/chart-jobs")
    def cancel_job():
        return jobs.cancel()

    @app.get("/static/plotly.min.js")
    def plotly():
        return FileResponse(plotly_js(), media_type="text/javascript")

    @app.get("/static/{name}")
    def static(name: str):
        path = STATIC / name
        if not charts.NAME.fullmatch(name) or not path.is_file():
            raise charts.NotFound(f"static file {name!r}: not there")
        return FileResponse(path)

    @app.get("/")
    def pattern_page():
        return FileResponse(STATIC / "pattern.html")

    @app.get("/charts")
    def chart_page():
        return FileResponse(STATIC / "charts.html")

    @app.get("/fit")
    def fit_page():
        return FileResponse(STATIC / "fit.html")

    return app
