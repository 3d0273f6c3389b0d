"""Start-up of each command: wall time of a fresh `spreadgym ...` process, end to end
(`make bench`, section startup). A command pays for the modules it imports and for
loading its compiled kernels from numba's cache; this measures both, as a person at a
terminal meets them."""

from __future__ import annotations

import statistics
import subprocess
import sys
import time

INLINE_FERTILIZER = ("fertilizer={name: my-blend, particle_density_kg_m3: 1650, friction: {mc: 0.45}, "
                     "restitution: {mc: 0.40}, rolling_resistance: {mc: 0.1}, "
                     "size: {d50_m: 0.0032, sd_m: 0.0005, min_m: 0.002, max_m: 0.005}}")
"""A fertilizer given inline in the scene (docs/materials.md's example), rolling resistance on."""

COMMANDS = (
    ("--help",),
    ("materials",),
    ("simulate", "--scene", "paper", "--json"),
    ("simulate", "--scene", "paper", "--set", "fertilizer=potassium-chloride", "--json"),
    ("simulate", "--scene", "paper", "--set", INLINE_FERTILIZER, "--json"),
    ("simulate", "--scene", "field", "--json"),
    ("reference", "--scene", "paper", "--json"),
    ("chart", "--help"),
)
TARGETS_S = {COMMANDS[0]: 0.6, **dict.fromkeys(COMMANDS[2:5], 1.5)}  # --help; simulate paper, KCl, inline


def startup_rows(repeats: int = 3) -> list[dict]:
    """Median and range of the wall time of each command in a new interpreter (one warm-up
    run first, so numba's cache is written and the figure is a warm install's)."""
    rows = []
    for argv in COMMANDS:
        command = [sys.executable, "-m", "spreadgym.cli.main", *argv]
        subprocess.run(command, capture_output=True, check=True)
        walls = []
        for _ in range(repeats):
            started = time.perf_counter()
            subprocess.run(command, capture_output=True, check=True)
            walls.append(time.perf_counter() - started)
        target = TARGETS_S.get(argv)
        rows.append({"command": "spreadgym " + " ".join(argv), "repeats": repeats,
                     "median_s": round(statistics.median(walls), 3), "min_s": round(min(walls), 3),
                     "max_s": round(max(walls), 3), "target_s": target if target is not None else "",
                     "met": "" if target is None else statistics.median(walls) <= target})
    return rows
