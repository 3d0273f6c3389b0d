"""The server's heavy work (simulations, fits) in worker processes it can stop.

A `Lane` owns one worker process (spawned, not forked) and runs one job at a time on it,
in the order the requests came (each uses every core already); the server's own event
loop only waits, so health and page routes answer at once under any load. Each waiting
or running request is watched:

* its client left (the connection closed), or it passed the lane's time limit: the job
  is stopped. The worker is asked first (a flag its simulations read between batches of
  runs: `Stop`), and killed when it has not stopped within STOP_GRACE_S; a new worker is
  started in its place. Either way the CPU is free within about a second;
* too many wait already (`max_waiting`): refused at once (HTTP 503).

A worker whose memory grew by more than `grow_limit_bytes` over its size after its start
(a large run's arrays the allocator kept) is replaced once its job is done, so the
server returns to its idle size after load. Workers die with the server (Linux
PR_SET_PDEATHSIG), and `shutdown` kills them at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import multiprocessing
import os
import signal
import time
from dataclasses import dataclass
from typing import Any, Awaitable, Callable, Optional

from spreadgym.errors import SpreadgymError

POLL_S = 0.1  # how often a waiting request looks whether its client is still there
STOP_GRACE_S = 1.0  # a worker asked to stop gets this long (one batch of runs, mostly) before it is killed
START_TIMEOUT_S = 120.0  # a new worker's imports and warm-up (numba's compiled kernels load from its cache)
PAGE_BYTES = os.sysconf("SC_PAGE_SIZE")


class Busy(SpreadgymError):
    """Too many requests wait already, or the lane's one job runs (HTTP 503)."""


class TimeLimit(SpreadgymError):
    """The request ran past the server's time limit (HTTP 503)."""


class Left(Exception):
    """The client closed the connection: nobody waits for the answer."""


class Stop(Exception):
    """Raised inside a worker's job where it checks its stop flag."""


def rss_bytes() -> int:
    """This process's resident memory (Linux /proc)."""
    with open("/proc/self/statm", encoding="ascii") as handle:
        return int(handle.read().split()[1]) * PAGE_BYTES


def _die_with_parent(parent: int) -> None:
    """Linux: SIGKILL this process when its parent dies (a killed server leaves no worker);
    end at once if the parent died before this was set."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:
        os._exit(0)


def _worker(conn, stop_flag, warm: Optional[str], parent: int) -> None:
    """The worker process: import, warm up, then run jobs `(task, args)` sent on `conn`,
    each `task` a "module:function" called as function(args, check), `check()` raising
    Stop once the server asked to stop. Replies: ("ok", text), ("error", message),
    ("failed", message), ("stopped", ""), each with the process's memory after the job."""
    _die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C in the server's terminal is the server's to handle

    def check() -> None:
        if stop_flag.value:
            raise Stop

    try:
        if warm:
            _call(warm, {}, check)
        conn.send(("ready", "", rss_bytes()))
        while True:
            task, args = conn.recv()
            try:
                reply = ("ok", _call(task, args, check))
            except Stop:
                reply = ("stopped", "")
            except SpreadgymError as exc:
                reply = ("error", str(exc))
            except Exception as exc:  # a bug's one line; the worker carries on
                reply = ("failed", f"internal error: {type(exc).__name__}: {exc}")
            conn.send((*reply, rss_bytes()))
    except (EOFError, OSError):  # the server is gone
        return


def _call(task: str, args: dict, check: Callable[[], None]) -> Any:
    module, _, name = task.partition(":")
    return getattr(importlib.import_module(module), name)(args, check)


@dataclass
class _Process:
    process: Any
    conn: Any
    stop_flag: Any
    started_rss: int = 0


class Lane:
    """One worker process and the queue of requests for it (see the module's docstring)."""

    def __init__(self, name: str, time_limit_s: float, max_waiting: int, grow_limit_bytes: int = 512 * 2**20,
                 warm: Optional[str] = None):
        self.name, self.time_limit_s, self.max_waiting = name, time_limit_s, max_waiting
        self.grow_limit_bytes, self.warm = grow_limit_bytes, warm
        self._context = multiprocessing.get_context("spawn")
        self._worker: Optional[_Process] = None
        self._starting: Optional[asyncio.Task] = None
        self._turn: Optional[asyncio.Lock] = None
        self._closed = False
        self.waiting = 0

    # -- worker processes ------------------------------------------------------------
    def start(self) -> None:
        """Start the worker now (it warms up while the server starts); call in the event loop."""
        if self._worker is None and self._starting is None and not self._closed:
            self._starting = asyncio.ensure_future(self._spawn())

    async def _spawn(self) -> _Process:
        parent, child = self._context.Pipe()
        stop_flag = self._context.Value("b", 0, lock=False)
        process = self._context.Process(target=_worker, args=(child, stop_flag, self.warm, os.getpid()),
                                        daemon=True, name=f"spreadgym-{self.name}")
        process.start()
        child.close()
        worker = _Process(process, parent, stop_flag)
        try:
            kind, _, rss = await self._reply(worker, time.monotonic() + START_TIMEOUT_S)
        except BaseException:
            self._kill(worker)
            raise
        if kind != "ready":
            self._kill(worker)
            raise SpreadgymError(f"{self.name}: the worker did not start")
        worker.started_rss = rss
        return worker

    async def _ready(self) -> _Process:
        if self._worker is not None and self._worker.process.is_alive():
            return self._worker
        self._worker = None
        self.start()
        starting = self._starting
        if starting is None:
            raise Busy(f"{self.name}: the server is stopping")
        try:
            self._worker = await starting
        finally:
            if self._starting is starting:
                self._starting = None
        return self._worker

    @staticmethod
    def _kill(worker: _Process) -> None:
        with contextlib.suppress(ProcessLookupError, OSError):
            os.kill(worker.process.pid, signal.SIGKILL)
        worker.process.join(timeout=5.0)
        worker.conn.close()

    def _retire(self) -> None:
        """Kill the worker; the next job starts a new one (which starts now, in the background)."""
        if self._worker is not None:
            self._kill(self._worker)
            self._worker = None
        self.start()

    async def _reply(self, worker: _Process, deadline: float,
                     leave: Optional[Callable[[], Awaitable[bool]]] = None) -> tuple:
        """The worker's next message; Left or TimeLimit raised (the job left running) when
        the client leaves or the deadline passes first."""
        loop = asyncio.get_running_loop()
        ready = asyncio.Event()
        fd = worker.conn.fileno()
        loop.add_reader(fd, ready.set)
        try:
            while True:
                self._check_open()
                if worker.conn.poll():
                    break
                if not worker.process.is_alive():
                    raise SpreadgymError(f"{self.name}: the worker ended ({worker.process.exitcode})")
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(ready.wait(), POLL_S)
                ready.clear()
                if leave is not None and await leave():
                    raise Left
                if time.monotonic() > deadline:
                    raise TimeLimit(f"{self.name}: stopped at the server's time limit of {self.time_limit_s:g} s "
                                    "(serve --time-limit); ask for less work (fewer runs, granules or keys)")
            return worker.conn.recv()
        finally:
            loop.remove_reader(fd)

    async def _stop(self, worker: _Process) -> None:
        """Stop the running job: the flag first, the kill after STOP_GRACE_S."""
        if self._closed:
            return  # `close` killed the worker already
        worker.stop_flag.value = 1
        try:
            await self._reply(worker, time.monotonic() + STOP_GRACE_S)
        except (TimeLimit, SpreadgymError, OSError, EOFError):
            self._retire()

    def _check_open(self) -> None:
        if self._closed:
            raise Busy(f"{self.name}: the server is stopping")

    # -- requests ----------------------------------------------------------------------
    async def run(self, task: str, args: dict, leave: Callable[[], Awaitable[bool]]) -> str:
        """The text `task` returns for `args`, run on the worker in its turn. SpreadgymError
        (bad input: its message), Busy, TimeLimit or Left (the client went; nobody reads
        the answer) where it does not finish."""
        if self._turn is None:
            self._turn = asyncio.Lock()
        if self.waiting >= self.max_waiting:
            raise Busy(f"{self.name}: {self.waiting} request(s) running or waiting already; try again later")
        deadline = time.monotonic() + self.time_limit_s
        self.waiting += 1
        try:
            await self._wait_turn(leave, deadline)
            try:
                return await self._run_turn(task, args, leave, deadline)
            finally:
                self._turn.release()
        finally:
            self.waiting -= 1

    async def _wait_turn(self, leave: Callable[[], Awaitable[bool]], deadline: float) -> None:
        turn = asyncio.ensure_future(self._turn.acquire())
        try:
            while not turn.done():
                await asyncio.wait({turn}, timeout=POLL_S)
                if turn.done():
                    break
                self._check_open()
                if await leave():
                    raise Left
                if time.monotonic() > deadline:
                    raise TimeLimit(f"{self.name}: waited the server's time limit of {self.time_limit_s:g} s "
                                    "(serve --time-limit) behind other requests; try again later")
        except BaseException:
            if turn.done() and not turn.cancelled():
                self._turn.release()
            else:
                turn.cancel()
            raise

    async def _run_turn(self, task: str, args: dict, leave, deadline: float) -> str:
        worker = await self._ready()
        worker.stop_flag.value = 0
        worker.conn.send((task, args))
        try:
            kind, text, rss = await self._reply(worker, deadline, leave)
        except BaseException:  # the client left, the time ran out or the server stops: free the CPU
            await asyncio.shield(self._stop(worker))
            raise
        if rss > worker.started_rss + self.grow_limit_bytes:
            self._retire()  # its memory goes back to the machine; a fresh worker takes the next job
        if kind == "ok":
            return text
        if kind == "error":
            raise SpreadgymError(text)
        if kind == "stopped":
            raise Left
        raise RuntimeError(text)

    def shutdown(self) -> None:
        """The server stops: the worker is killed, no new one starts, and every request
        waiting or running answers within POLL_S (503)."""
        self._closed = True
        if self._starting is not None:
            self._starting.cancel()
        if self._worker is not None:
            self._kill(self._worker)
            self._worker = None
