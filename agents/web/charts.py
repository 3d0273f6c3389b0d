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
from spreadgym.out_folder import STAMP

NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]{0,99}")  # one folder name: no '..', no hidden names
MAX_DEPTH = 3  # chart folders are looked for this deep under the charts folder
MAX_LISTED = 500
FILE_TYPES = {".png": "image/png", ".csv": "text/csv", ".json": "application/json", ".md": "text/markdown",
              ".html": "text/html"}
MAX_READ_BYTES = 5_000_000  # chart.json / chart.md read for the page
CANCEL_WAIT_S = 30.0  # after Ctrl-C, before the job's process is terminated
STOP_WAIT_S = 5.0  # after the kill, for the job's process group to be gone
SHUTDOWN_WAIT_S = 3.0  # the same when the server stops: it stops within a few seconds (finished cells are on disk)
PROBE_GRANULES = 256  # the start's estimate times one run of this many granules per model, scaled to the chart's
RAY_START_S = 10.0  # the embedded Ray's start in the estimate (6-8 s on an idle two-core machine)
REMOVABLE = re.compile(r"(manifest\.json|chart\.(csv|json|md|png|html)|cells|\.?.*\.partial|"
                       + re.escape(STAMP) + ")")  # what a chart folder holds: removed with an unfinished chart


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


def estimate_s(spec, workers: int) -> float:
    """A chart's time before any cell has finished, from one timed run per model at PROBE_GRANULES granules
    scaled to the chart's: a cell is its search (budget x draws runs of the search model) and its verification
    (the verify model's runs); rows run side by side on the workers, a row's cells one after the other."""
    import math

    from spreadgym.agents.chart.spec import Cell
    from spreadgym.config.scene import scene_with
    from spreadgym.spread.pipeline import run_scene

    scene = spec.cell_scene(Cell(spec.fertilizers[0], spec.widths_m[0]))
    probe = scene_with(scene, {"sim.granules": min(PROBE_GRANULES, scene.sim.granules)})
    scale = scene.sim.granules / probe.sim.granules

    def timed(model: str) -> float:
        started = time.perf_counter()
        run_scene(probe, model=model, library=spec.library(), ci=False)
        return (time.perf_counter() - started) * scale

    cell = spec.budget * spec.draws * timed(spec.search_model) + spec.verify_simulations * timed(spec.verify_model)
    side_by_side = max(1, min(workers, len(spec.fertilizers)))
    return RAY_START_S + math.ceil(len(spec.fertilizers) / side_by_side) * len(spec.widths_m) * cell


def remove_folder(root: Path, name: str) -> None:
    """Remove an unfinished chart folder (a cancelled or failed job's): only the chart's own files may be there."""
    import shutil

    folder = inside(root, name)
    if not folder.is_dir() or not is_chart(root, folder) or folder == root.resolve():
        raise NotFound(f"chart: no chart folder {brief(name)} under the charts folder")
    if (folder / "chart.json").is_file():
        raise SpreadgymError(f"chart {brief(name)}: finished; only an unfinished chart (a cancelled or failed job's) "
                             "is removed from the page")
    others = [p.name for p in folder.iterdir() if not REMOVABLE.fullmatch(p.name)]
    if others:
        raise SpreadgymError(f"chart {brief(name)}: holds other files ({', '.join(sorted(others)[:3])}); "
                             "remove it by hand")
    shutil.rmtree(folder)


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


def waiting_detail(name: str) -> dict:
    """`chart_detail`'s answer for the running job's folder before its first file: nothing to show yet."""
    return {"name": name, "finished": False, "markdown": None, "rows": [], "files": [], "cell_pictures": []}


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


def _stop_group(process, wait_s: float = STOP_WAIT_S) -> None:
    """Kill what is left of a job's process group (`process` leads it; Ray's helpers after an interrupted start),
    reap the leader and wait until the group is gone, at most `wait_s` (a killed process lingers until it exits
    and is reaped: longer on a loaded machine)."""
    leader = process.pid
    try:
        os.killpg(leader, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        return
    process.join(timeout=wait_s)
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        try:
            os.killpg(leader, 0)
        except (ProcessLookupError, PermissionError):
            return
        time.sleep(0.02)


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
                           "message": "starting the embedded Ray", "started": time.time(), "estimate_s": None}
            self.process.start()
            threading.Thread(target=self._follow, args=(self.process, events), daemon=True).start()
            threading.Thread(target=self._estimate, args=(spec, request.workers or cpus), daemon=True).start()
        return self.report()

    def _estimate(self, spec, workers: int) -> None:
        """The chart's time before its first cell (`estimate_s`), once one run per model is timed."""
        try:
            total = estimate_s(spec, workers)
        except Exception:  # an estimate is not worth a failed job: the page says it has none
            return
        with self.lock:
            if self.status.get("state") == "running" and self.status.get("estimate_s") is None:
                self.status["estimate_s"] = total

    def report(self) -> dict:
        """The job's status with its elapsed time and the time left: from the start's estimate until a cell has
        finished, then from the cells' own pace."""
        with self.lock:
            status = dict(self.status)
        if status["state"] == "idle":
            return status
        end = status.get("ended") or time.time()
        elapsed = end - status["started"]
        left = None
        if status["state"] == "running":
            done, total = status["done"], status["total"]
            if done:
                left = elapsed / done * (total - done)
            elif status.get("estimate_s") is not None:
                left = max(0.0, status["estimate_s"] - elapsed)
        return {**status, "elapsed_s": elapsed, "left_s": left}

    def _is_jobs(self, folder: Path) -> bool:
        """Whether `folder` (resolved, `inside`) is the folder the job's status names: compared
        as folders, so "job/", "job/." and "job" are one. The caller holds the lock."""
        out = self.status.get("out")
        return out is not None and inside(self.root, out) == folder

    def is_running_folder(self, name: str) -> bool:
        """Whether `name` is the running job's folder."""
        folder = inside(self.root, name)
        with self.lock:
            return self.running() and self._is_jobs(folder)

    def remove(self, name: str) -> dict:
        """Remove an unfinished chart folder that no job is writing (`remove_folder`); the job's status is
        cleared when it is its folder."""
        folder = inside(self.root, name)
        with self.lock:
            ours = self._is_jobs(folder)
            if self.running() and ours:
                raise SpreadgymError(f"chart {brief(name)}: its job is running; cancel it first")
            remove_folder(self.root, name)
            if ours:
                self.status = {"state": "idle"}
            return {"removed": name}

    def _follow(self, process, events) -> None:
        """Read the job's events until it ends."""
        import queue

        while True:
            try:
                kind, text = events.get(timeout=0.5)
            except queue.Empty:
                if process.is_alive():
                    continue
                _stop_group(process)
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
            _stop_group(process)
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
        _stop_group(process)
        with self.lock:
            if self.status["state"] == "running":
                self.status.update(state="cancelled", message="cancelled; finished cells kept", ended=time.time())
        return self.report()

    def shutdown(self) -> None:
        """Stop a running job when the server stops (within SHUTDOWN_WAIT_S and a moment)."""
        if self.running():
            self.cancel(SHUTDOWN_WAIT_S)
