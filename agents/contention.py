"""Why P independent processes, one per core, each keep less than one process's rate alone.

On a lent 16-core machine the vector env's 16 worker processes of one thread each kept
0.61 of one process's designs/s per core (docs/performance.md), where this two-core
machine's workers keep about 0.98. The workers share nothing in Python; what they share
is the hardware: the cores' clock under an all-core load, the caches, the memory. This
probe times the same work in 1, 2, 4, ... concurrent processes, each pinned to a core of
its own and running one thread, phase by phase, every process in the same phase at the
same time (phases start at agreed wall-clock times, with a pause between them):

- **arithmetic**: a compiled loop over a few scalars (multiply-adds and a square root,
  no memory traffic): how the cores' clock holds up under the load;
- **memory**: numpy sums over an array far larger than any cache (`--stream-mb`): each
  core's share of the memory bandwidth;
- **spinner** and **finish**: `run_batch` of paper designs with its stages timed
  (`device_check.staged_batch`): the simulator's own two stages.

Each rate per process at P processes is divided by the rate of one process alone: a stage
that falls like the arithmetic is bound by the clock (no code change gives that back); one
that falls further than the arithmetic, by what the cores share (its memory traffic). Run
by `device_check.py --contention` on the lent machine; `--procs 1,2` works anywhere.
Writes contention.csv (a row per process count and probe) under `--out`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import numpy as np
from numba import njit

from spreadgym.agents.device_check import Table, count_list, paper_designs, staged_batch

PROBES = ("arithmetic", "memory", "spinner", "finish")
ARITHMETIC_STEPS = 2_000_000  # one arithmetic unit: ~10 ms on a 3 GHz core
PAUSE_S = 1.5  # between phases: a unit begun near a phase's end finishes before the next phase


@njit(cache=True)
def arithmetic(steps: int) -> float:
    """`steps` rounds of four dependent chains of multiply-adds and a square root on
    scalars held in registers (nothing the compiler can fold away): core-bound work."""
    a, b, c, d = 1.0, 0.5, 0.25, 0.125
    for _ in range(steps):
        a = math.sqrt(a * 1.0000001 + 0.3)
        b = b * 0.9999997 + 0.1 * a
        c = c * 0.9999993 + 0.2 * b
        d = d * 0.9999989 + 0.3 * c
    return a + b + c + d


PHASES = {"arithmetic": 1, "memory": 1, "batches": 2}  # each phase's length in `phase_s`


def phase_windows(start_at: float, phase_s: float) -> dict:
    """Each phase's (begin, end) wall-clock window, one after another from `start_at` with
    PAUSE_S between them (the batches phase gives the spinner and finish probes)."""
    windows, begin = {}, start_at
    for name, length in PHASES.items():
        windows[name] = (begin, begin + length * phase_s)
        begin += length * phase_s + PAUSE_S
    return windows


def _units_until(end: float, unit) -> tuple[int, float, list]:
    """Call `unit()` until wall-clock `end` (a unit begun before it is finished; at least one,
    so a process that started late still gives a rate); returns the count, their summed
    seconds and what each returned."""
    count, seconds, returned = 0, 0.0, []
    while count == 0 or time.time() < end:
        began = time.perf_counter()
        returned.append(unit())
        seconds += time.perf_counter() - began
        count += 1
    return count, seconds, returned


def worker(core: int, start_at: float, phase_s: float, stream_mb: int, designs: int, out: Path) -> None:
    """One process of a round: pinned to `core`, one thread, warmed before `start_at`; each
    phase run in its window (`phase_windows`); the rates written to `out` as JSON."""
    began = time.time()
    os.sched_setaffinity(0, {core})
    from spreadgym import threads
    from spreadgym.config.materials import load_library

    threads.set_threads(1)
    library = load_library()
    papers = paper_designs(designs)
    block = np.ones(stream_mb * 2**20 // 8)
    arithmetic(1000)
    staged_batch(papers[:2], library)  # loads the cached kernels before the clock starts
    windows = phase_windows(start_at, phase_s)
    found: dict = {"core": core, "late": time.time() > start_at, "ready_s": time.time() - began}

    def wait(until: float) -> None:
        time.sleep(max(0.0, until - time.time()))

    wait(windows["arithmetic"][0])
    count, seconds, _ = _units_until(windows["arithmetic"][1], lambda: arithmetic(ARITHMETIC_STEPS))
    found["arithmetic"] = count * ARITHMETIC_STEPS / seconds / 1e6  # million rounds/s
    wait(windows["memory"][0])
    count, seconds, _ = _units_until(windows["memory"][1], lambda: float(block.sum()))
    found["memory"] = count * block.nbytes / seconds / 1e9  # GB/s read
    wait(windows["batches"][0])  # batches of paper designs, their two stages timed apart
    count, seconds, stages = _units_until(windows["batches"][1], lambda: staged_batch(papers, library)[1])
    found["spinner"] = count * designs / sum(s["spinner"] for s in stages)  # designs/s of the stage alone
    found["finish"] = count * designs / sum(s["finish"] for s in stages)
    found["batches"] = count
    out.write_text(json.dumps(found))


def run_round(procs: int, cores: list[int], phase_s: float, stream_mb: int, designs: int, folder: Path,
              start_s: float) -> list[dict]:
    """`procs` worker processes on the first `procs` of `cores`, started together; their rates."""
    start_at = time.time() + start_s
    children, files = [], []
    for i in range(procs):
        files.append(folder / f"p{procs}-{i}.json")
        command = [sys.executable, "-P", "-m", "spreadgym.agents.contention", "--role", "worker",
                   "--core", str(cores[i]), "--start-at", repr(start_at), "--phase-s", str(phase_s),
                   "--stream-mb", str(stream_mb), "--designs", str(designs), "--file", str(files[-1])]
        children.append(subprocess.Popen(command, env=dict(os.environ, NUMBA_NUM_THREADS="1",
                                                           SPREADGYM_THREADS="1")))
    for child in children:
        child.wait()
    return [json.loads(f.read_text()) for f in files if f.exists()]


def summarise(rounds: dict) -> list[dict]:
    """Rows of contention.csv from {procs: [each process's rates]}: per probe the median
    (and range) per process, the sum over processes, and the median over one process's."""
    solo = {probe: statistics.median(r[probe] for r in rounds[min(rounds)]) for probe in PROBES}
    rows = []
    for procs in sorted(rounds):
        found = rounds[procs]
        for probe in PROBES:
            rates = [r[probe] for r in found]
            median = statistics.median(rates)
            rows.append({"procs": procs, "probe": probe, "unit": UNITS[probe], "per_process": median,
                         "low": min(rates), "high": max(rates), "total": sum(rates),
                         "per_process_over_one": median / solo[probe], "processes_reported": len(rates),
                         "late_starts": sum(bool(r["late"]) for r in found),
                         "slowest_ready_s": max(r["ready_s"] for r in found)})
    return rows


UNITS = {"arithmetic": "million rounds/s", "memory": "GB/s", "spinner": "designs/s", "finish": "designs/s"}


def measure(out: Path, procs: list[int], phase_s: float = 5.0, stream_mb: int = 512, designs: int = 8,
            start_s: float = 12.0, say=print) -> list[dict]:
    """The rounds at each count in `procs` (at most the cores this process may use), one
    after another; contention.csv under `out`; returns its rows."""
    cores = sorted(os.sched_getaffinity(0))
    arithmetic(1000)  # compiled and cached here once, so the workers only load it
    table, rounds = Table(out / "contention.csv"), {}
    with tempfile.TemporaryDirectory(prefix="contention-") as folder:
        for count in [p for p in procs if p <= len(cores)]:
            began = time.time()
            rounds[count] = run_round(count, cores, phase_s, stream_mb, designs, Path(folder), start_s)
            if len(rounds[count]) < count:
                say(f"contention: {count - len(rounds[count])} of {count} processes reported nothing")
            if not rounds[count]:
                del rounds[count]
                continue
            rows = summarise(rounds)
            table.rows = []
            for row in rows:
                table.add(row)
            line = ", ".join(f"{r['probe']} {r['per_process_over_one']:.2f}" for r in rows if r["procs"] == count)
            say(f"contention: {count} processes, rate per process over one process alone: {line} "
                f"({time.time() - began:.0f} s)")
    return table.rows


def main(argv: Optional[list[str]] = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/contention", help="folder for contention.csv")
    parser.add_argument("--procs", type=count_list, default=[1, 2, 4, 8, 16], help="process counts, comma-separated")
    parser.add_argument("--phase-s", type=float, default=5.0,
                        help="seconds each of the arithmetic and memory probes runs (the batches twice that)")
    parser.add_argument("--stream-mb", type=int, default=512, help="the memory probe's array, MB per process")
    parser.add_argument("--designs", type=int, default=8, help="paper designs per timed batch")
    parser.add_argument("--role", choices=("main", "worker"), default="main", help=argparse.SUPPRESS)
    parser.add_argument("--core", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--start-at", type=float, help=argparse.SUPPRESS)
    parser.add_argument("--file", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role == "worker":
        worker(args.core, args.start_at, args.phase_s, args.stream_mb, args.designs, Path(args.file))
        return
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    measure(out, args.procs, args.phase_s, args.stream_mb, args.designs)


if __name__ == "__main__":
    main()
