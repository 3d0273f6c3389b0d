"""Running a chart's cells: each cell a Ray task (an embedded local Ray, or a cluster
joined by address), or one after the other in this process.

The embedded Ray is private: without an address a new local instance is started
(`address="local"`), never a cluster named by RAY_ADDRESS or one already running on the
machine, with an object store sized to the chart's results; a failed start is one line.
Every service it starts listens on 127.0.0.1 only (dashboard off), and its session
folder (logs, sockets) lies in a per-user cache, removed when the chart ends.
Everything that can be checked before the work is (the folder, the files to come, the
address, Ray's start), and a refused run leaves the folder as it was.

Cells of one fertilizer (a row) run in width order, each started from its narrower
neighbour's settings (`search.run_cell`); rows run side by side. Each finished cell is
written to the chart folder as it arrives, with its pattern picture; a rerun skips the
cells already there. Once a row's cells are all there, the row sweep (`sweep_rows`,
`agents.chart.sweep`) picks one tied point per cell for the whole row; a cell moved off
its search pick is verified again there (Ray tasks side by side) and every cell file is
rewritten with what the sweep did. Ctrl-C cancels the running tasks and
stops, keeping every finished cell. The chart files (chart.csv, .json, .md, .png) are
written only when every cell is done, so nothing half-done reads as a chart.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence

from spreadgym.agents.chart import outputs, sweep
from spreadgym.agents.chart.search import run_cell, score_candidates
from spreadgym.agents.chart.spec import Cell, ChartSpec, make_spec
from spreadgym.agents.chart.store import ChartStore
from spreadgym.config.base import brief, first_line
from spreadgym.errors import SpreadgymError

ENGINES = ("ray", "local")
ADDRESS_TIMEOUT_S = 3.0
WAIT_S = 0.5
OBJECT_STORE_BASE_BYTES = 80 * 2**20  # Ray's least (75 MiB) and some room
OBJECT_STORE_PER_WORKER_BYTES = 16 * 2**20  # a cell's record and picture are under 1 MiB; a few wait per worker
LOOPBACK = "127.0.0.1"
LOOPBACK_SWITCH = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"  # Ray's own switch (ray._private.ray_constants)
SESSION_ROOT_CHARS = 45  # a session folder and socket name add 62 characters; a socket path holds 107 at most


@dataclass
class ChartResult:
    spec: ChartSpec
    payload: dict  # what chart.json holds
    files: list[Path]
    computed: list[str] = field(default_factory=list)  # keys of the cells run this time
    reused: list[str] = field(default_factory=list)  # keys of the cells found finished
    replaced: dict[str, str] = field(default_factory=dict)  # key -> why its file was not its record (run again)
    wall_s: float = 0.0


def check_address(address: str) -> None:
    """Refuse an address where nothing listens (before Ray spends its own long timeout)."""
    if address == "auto":
        return
    hostport = address.split("://", 1)[-1]
    host, sep, port = hostport.rpartition(":")
    if not sep or not port.isdigit() or not host:
        raise SpreadgymError(f"--address {brief(address)}: expected HOST:PORT (or ray://HOST:PORT, or auto)")
    if not 1 <= int(port) <= 65535:
        raise SpreadgymError(f"--address {address}: port {port} is out of range; allowed [1, 65535]")
    try:
        socket.create_connection((host, int(port)), timeout=ADDRESS_TIMEOUT_S).close()
    except OSError as exc:
        raise SpreadgymError(f"--address {address}: no Ray cluster reachable there "
                             f"({exc.strerror or type(exc).__name__})") from None


def connect_ray(workers: Optional[int], address: Optional[str]) -> bool:
    """Start a private local Ray with `workers` CPUs (never joining RAY_ADDRESS or a running
    instance), or join the cluster at `address`; an already running session (the
    caller's) is used as it is. True if started here. A failed start is a SpreadgymError."""
    import ray

    if ray.is_initialized():
        return False
    quiet = {"logging_level": logging.ERROR, "log_to_driver": False}
    if address:
        check_address(address)
        try:
            ray.init(address=address, **quiet)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise SpreadgymError(f"--address {address}: cannot join a Ray cluster there ({first_line(exc)})") from None
        return True
    cpus = workers or os.cpu_count() or 1
    try:
        with loopback_only():
            ray.init(address="local", num_cpus=cpus, include_dashboard=False, _node_ip_address=LOOPBACK,
                     _temp_dir=str(session_root()),
                     object_store_memory=OBJECT_STORE_BASE_BYTES + OBJECT_STORE_PER_WORKER_BYTES * cpus, **quiet)
    except BaseException as exc:  # whatever stops Ray's start (Ctrl-C too) stops its processes
        end_session()
        if not isinstance(exc, Exception):
            raise
        raise SpreadgymError(f"the embedded Ray ({cpus} CPUs) did not start: {first_line(exc)}") from None
    return True


@contextmanager
def loopback_only() -> Iterator[None]:
    """While an embedded Ray starts: every service it starts (GCS, raylet, workers, agents)
    binds 127.0.0.1 only. Ray does so where its node address is the loopback one, which it
    keeps only where "clusters" are off (its default on macOS and Windows, the switch
    RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 elsewhere); the switch is read by Ray when imported
    and by the processes it starts (they inherit the environment), so both are set here
    and put back after the start (joining a cluster later in this process is untouched).
    The test lists the listening sockets of the chart's processes (tests/agents/test_chart_ray.py)."""
    from ray._private import ray_constants

    saved_env, saved_flag = os.environ.get(LOOPBACK_SWITCH), ray_constants.ENABLE_RAY_CLUSTER
    os.environ[LOOPBACK_SWITCH] = "0"
    ray_constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        ray_constants.ENABLE_RAY_CLUSTER = saved_flag
        if saved_env is None:
            os.environ.pop(LOOPBACK_SWITCH, None)
        else:
            os.environ[LOOPBACK_SWITCH] = saved_env


def session_root() -> Path:
    """Where the embedded Ray keeps its session folders (logs, sockets): a per-user cache
    ($XDG_CACHE_HOME or ~/.cache, spreadgym/ray), never the shared system temp folder.
    Ray makes the folder it is given writable by everyone (for other users' drivers), so
    that folder lies inside one of this user's own (`_own_folder`, mode 700), which no one
    else can enter. Ray's Unix sockets need a short path (108 bytes with the session's own
    60), so a cache path longer than SESSION_ROOT_CHARS falls back to such a folder under
    the system temp folder."""
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "spreadgym"
    if len(str((cache / "ray").absolute())) <= SESSION_ROOT_CHARS:
        try:
            return _ray_folder(_own_folder(cache.absolute(), link_allowed=True))
        except OSError:
            pass
    return _ray_folder(_own_folder(Path(tempfile.gettempdir()) / f"spreadgym-ray-{os.getuid()}", link_allowed=False))


def _own_folder(folder: Path, link_allowed: bool) -> Path:
    """`folder`, made if missing, refused unless it is this user's own (and, in a shared
    folder, no link); its mode set to 700 (again at every start: an older version left it open)."""
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    if (folder.is_symlink() and not link_allowed) or folder.stat().st_uid != os.getuid():
        raise SpreadgymError(f"the embedded Ray's folder {folder} is not this user's own; remove it")
    folder.chmod(0o700)
    return folder


def _ray_folder(private: Path) -> Path:
    folder = private / "ray"
    folder.mkdir(exist_ok=True)
    return folder


def end_session() -> None:
    """Stop the embedded Ray and remove its session folder (its logs and sockets)."""
    import ray

    try:
        session = Path(ray._private.worker._global_node.get_session_dir_path())
    except Exception:  # no node, or a Ray without the call: nothing of ours to remove
        session = None
    ray.shutdown()
    if session is not None and session.parent == session_root():
        shutil.rmtree(session, ignore_errors=True)
        latest = session.parent / "session_latest"
        if latest.is_symlink() and not latest.exists():
            latest.unlink(missing_ok=True)


def cell_with_picture(spec: ChartSpec, cell: Cell, previous=None) -> tuple[dict, bytes]:
    """One cell and its pattern picture (PNG bytes), both made where the cell runs.
    `previous`: the narrower neighbour's record, or its (record, picture)."""
    record = run_cell(spec, cell, previous[0] if isinstance(previous, tuple) else previous)
    return record, outputs.cell_picture(spec, cell, record)


def _run_ray(spec: ChartSpec, todo: Sequence[Cell], records: dict,
             finish: Callable[[Cell, dict, bytes], None]) -> None:
    """The cells of `todo` as tasks of the connected Ray, each finished as it arrives; a
    cell's task waits for its narrower neighbour's (rows run side by side)."""
    import ray

    pending: dict = {}
    try:
        task = ray.remote(num_cpus=1)(cell_with_picture)
        spec_ref = ray.put(spec)
        refs: dict = {}
        for cell in todo:  # in spec order: a row's cells narrowest first
            before = spec.previous(cell)
            previous = None if before is None else records.get(before.key, refs.get(before.key))
            refs[cell.key] = task.remote(spec_ref, cell, previous)
            pending[refs[cell.key]] = cell
        while pending:  # short waits, so Ctrl-C is seen at once
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=WAIT_S)
            for ref in ready:
                finish(pending.pop(ref), *ray.get(ref))
    finally:
        for ref in pending:  # interrupted or failed: stop what is still running
            ray.cancel(ref, force=True)


def run_chart(spec: ChartSpec, out: Path, engine: str = "ray", workers: Optional[int] = None,
              address: Optional[str] = None, notes: Sequence[str] = (), progress: bool = True,
              on_cell: Optional[Callable[[Cell, dict], None]] = None, force: bool = False,
              inputs: Sequence[Path] = ()) -> ChartResult:
    """Run (or resume) the chart of `spec` in folder `out` and write its files.

    engine "ray": cells are Ray tasks (local Ray with `workers` CPUs, default all, or
    the cluster at `address`); "local": one after the other in this process.
    `on_cell(cell, record)` is called after each finished cell is written. `force`: write
    into a folder holding another command's outputs; `inputs`: files the chart reads
    (never written over).
    """
    if engine not in ENGINES:
        raise SpreadgymError(f"engine {brief(engine)}; allowed: {', '.join(ENGINES)}")
    if workers is not None and workers < 1:
        raise SpreadgymError(f"--workers: {workers} must be at least 1")
    if address and engine != "ray":
        raise SpreadgymError("--address needs the ray engine")
    cpus = os.cpu_count() or 1
    if workers is not None and workers > cpus and engine == "ray" and not address:
        raise SpreadgymError(f"--workers: {workers} is more than the {cpus} CPUs here; allowed [1, {cpus}] "
                             "(join a larger cluster with --address)")
    if address:
        check_address(address)  # before the folder is claimed
    started = time.perf_counter()
    store = ChartStore(out, spec)
    store.probe(force, inputs)
    store.check_manifest()
    records, replaced = store.finished()
    reused = list(records)
    todo = [c for c in spec.cells if c.key not in records]
    computed: list[str] = []
    started_here = bool(todo) and engine == "ray" and connect_ray(workers, address)
    try:
        with store.folder(force, inputs).writing():
            store.open()  # the first write: every refusal came before it
            _run_cells(spec, store, todo, engine, records, computed, progress, on_cell)
            sweep_rows(spec, store, records, remote=engine == "ray")
            ordered = [records[c.key] for c in spec.cells]
            for cell, record in zip(spec.cells, ordered):
                if not store.picture_ok(cell):  # interrupted before its picture, or the picture damaged
                    outputs.cell_figure(store, cell, record)
            files, payload = outputs.write_chart(store, ordered, list(notes))
    finally:
        if started_here:
            end_session()
    return ChartResult(spec, payload, files, computed, reused, replaced, time.perf_counter() - started)


def swept_with_picture(spec: ChartSpec, cell: Cell, record: dict, pick: int, before: int, after: int,
                       candidates: list, repair_wall_s: float) -> tuple[dict, Optional[bytes]]:
    """The cell's record after the row sweep, and its picture when the sweep re-verified it (else None)."""
    swept = sweep.swept_record(spec, cell, record, pick, before, after, candidates, repair_wall_s)
    moved = swept["detail"]["unit_settings"] != record["detail"]["unit_settings"]
    return swept, outputs.cell_picture(spec, cell, swept) if moved else None


def _map(function, jobs: list, remote: bool) -> list:
    """[function(spec, *job) for job in jobs]: as Ray tasks side by side when `remote` and Ray is running."""
    if remote and jobs:
        import ray

        remote = ray.is_initialized()  # a chart whose cells were all found finished starts no Ray
    if not (remote and jobs):
        return [function(*job) for job in jobs]
    import ray

    task = ray.remote(num_cpus=1)(function)
    return ray.get([task.remote(*job) for job in jobs])


def repair_row(spec: ChartSpec, cells: list, spaces: list, records: dict, remote: bool) -> tuple[list, list]:
    """The row repair (`sweep.repair`) of one row: (each cell's scored candidates, each cell's wall time of
    the scoring done now). A candidate already in a cell's record (a resumed chart) is taken from it: scoring
    is deterministic, so that is what scoring it again would give."""
    details = [records[c.key]["detail"] for c in cells]
    walls = [0.0] * len(cells)

    def score(jobs: dict) -> dict:
        found = {}
        todo = []
        for k, wanted in jobs.items():
            known = {sweep.start_of(c): c for c in sweep.candidates_of(details[k])}
            found[k] = [known.get(sweep.job_key(u, f)) for u, f in wanted]
            missing = [(u, f) for u, f in wanted if sweep.job_key(u, f) not in known]
            if missing:
                todo.append((k, missing))
        scored = _map(score_candidates, [(spec, cells[k], details[k], wanted) for k, wanted in todo], remote)
        for (k, _), (points, wall) in zip(todo, scored):
            new = iter(points)
            found[k] = [p if p is not None else next(new) for p in found[k]]
            walls[k] += wall
        return found

    tried = sweep.repair(spaces, [c.width_m for c in cells], [d["tie_set"] for d in details], score,
                         preference=spec.tie_preference)
    return tried, walls


def sweep_rows(spec: ChartSpec, store: ChartStore, records: dict, remote: bool = False) -> None:
    """The row repair and sweep (`agents.chart.sweep`) over every row whose cells are all in `records`: the
    repair's candidates scored, each cell's pick among its tie set and its tied candidates, a cell moved off
    the point it is verified at verified again (`remote`: as Ray tasks if Ray is running, else here), every
    changed cell's file rewritten with what the sweep did."""
    jobs = []
    for fertilizer in spec.fertilizers:
        cells = [c for c in spec.cells if c.fertilizer == fertilizer]
        if not all(c.key in records for c in cells):
            continue
        spaces = [spec.space(spec.cell_scene(c)) for c in cells]
        tried, walls = repair_row(spec, cells, spaces, records, remote)
        details = [records[c.key]["detail"] for c in cells]
        points = sweep.row_with(spaces, [d["tie_set"] for d in details], tried)
        picks = sweep.steadiest(points, spec.tie_preference)
        before = sweep.row_turns(points, [d["tie_set"]["search_pick"] for d in details])
        after = sweep.row_turns(points, picks)
        jobs += [(cell, pick, before, after, t, wall) for cell, pick, t, wall in zip(cells, picks, tried, walls)]

    def verifies(job) -> bool:
        cell, pick, *_, candidates, _ = job
        detail = records[cell.key]["detail"]
        return detail["unit_settings"] != sweep.points_of(detail["tie_set"], candidates)[pick]["unit_settings"]

    # a cell that keeps the point it is verified at only gets its sweep block: no task for it
    verify = [job for job in jobs if verifies(job)]
    results = {cell.key: swept_with_picture(spec, cell, records[cell.key], *rest)
               for cell, *rest in jobs if not verifies((cell, *rest))}
    done = _map(swept_with_picture, [(spec, cell, records[cell.key], *rest) for cell, *rest in verify], remote)
    results.update({cell.key: result for (cell, *_), result in zip(verify, done)})
    for cell, *_ in jobs:
        record, picture = results[cell.key]
        if record == records[cell.key]:
            continue
        store.save(cell, record)
        if picture is not None:
            outputs.cell_figure(store, cell, record, picture)
        records[cell.key] = record


def _run_cells(spec: ChartSpec, store: ChartStore, todo: Sequence[Cell], engine: str, records: dict,
               computed: list[str], progress: bool, on_cell: Optional[Callable[[Cell, dict], None]]) -> None:
    """Run the cells of `todo`, saving each (record, picture) as it finishes."""
    from tqdm import tqdm

    bar = tqdm(total=len(spec.cells), initial=len(records), desc="chart", unit="cell", file=sys.stderr,
               disable=None if progress else True, leave=False, dynamic_ncols=True)

    def finish(cell: Cell, record: dict, picture: bytes) -> None:
        store.save(cell, record)
        outputs.cell_figure(store, cell, record, picture)
        records[cell.key] = record
        computed.append(cell.key)
        bar.update()
        if on_cell:
            on_cell(cell, record)

    try:
        if todo and engine == "ray":
            _run_ray(spec, todo, records, finish)
        else:
            for cell in todo:
                before = spec.previous(cell)
                finish(cell, *cell_with_picture(spec, cell, None if before is None else records[before.key]))
    finally:
        bar.close()


def chart(scene: str, fertilizers, widths, out: Path, driving: Optional[str] = None, budget: int = 200,
          granules: Optional[int] = None, seed: int = 0, workers: Optional[int] = None,
          address: Optional[str] = None, engine: str = "ray", progress: bool = True,
          on_cell: Optional[Callable[[Cell, dict], None]] = None, force: bool = False,
          **spec_options) -> ChartResult:
    """The spreading chart of `scene` for `fertilizers` (names, a comma list or "all") at
    `widths` (metres, "W1,W2" or "LO:HI:STEP"), in folder `out`: what `spreadgym chart`
    runs. `spec_options` go to `make_spec` (search_model, verify_model, verify_runs,
    settings ranges)."""
    spec, notes = make_spec(scene, fertilizers, widths, driving=driving, budget=budget, granules=granules,
                            seed=seed, **spec_options)
    inputs = [Path(p) for p in (scene, spec_options.get("variability"), spec_options.get("policy"))
              if p and Path(p).exists()]
    return run_chart(spec, out, engine=engine, workers=workers, address=address, notes=notes,
                     progress=progress, on_cell=on_cell, force=force, inputs=inputs)
