"""Speed against accuracy of every spinner model, measured against converged references.

For each scene with a stored full-model reference (`studies.references`), each model is
run at a few granule counts (and, for pymunk, time steps) on `seeds` seeds that share no
granule sample with the reference. Accuracy is the root-mean-square error of one run's
CV at the target against the converged full-model CV (bias and sampling noise both
count: they are what one evaluation costs or buys) and the share of seeds whose
effective swath equals the converged one; cost is the median wall time of one run.
"""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from spreadgym.config.materials import load_library
from spreadgym.config.scene import Scene, scene_with
from spreadgym.errors import ConfigError
from spreadgym.physics.numerics import choose_time_step
from spreadgym.spread.pipeline import run_scene
from spreadgym.studies.estimate_bench import FIRST_TARGET_SEED
from spreadgym.studies.references import load_references, reference_family

SCENES = ("paper", "field", "paper-deflectors")
COUNTS = (1024, 4096, 16384)
DT_FACTORS = (2.0, 1.0)  # x the pymunk model's automatic step (the references use 1.0)
# Seeds per point: the RMSE of 3 seeds is uncertain by about +-40 %, of 16 by about +-18 %;
# the stepped models get few because each of their runs costs seconds to a minute.
SEEDS = {"pymunk": 3, "spring-damper": 3}
DEFAULT_SEEDS = 16


def automatic_dt(scene: Scene) -> float:
    """The pymunk model's automatic step for this scene (smallest granule radius), s."""
    fertilizer = load_library().fertilizer_of(scene)
    return choose_time_step(scene, 0.5 * min(fertilizer.size.min_m, fertilizer.size.d50_m)).dt_s


def plans(models: tuple[str, ...]) -> list[tuple[str, int, Optional[float]]]:
    """(model, granules, dt factor or None) for every point of the chart."""
    out = []
    for model in models:
        for n in COUNTS:
            factors = DT_FACTORS if model == "pymunk" else (None,)
            out += [(model, n, f) for f in factors if not (model == "pymunk" and n > 4096 and f != 1.0)]
    return out


def speed_accuracy_rows(references_dir: Path, scenes=SCENES, models=("compiled", "analytic", "pymunk", "spring-damper"),
                        seeds: Optional[int] = None, progress: Callable[[str], None] = lambda _: None) -> list[dict]:
    """One row per scene, model, granule count and step: CV RMSE and swath agreement, wall time
    (`seeds` per point; default SEEDS for the stepped models, DEFAULT_SEEDS otherwise)."""
    references = load_references(references_dir, "pymunk")
    family = reference_family()
    rows = []
    for name in scenes:
        if name not in references:
            raise ConfigError("references", f"no pymunk reference for {name!r} in {references_dir}; "
                                            "run the references section first")
        ref = references[name]
        for model, n, factor in plans(models):
            progress(f"{name}: {model}, {n} granules" + (f", dt x{factor:g}" if factor else ""))
            overrides = {"sim.granules": n}
            if factor is not None:
                overrides["sim.dt_s"] = factor * automatic_dt(family[name])
            cvs, swaths, walls, note = [], [], [], ""
            for seed in range(seeds or SEEDS.get(model, DEFAULT_SEEDS)):
                try:
                    m = run_scene(scene_with(family[name], {**overrides, "sim.seed": FIRST_TARGET_SEED + seed}),
                                  model=model).metrics
                except ConfigError as refused:  # a step beyond a stability limit: the guard said no
                    note = f"refused: {refused}"
                    break
                cvs.append(m.cv_percent_at_target if m.cv_percent_at_target is not None else 100.0)
                swaths.append(m.effective_swath_m)
                walls.append(m.wall_s)
            errors = np.array(cvs) - ref["cv_percent_at_target"]
            rows.append({
                "scene": name, "model": model, "granules": n, "dt_factor": factor or 1.0, "seeds": len(cvs),
                "converged_cv_percent": ref["cv_percent_at_target"],
                "cv_rmse_pp": float(np.sqrt(np.mean(errors ** 2))) if cvs else float("nan"),
                "cv_bias_pp": float(errors.mean()) if cvs else float("nan"),
                "swath_equal_share": (float(np.mean([s == ref["effective_swath_m"] for s in swaths]))
                                      if cvs else float("nan")),
                "wall_median_s": statistics.median(walls) if walls else float("nan"),
                "note": note,
            })
    return rows


def pareto_mask(cost: np.ndarray, error: np.ndarray) -> np.ndarray:
    """True for points no other point beats on both cost and error (NaN never on the front)."""
    ok = np.isfinite(cost) & np.isfinite(error)
    front = np.zeros(cost.shape, dtype=bool)
    for i in np.flatnonzero(ok):
        beaten = ok & (cost <= cost[i]) & (error <= error[i]) & ((cost < cost[i]) | (error < error[i]))
        front[i] = not beaten.any()
    return front


STYLES = {"analytic": ("o", "tab:green"), "pymunk": ("s", "tab:blue"), "spring-damper": ("^", "tab:red"),
          "compiled": ("D", "tab:purple")}


def plot_speed_accuracy(rows: list[dict], path) -> None:
    """CV error (RMSE against the converged full model) against wall time per run, per scene."""
    from matplotlib.figure import Figure

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig = Figure(figsize=(5.0 * len(scenes), 4.2), dpi=100)
    axes = fig.subplots(1, len(scenes), squeeze=False)[0]
    for ax, scene in zip(axes, scenes):
        data = [r for r in rows if r["scene"] == scene and np.isfinite(r["wall_median_s"])]
        cost = np.array([r["wall_median_s"] for r in data])
        err = np.array([r["cv_rmse_pp"] for r in data])
        for model, (marker, colour) in STYLES.items():
            pick = np.array([r["model"] == model for r in data])
            if pick.any():
                ax.scatter(cost[pick], err[pick], marker=marker, color=colour, label=model, zorder=3)
        front = pareto_mask(cost, err)
        order = np.argsort(cost[front])
        ax.step(cost[front][order], err[front][order], where="post", color="k", lw=1, alpha=0.6,
                label="Pareto front", zorder=2)
        for r, c, e in zip(data, cost, err):
            label = f"{r['granules']}" + (f" x{r['dt_factor']:g}" if r["model"] == "pymunk" else "")
            ax.annotate(label, (c, e), fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.axhline(0.5, color="grey", ls=":", lw=0.8, label="0.5 pp")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per run (s, median)")
        ax.set_ylabel("CV error against the converged full model (pp, RMS)")
        ax.set_title(f"{scene} (converged {data[0]['converged_cv_percent']:.2f} %)", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Speed against accuracy (labels: granules, and dt x automatic step for pymunk)")
    fig.tight_layout()
    fig.savefig(path)
