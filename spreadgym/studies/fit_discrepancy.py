"""Measure the compiled model's discrepancy from the full model for the fit's intervals.

For each shipped single-disc scene (paper, field), fertilizer (compound-10-16-10,
pellet) and granule rotation (locked, free): `points` calibration points over the fit
bench's search box (vane friction 0.2-0.8, vane restitution 0.2-0.7) from a Sobol
sequence of seed 1 (the bench's truths come from seed 0), each simulated with both
models at the same granules and a seed of its own (`discrepancy.CALIBRATION_SEED` + i,
never a truth's or a fit's). Written to `spreadgym/fit/discrepancy.csv`, which the fit
reads (`spreadgym.fit.discrepancy`).
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from itertools import product
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Optional

from spreadgym.fit import discrepancy
from spreadgym.studies.fit_bench import FERTILIZERS, ROTATIONS, SCENES, SEARCH

POINTS = 4


def search_ranges() -> dict[str, tuple[float, float]]:
    """The fit bench's search box as key -> (low, high)."""
    ranges = {}
    for spec in SEARCH.split(","):
        key, bounds = spec.split("=")
        lo, hi = bounds.split(":")
        ranges[key] = (float(lo), float(hi))
    return ranges


def measure_case(scene_name: str, fertilizer: str, rotation: str, index: int, point: dict, granules: int,
                 cache: Optional[Path]) -> list[dict]:
    """One calibration point's rows."""
    from spreadgym.config.scene import load_scene
    from spreadgym.threads import set_threads

    set_threads(1)
    scene = load_scene(scene_name, {"fertilizer": fertilizer, "granule.rotation": rotation})
    x_m, delta, variance = discrepancy.measure(scene, point, discrepancy.CALIBRATION_SEED + index, granules, cache)
    label = ";".join(f"{k}={v}" for k, v in point.items())
    return [{"scene": scene_name, "fertilizer": fertilizer, "rotation": rotation, "point": label,
             "x_m": f"{x:.3f}", "delta": f"{d:.6g}", "delta_var": f"{v:.6g}"} for x, d, v in zip(x_m, delta, variance)]


def fit_discrepancy_rows(path: Path = discrepancy.STORED, points: int = POINTS,
                         granules: int = discrepancy.CALIBRATION_GRANULES, workers: int = 1,
                         cache: Optional[Path] = None, progress: Optional[Callable[[str], None]] = None) -> list[dict]:
    """Measure every scene x fertilizer x rotation at `points` calibration points on `workers`
    processes; write `path`; the rows."""
    calibration = discrepancy.sobol_points(search_ranges(), points)
    jobs = [(s, f, r, i, p, granules, cache) for s, f, r in product(SCENES, FERTILIZERS, ROTATIONS)
            for i, p in enumerate(calibration)]
    rows: list[dict] = []
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        for job, found in zip(jobs, pool.map(measure_case, *zip(*jobs))):
            rows += found
            if progress:
                progress(f"discrepancy {job[0]} {job[1]} {job[2]} point {job[3]}: {len(found)} trays")
    header = (f"full (pymunk) minus compiled log tray mass, paired seeds {discrepancy.CALIBRATION_SEED}+i, "
              f"{granules} granules x {discrepancy.CALIBRATION_REPLICATES} replicates, {points} Sobol points "
              f"(seed 1) over {SEARCH}; written by spreadgym.studies.fit_discrepancy")
    discrepancy.write_discrepancy(path, rows, header)
    return rows
