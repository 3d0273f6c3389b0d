"""The chart page's work: chart folders under the server's charts folder (nothing outside
it is reachable), and one chart job at a time, run as `spreadgym chart` runs it.

A job runs in its own process (spawned, not forked) on the embedded private Ray; its
finished cells are reported as they arrive. Cancelling interrupts it as Ctrl-C would (the
running Ray tasks cancelled, finished cells kept), so the server goes on as before.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import re
import signal
import threading
import time
from pathlib import Path
from typing import Optional, Union

from pydantic import BaseModel, ConfigDict, Field

from spreadgym.config.base import brief
from spreadgym.errors import SpreadgymError

NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]{0,99}")  # one folder name: no '..', no hidden names
MAX_DEPTH = 3  # chart folders are looked for this deep under the charts folder
MAX_LISTED = 500
FILE_TYPES = {".png": "image/png", ".csv": "text/csv", ".json": "application/json", ".md": "text/markdown",
              ".html": "text/html"}
MAX_READ_BYTES = 5_000_000  # chart.json / chart.md read for the page
CANCEL_WAIT_S = 30.0  # after Ctrl-C, before the job's process is terminated
SHUTDOWN_WAIT_S = 3.0  # the same when the server stops: it stops within a few seconds (finished cells are on disk)


class NotFound(SpreadgymError):
    """A chart folder or file that is not there (HTTP 404)."""


def relative(text: str) -> tuple[str, ...]:
    """The parts of a path under the charts folder: folder names joined by '/', nothing else."""
    parts = tuple(text.strip("/").split("/")) if text.strip("/") else ()
    if len(parts) > MAX_DEPTH + 2 or not all(NAME.fullmatch(p) for p in parts):
        raise SpreadgymError(f"chart: {brief(text)} is not a path under the charts folder (folder names of letters, "
                             f"digits and . _ - joined by /, at most {MAX_DEPTH + 2} deep)")
    return parts


def confined(root: Path, path: Path) -> Optional[Path]:
    """`path` with every link followed, where that lies inside `root`; else None. Every
    file the chart page reads or lists under the charts folder goes through this one check."""
    try:
        resolved = Path(path).resolve()
        return resolved if resolved.is_relative_to(Path(root).resolve()) else None
    except (OSError, RuntimeError):  # a link loop
        return None


def inside(root: Path, text: str) -> Path:
    """`root/text`, refused unless it resolves inside `root` (links included)."""
    path = confined(root, root.joinpath(*relative(text)))
    if path is None:
        raise NotFound(f"chart: {brief(text)} is not under the charts folder")
    return path


def _file(root: Path, path: Path) -> Optional[Path]:
    """`path`, resolved, where it is a file inside `root` (else None)."""
    found = confined(root, path)
    return found if found is not None and found.is_file() else None


def is_chart(root: Path, folder: Path) -> bool:
    return any(_file(root, folder / name) for name in ("chart.json", "manifest.json"))


def chart_folders(root: Path) -> list[dict]:
    """Chart folders under `root` (at most MAX_DEPTH deep, MAX_LISTED of them), each with
    whether its chart files are written and how many cells are finished."""
    found: list[dict] = []
    if not root.is_dir():
        return found
    base = root.resolve()
    for current, dirs, _files in os.walk(base):
        here = Path(current)
        depth = len(here.relative_to(base).parts)
        dirs[:] = sorted(d for d in dirs if NAME.fullmatch(d) and d != "cells") if depth < MAX_DEPTH else []
        if here != base and is_chart(base, here):
            cells = here / "cells"
            found.append({"name": here.relative_to(base).as_posix(),
                          "finished": _file(base, here / "chart.json") is not None,
                          "cells": len(_listed(base, cells, ".json")) if cells.is_dir() else 0})
            if len(found) >= MAX_LISTED:
                break
    return found


def _listed(root: Path, folder: Path, *suffixes: str) -> list[str]:
    """Names of the files in `folder` of the given suffixes that the file route serves: a
    listing never shows a file a request for it would refuse (a link out of the charts folder)."""
    return sorted(p.name for p in folder.iterdir() if p.suffix in suffixes and NAME.fullmatch(p.name)
                  and _file(root, p) is not None)


def _read(root: Path, path: Path) -> Optional[str]:
    found = _file(root, path)
    if found is None:
        return None
    with open(found, "rb") as handle:
        data = handle.read(MAX_READ_BYTES + 1)
    if len(data) > MAX_READ_BYTES:
        raise SpreadgymError(f"{path.name}: larger than {MAX_READ_BYTES} bytes; allowed: at most {MAX_READ_BYTES}")
    return data.decode("utf-8", errors="replace")


def chart_detail(root: Path, name: str) -> dict:
    """A chart folder for the page: its printable table (chart.md), rows (chart.json) and pictures."""
    folder = inside(root, name)
    if not folder.is_dir() or not is_chart(root, folder):
        raise NotFound(f"chart: no chart folder {brief(name)} under the charts folder")
    text = _read(root, folder / "chart.json")
    try:
        payload = json.loads(text) if text is not None else None
    except json.JSONDecodeError as exc:
        raise SpreadgymError(f"chart.json of {brief(name)}: not valid JSON (line {exc.lineno})") from None
    rows = payload.get("rows") if isinstance(payload, dict) else None
    cells = folder / "cells"
    pictures = [f"cells/{p}" for p in _listed(root, cells, ".png")] if cells.is_dir() else []
    return {"name": name, "finished": text is not None, "markdown": _read(root, folder / "chart.md"),
            "rows": rows if isinstance(rows, list) else [], "files": _listed(root, folder, *FILE_TYPES),
            "cell_pictures": pictures}


def chart_file(root: Path, name: str) -> tuple[Path, str]:
    """(path, media type) of a chart's file: a known type, inside the charts folder."""
    path = inside(root, name)
    media = FILE_TYPES.get(path.suffix)
    if media is None or not path.is_file():
        raise NotFound(f"chart file {brief(name)}: not a chart file under the charts folder")
    return path, media


class ChartJobRequest(BaseModel):
    """`POST /api/chart-jobs`: the flags of `spreadgym chart` (on the embedded Ray; --out a folder name)."""

    model_config = ConfigDict(extra="forbid")
    scene: str = Field(max_length=200, description="shipped scene name")
    fertilizers: Union[str, list[str]] = Field(description="names, comma separated or a list, or all")
    widths: str = Field(max_length=2000, description="W1,W2,... or LO:HI:STEP (metres)")
    out: str = Field(max_length=100, description="chart folder name under the charts folder")
    driving: Optional[str] = None
    budget: int = 200
    granules: Optional[int] = None
    seed: int = 0
    workers: Optional[int] = None


def _job(options: dict, out: str, events) -> None:
    """The job's process: `spreadgym chart` with progress reported on `events`, in a process
    group of its own (so whatever Ray leaves behind is stopped with it)."""
    os.setsid()
    from spreadgym.agents.chart import chart

    try:
        result = chart(out=Path(out), progress=False, on_cell=lambda cell, _record: events.put(("cell", cell.key)),
                       **options)
        events.put(("finished", f"{len(result.computed)} cell(s) computed, {len(result.reused)} reused"))
    except KeyboardInterrupt:
        events.put(("cancelled", "cancelled; finished cells kept"))
    except SpreadgymError as exc:
        events.put(("failed", str(exc)))
    except Exception as exc:  # the job's one line; the server carries on
        events.put(("failed", f"{type(exc).__name__}: {exc}"))


def _stop_group(leader: int) -> None:
    """Kill what is left of a finished job's process group (Ray's helpers after an interrupted start)."""
    try:
        os.killpg(leader, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


class ChartJobs:
    """One chart job at a time: start (checked first, as the CLI checks), status, cancel."""

    def __init__(self, root: Path):
        self.root = root
        self.lock = threading.Lock()
        self.process = None
        self.cancelling = False
        self.status: dict = {"state": "idle"}

    def running(self) -> bool:
        """A job started and not yet reported finished, failed or cancelled."""
        return self.status["state"] == "running"

    def start(self, request: ChartJobRequest) -> dict:
        from spreadgym.agents.chart.spec import make_spec
        from spreadgym.agents.chart.store import ChartStore
        from spreadgym.config.resources import available

        with self.lock:
            if self.running():
                raise SpreadgymError(f"chart job: one is running already ({self.status.get('out')}); "
                                     "cancel it or wait for it")
            names = available("scenes")
            if request.scene not in names:
                raise SpreadgymError(f"--scene: unknown name {brief(request.scene)}; available: {', '.join(names)}")
            if not NAME.fullmatch(request.out):
                raise SpreadgymError(f"--out: {brief(request.out)} must be one folder name (letters, digits, . _ -)")
            cpus = os.cpu_count() or 1
            if request.workers is not None and not 1 <= request.workers <= cpus:
                raise SpreadgymError(f"--workers: {request.workers} is out of range; allowed [1, {cpus}]")
            options = {"scene": request.scene, "fertilizers": request.fertilizers, "widths": request.widths,
                       "driving": request.driving, "budget": request.budget, "granules": request.granules,
                       "seed": request.seed, "workers": request.workers}
            spec, _notes = make_spec(**{k: v for k, v in options.items() if k != "workers"})
            out = inside(self.root, request.out)
            store = ChartStore(out, spec)
            store.probe()
            store.check_manifest()
            context = multiprocessing.get_context("spawn")
            events = context.Queue()
            self.cancelling = False
            self.process = context.Process(target=_job, args=(options, str(out), events), daemon=False)
            self.status = {"state": "running", "out": request.out, "done": 0, "total": len(spec.cells),
                           "message": "starting the embedded Ray", "started": time.time()}
            self.process.start()
            threading.Thread(target=self._follow, args=(self.process, events), daemon=True).start()
            return dict(self.status)

    def _follow(self, process, events) -> None:
        """Read the job's events until it ends."""
        import queue

        while True:
            try:
                kind, text = events.get(timeout=0.5)
            except queue.Empty:
                if process.is_alive():
                    continue
                _stop_group(process.pid)
                with self.lock:
                    if self.status["state"] == "running" and self.cancelling:
                        self.status.update(state="cancelled", message="cancelled", ended=time.time())
                    elif self.status["state"] == "running":
                        self.status.update(state="failed", message=f"the job's process ended ({process.exitcode})")
                return
            with self.lock:
                if kind == "cell":
                    self.status.update(done=self.status["done"] + 1, message=f"cell {text} finished")
                    continue
                self.status.update(state=kind, message=text, ended=time.time())
            process.join(timeout=CANCEL_WAIT_S)
            _stop_group(process.pid)
            return

    def cancel(self, wait_s: float = CANCEL_WAIT_S) -> dict:
        """Interrupt the running job as Ctrl-C would; end its process group if it has not
        ended within `wait_s`."""
        process = self.process
        if process is None or not self.running():
            raise SpreadgymError("chart job: none is running")
        self.cancelling = True
        try:
            os.kill(process.pid, signal.SIGINT)
        except ProcessLookupError:  # it ended just now
            pass
        process.join(timeout=wait_s)
        _stop_group(process.pid)
        process.join(timeout=5.0)
        with self.lock:
            if self.status["state"] == "running":
                self.status.update(state="cancelled", message="cancelled; finished cells kept", ended=time.time())
        return dict(self.status)

    def shutdown(self) -> None:
        """Stop a running job when the server stops (within SHUTDOWN_WAIT_S and a moment)."""
        if self.running():
            self.cancel(SHUTDOWN_WAIT_S)
