"""The server under load, measured from outside: `spreadgym serve` in a process of its
own, spoken to over real sockets (the web tests and `make bench`, section server).

* `health_under_load`: the answer time of GET /api/health while N simulations run or
  wait (target <= 0.2 s under 60);
* `cancel_seconds`: from the moment a client closes its connection to the moment the
  server's processes stop burning CPU (target <= 2 s);
* `memory`: the resident memory of the server and its workers, idle, under load and
  after it (target: back near idle);
* `stop_seconds`: from SIGTERM, during a simulation, until every process of the server
  has ended (target: a few seconds).
"""

from __future__ import annotations

import http.client
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Optional

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
PAGE_BYTES = os.sysconf("SC_PAGE_SIZE")
LONG = {"scene": "paper", "set": {"sim.granules": 20000}, "precision": 0.001, "max_runs": 4096}  # minutes of work
SHORT = {"scene": "paper", "set": {"sim.granules": 2048}, "max_runs": 4}  # about a second on two busy cores


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def tree(root: int) -> list[int]:
    """`root` and its descendants (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat", encoding="ascii", errors="replace") as handle:
                    parent = int(handle.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(parent, []).append(int(name))
    found, todo = [], [root]
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo += children.get(pid, [])
    return found


def cpu_seconds(pids: list[int]) -> float:
    total = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as handle:
                fields = handle.read().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])  # utime, stime
        except (OSError, IndexError, ValueError):
            pass
    return total / CLOCK_TICKS


def rss_bytes(pids: list[int]) -> int:
    total = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/statm", encoding="ascii") as handle:
                total += int(handle.read().split()[1]) * PAGE_BYTES
        except (OSError, IndexError, ValueError):
            pass
    return total


class Server:
    """`spreadgym serve` on a free loopback port, in a process of its own."""

    def __init__(self, charts: Path, *extra: str):
        self.port = free_port()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "spreadgym.cli.main", "serve", "--port", str(self.port), "--charts", str(charts),
             *extra], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def wait_ready(self, timeout_s: float = 180.0) -> None:
        """Until the health route answers and the simulation worker has warmed up."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"the server ended: {self.process.stdout.read()}")
            try:
                if self.request("GET", "/api/health", timeout=2.0)[0] == 200:
                    status, _ = self.request("POST", "/api/simulate", {"set": {"sim.granules": 64}, "max_runs": 2})
                    if status == 200:
                        return
            except OSError:
                pass
            time.sleep(0.2)
        raise RuntimeError("the server did not answer in time")

    def pids(self) -> list[int]:
        return tree(self.process.pid)

    def request(self, method: str, path: str, body: Optional[dict] = None, headers: Optional[dict] = None,
                timeout: float = 600.0) -> tuple[int, dict]:
        connection = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        try:
            data = None if body is None else json.dumps(body).encode()
            sent = {"content-type": "application/json", **(headers or {})}
            connection.request(method, path, body=data, headers=sent)
            response = connection.getresponse()
            return response.status, json.loads(response.read() or b"null")
        finally:
            connection.close()

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


@contextmanager
def serving(charts: Path, *extra: str) -> Iterator[Server]:
    server = Server(charts, *extra)
    try:
        server.wait_ready()
        yield server
    finally:
        server.stop()


def start_abandoned(server: Server, body: dict, path: str = "/api/simulate") -> socket.socket:
    """A request sent over a raw socket (closed by the caller to leave, or read to its end)."""
    data = json.dumps(body).encode()
    sock = socket.create_connection(("127.0.0.1", server.port))
    sock.sendall(b"POST %s HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nconnection: close\r\ncontent-type: application/json\r\n"
                 b"content-length: %d\r\n\r\n" % (path.encode(), server.port, len(data)) + data)
    return sock


def busy_until_idle(pids: list[int], timeout_s: float = 30.0, window_s: float = 0.3) -> float:
    """Seconds until the processes use less than a tenth of a core over `window_s`."""
    started = time.monotonic()
    before = cpu_seconds(pids)
    while time.monotonic() - started < timeout_s:
        time.sleep(window_s)
        now = cpu_seconds(pids)
        if now - before < 0.1 * window_s:
            return time.monotonic() - started - window_s
        before = now
    return float("inf")


def cancel_seconds(server: Server, body: dict = LONG, running_s: float = 2.0) -> float:
    """From closing the connection of a running simulation to its CPU freed."""
    sock = start_abandoned(server, body)
    time.sleep(running_s)
    pids = server.pids()
    sock.close()
    return busy_until_idle(pids)


def health_under_load(server: Server, concurrent: int = 60, body: dict = SHORT,
                      probes: int = 30) -> dict:
    """Answer times of /api/health (s) while `concurrent` simulations of `body` run or wait."""
    answers: list[int] = []

    def simulate() -> None:
        answers.append(server.request("POST", "/api/simulate", body)[0])

    threads = [threading.Thread(target=simulate, daemon=True) for _ in range(concurrent)]
    for thread in threads:
        thread.start()
    time.sleep(1.0)  # every request sent, the first running
    times, peak_rss = [], 0
    for _ in range(probes):
        started = time.perf_counter()
        status, _ = server.request("GET", "/api/health", timeout=30.0)
        times.append(time.perf_counter() - started)
        assert status == 200
        peak_rss = max(peak_rss, rss_bytes(server.pids()))
        time.sleep(0.1)
    pending = sum(thread.is_alive() for thread in threads)
    for thread in threads:
        thread.join()
    return {"concurrent": concurrent, "pending_at_end_of_probes": pending, "health_median_s": statistics.median(times),
            "health_max_s": max(times), "statuses": sorted(set(answers)), "peak_rss_bytes": peak_rss}


def stop_seconds(server: Server, body: dict = LONG, running_s: float = 2.0) -> float:
    """From SIGTERM, a simulation running, until every process of the server has ended."""
    sock = start_abandoned(server, body)
    time.sleep(running_s)
    pids = server.pids()
    started = time.monotonic()
    server.process.send_signal(signal.SIGTERM)
    while any(os.path.exists(f"/proc/{pid}") and not _zombie(pid) for pid in pids):
        if time.monotonic() - started > 60:
            return float("inf")
        time.sleep(0.05)
    sock.close()
    return time.monotonic() - started


def _zombie(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return False


def server_rows(charts: Path, repeats: int = 3) -> list[dict]:
    """The section server of `make bench`: each measurement `repeats` times on a fresh server."""
    rows = []
    for repeat in range(repeats):
        with serving(charts) as server:
            idle = rss_bytes(server.pids())
            load = health_under_load(server)
            time.sleep(2.0)
            after = rss_bytes(server.pids())
            cancel = cancel_seconds(server)
            server_rss = rss_bytes([server.process.pid])
        with serving(charts) as server:
            stop = stop_seconds(server)
        rows.append({"repeat": repeat, "concurrent": load["concurrent"], "health_median_s": load["health_median_s"],
                     "health_max_s": load["health_max_s"], "cancel_s": cancel, "stop_s": stop,
                     "idle_rss_mib": idle / 2**20, "peak_rss_mib": load["peak_rss_bytes"] / 2**20,
                     "after_load_rss_mib": after / 2**20, "server_process_rss_mib": server_rss / 2**20})
    return rows
