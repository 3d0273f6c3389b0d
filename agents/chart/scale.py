"""How a chart scales on Ray: cells per minute on an embedded local Ray with 1 and 2
workers, and on a simulated three-node cluster on this machine (`ray.cluster_utils.Cluster`:
a head node without CPUs, where the driver runs, and two worker nodes of one CPU each).

Every configuration runs the same small chart (the paper scene, its charted fertilizers
at 3-6 m, a small budget so the whole benchmark takes minutes) into a fresh folder. Ray
is started before the clock starts and stopped after it, so the figures are the cells'
throughput, not Ray's start-up (reported apart). Rows of every run are compared with the
first: the same seed gives the same chart wherever it ran.
Parallel efficiency = (cells/min on n CPUs) / (n x cells/min on 1 CPU).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Callable, Optional

from spreadgym.agents.chart.runner import connect_ray, end_session, run_chart
from spreadgym.agents.chart.spec import make_spec

SCALE_CHART = dict(scene="paper", fertilizers="all", widths="3:6:0.5", budget=48, granules=2048, verify_runs=2,
                   objective="nominal")  # the cells the figures in docs/charts.md were measured with


def _local(workers: int):
    connect_ray(workers, None)
    return end_session


def _three_nodes():
    import ray
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
    for _ in range(2):
        cluster.add_node(num_cpus=1)
    connect_ray(None, cluster.address)

    def stop():
        ray.shutdown()
        cluster.shutdown()
    return stop


CONFIGS = (("local Ray, 1 worker", 1, lambda: _local(1)),
           ("local Ray, 2 workers", 2, lambda: _local(2)),
           ("3-node cluster, 2 worker CPUs", 2, _three_nodes))


def _rows_without_wall(payload: dict) -> list[dict]:
    return [{k: v for k, v in row.items() if k != "wall_s"} for row in payload["rows"]]


def chart_scale_rows(repeats: int = 2, progress: Optional[Callable[[str], None]] = None,
                     chart: Optional[dict] = None, configs=CONFIGS) -> list[dict]:
    """One row per configuration of `configs` (name, worker CPUs, start function returning
    a stop function; the first is the 1-CPU baseline): median cells per minute over
    `repeats` runs (with the runs' range), parallel efficiency against the baseline's
    median, Ray start-up time and whether every run's chart equals the first one's.
    `chart` holds `make_spec` arguments (default SCALE_CHART)."""
    spec = make_spec(**(chart or SCALE_CHART))[0]
    first: Optional[list[dict]] = None
    rates: dict[str, list[float]] = {name: [] for name, _, _ in configs}
    starts: dict[str, list[float]] = {name: [] for name, _, _ in configs}
    same = dict.fromkeys(rates, True)
    for _ in range(repeats):  # configurations interleaved, so a drift in the machine's speed hits all alike
        for name, _, start in configs:
            t0 = time.perf_counter()
            stop = start()
            starts[name].append(time.perf_counter() - t0)
            try:
                with tempfile.TemporaryDirectory() as folder:
                    t0 = time.perf_counter()
                    result = run_chart(spec, Path(folder) / "chart", progress=False)
                    wall = time.perf_counter() - t0
            finally:
                stop()
            rates[name].append(60.0 * len(spec.cells) / wall)
            rows_now = _rows_without_wall(result.payload)
            first = first or rows_now
            same[name] = same[name] and rows_now == first
            if progress:
                progress(f"chart-scale: {name}: {rates[name][-1]:.2f} cells/min")
    rows = [{"configuration": name, "worker_cpus": cpus, "cells": len(spec.cells), "budget": spec.budget,
             "granules": spec.granules,
             "cells_per_min": statistics.median(rates[name]), "cells_per_min_low": min(rates[name]),
             "cells_per_min_high": max(rates[name]), "ray_start_s": statistics.median(starts[name]),
             "same_rows_as_first_run": same[name]} for name, cpus, _ in configs]
    single = rows[0]["cells_per_min"]
    for row in rows:
        row["parallel_efficiency"] = row["cells_per_min"] / (row["worker_cpus"] * single)
    return rows


def plot_chart_scale(rows: list[dict], path: Path) -> Path:
    """Bar chart of cells per minute per configuration, with the ideal line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
    names = [r["configuration"] for r in rows]
    rates = [r["cells_per_min"] for r in rows]
    errors = [[r["cells_per_min"] - r["cells_per_min_low"] for r in rows],
              [r["cells_per_min_high"] - r["cells_per_min"] for r in rows]]
    ax.bar(names, rates, yerr=errors, capsize=4, color="#4c78a8")
    ideal = [rows[0]["cells_per_min"] * r["worker_cpus"] for r in rows]
    ax.plot(names, ideal, "_", color="#c0392b", markersize=60, markeredgewidth=2, label="ideal (n x 1 worker)")
    for x, r in enumerate(rows):
        ax.text(x, r["cells_per_min"] / 2, f"efficiency\n{r['parallel_efficiency']:.2f}", ha="center",
                va="center", color="white")
    ax.set_ylabel("chart cells per minute")
    ax.set_title(f"{int(rows[0]['cells'])} chart cells (budget {int(rows[0]['budget'])}, "
                 f"{int(rows[0]['granules'])} granules)")
    ax.set_ylim(0, 1.15 * max(ideal + [r["cells_per_min_high"] for r in rows]))
    ax.legend(loc="upper left", markerscale=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
