"""`spreadgym bench`: speed (and speed against accuracy) measurements, written under docs/."""

from __future__ import annotations

import argparse
import csv
import os
from pathlib import Path

from spreadgym.report import format_table

NAME = "bench"
HELP = "run the benchmarks (speed, speed against accuracy) and write CSV/PNG under --out"
SECTIONS = ("spinner", "flight", "cv-noise")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--only", choices=SECTIONS, action="append", help="run only these sections")
    parser.add_argument("--out", type=Path, default=Path("docs/bench"), help="output folder (default docs/bench)")
    parser.add_argument("--repeats", type=int, default=3, help="repeats per timing (median is reported)")


def write_csv(rows: list[dict], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def run(args: argparse.Namespace) -> int:
    from spreadgym import benchmarks
    from spreadgym.errors import SpreadgymError

    if args.repeats < 1:
        raise SpreadgymError(f"--repeats: {args.repeats} must be at least 1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    sections = args.only or list(SECTIONS)
    runners = {
        "spinner": lambda: benchmarks.spinner_benchmark(repeats=args.repeats),
        "flight": lambda: benchmarks.flight_benchmark(repeats=max(args.repeats, 5)),
        "cv-noise": lambda: benchmarks.cv_noise_benchmark(),
    }
    plots = {"cv-noise": benchmarks.plot_cv_noise}
    for name in sections:
        rows = runners[name]()
        write_csv(rows, args.out / f"{name}.csv")
        if name in plots:
            plots[name](rows, args.out / f"{name}.png")
        print(f"[{name}]")
        print(format_table([list(r.values()) for r in rows], list(rows[0])))
        print()
    return 0
