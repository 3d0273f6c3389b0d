"""How closely a fast spinner model reproduces the full (pymunk) model, scene by scene.

Two kinds of evidence, both against the full model:
- the converged references (`studies.references`, many granules pooled per model):
  the CV at the target with its standard error, the effective swath, the pattern and
  the CV curve;
- one large departure sample per model on the same granules (same seed), so the
  differences are the models' and not sampling: where around the disc granules leave
  (azimuth histogram, 36 bins, machine frame), the time on the spinner, the speed and
  the exit angle (velocity against the outward radius) at the rim.

The targets are those of the faithful-fast-model work: CV within 0.5 pp, the same
effective swath, a total-variation distance of the azimuth histograms <= 0.05 and the
median time on the spinner within 3 %.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from spreadgym.config.scene import scene_with
from spreadgym.physics.departure import Departure
from spreadgym.spread.pipeline import run_scene
from spreadgym.studies.references import load_references, reference_family

AZIMUTH_BINS = 36
SAMPLE_GRANULES = 16384
SAMPLE_SEED = 7  # shares no granules with the references (seeds 0..runs-1)
TARGET_CV_PP = 0.5
TARGET_AZIMUTH_TV = 0.05
TARGET_TIME_RATIO = 0.03


def azimuth_histogram(departure: Departure) -> np.ndarray:
    """Share of departed granules per azimuth bin (36 bins over -pi..pi, machine frame)."""
    gone = departure.departed
    angle = np.arctan2(departure.position_m[gone, 1], departure.position_m[gone, 0])
    counts, _ = np.histogram(angle, bins=AZIMUTH_BINS, range=(-np.pi, np.pi))
    return counts / max(counts.sum(), 1)


def total_variation(p: np.ndarray, q: np.ndarray) -> float:
    """Total-variation distance of two histograms that each sum to 1."""
    return 0.5 * float(np.abs(p - q).sum())


def exit_angle_rad(departure: Departure) -> np.ndarray:
    """Angle of the velocity against the outward radius at the rim, rad (departed granules)."""
    gone = departure.departed
    x, v = departure.position_m[gone], departure.velocity_m_s[gone]
    radial = np.einsum("ij,ij->i", x, v)
    tangential = x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]
    return np.arctan2(tangential, radial)


def departure_sample(scene, model: str, granules: int = SAMPLE_GRANULES, seed: int = SAMPLE_SEED) -> Departure:
    """Departures of one large run of `scene` on `model`."""
    return run_scene(scene_with(scene, {"sim.granules": granules, "sim.seed": seed}), model=model, ci=False).departure


def fidelity_rows(references_dir: Path, model: str = "compiled", full: str = "pymunk",
                  granules: int = SAMPLE_GRANULES, figures: Path | None = None,
                  progress: Callable[[str], None] = lambda _: None) -> list[dict]:
    """One row per family scene that has both converged references; a figure per scene in
    `figures` when given."""
    fast_refs, full_refs = load_references(references_dir, model), load_references(references_dir, full)
    family = reference_family()
    rows = []
    for name, scene in family.items():
        if name not in fast_refs or name not in full_refs:
            continue
        progress(f"fidelity {name}: {model} against {full}, {granules} granules")
        fast, slow = departure_sample(scene, model, granules), departure_sample(scene, full, granules)
        f_ref, p_ref = fast_refs[name], full_refs[name]
        cv_diff = f_ref["cv_percent_at_target"] - p_ref["cv_percent_at_target"]
        se = float(np.hypot(f_ref["cv_standard_error_percent"], p_ref["cv_standard_error_percent"]))
        tf, tp = fast.time_s[fast.departed], slow.time_s[slow.departed]
        tv = total_variation(azimuth_histogram(fast), azimuth_histogram(slow))
        time_ratio = float(np.median(tf) / np.median(tp))
        rows.append({
            "scene": name,
            "cv_fast_percent": f_ref["cv_percent_at_target"], "cv_full_percent": p_ref["cv_percent_at_target"],
            "cv_diff_pp": cv_diff, "cv_diff_se_pp": se,
            "swath_fast_m": f_ref["effective_swath_m"], "swath_full_m": p_ref["effective_swath_m"],
            "azimuth_tv": tv, "median_time_ratio": time_ratio,
            "speed_ratio": float(np.mean(np.hypot(*fast.velocity_m_s[fast.departed].T))
                                 / np.mean(np.hypot(*slow.velocity_m_s[slow.departed].T))),
            "exit_angle_diff_deg": float(np.degrees(np.mean(exit_angle_rad(fast)) - np.mean(exit_angle_rad(slow)))),
            "departed_fast": float(fast.departed.mean()), "departed_full": float(slow.departed.mean()),
            "meets_cv": abs(cv_diff) <= TARGET_CV_PP,
            "meets_swath": f_ref["effective_swath_m"] == p_ref["effective_swath_m"],
            "meets_azimuth": tv <= TARGET_AZIMUTH_TV, "meets_time": abs(time_ratio - 1.0) <= TARGET_TIME_RATIO,
        })
        if figures is not None:
            plot_scene(Path(figures) / f"{name}.png", name, (model, fast, f_ref), (full, slow, p_ref))
    return rows


def plot_scene(path: Path, name: str, *runs) -> None:
    """Six panels, fast and full overlaid: azimuth, time on the spinner, speed, exit angle,
    the converged single-pass pattern and the CV curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5))
    for (label, dep, ref), colour in zip(runs, ("tab:orange", "tab:blue")):
        gone = dep.departed
        edges = np.linspace(-180, 180, AZIMUTH_BINS + 1)
        axes[0, 0].stairs(100 * azimuth_histogram(dep), edges, color=colour, label=label)
        axes[0, 1].hist(1e3 * dep.time_s[gone], bins=60, histtype="step", density=True, color=colour)
        axes[0, 2].hist(np.hypot(*dep.velocity_m_s[gone].T), bins=60, histtype="step", density=True, color=colour)
        axes[1, 0].hist(np.degrees(exit_angle_rad(dep)), bins=60, histtype="step", density=True, color=colour)
        trays = ref["trays"]
        mass = np.asarray(trays["mass_kg"], dtype=float)
        axes[1, 1].step(trays["center_m"], mass / mass.sum(), where="mid", color=colour)
        curve = ref["cv_curve"]
        cv = [np.nan if c is None else c for c in curve["cv_percent"]]
        axes[1, 2].plot(curve["bout_width_m"], cv, color=colour,
                        label=f"{label}: {ref['cv_percent_at_target']:.2f} ± {ref['cv_standard_error_percent']:.2f} %")
    axes[1, 2].axhline(ref["cv_threshold_percent"], color="grey", lw=0.8, ls="--")
    axes[1, 2].axvline(ref["target_swath_m"], color="grey", lw=0.8, ls=":")
    titles = [("departure azimuth (deg)", "share (%)"), ("time on the spinner (ms)", "density"),
              ("speed at the rim (m/s)", "density"), ("exit angle from the radius (deg)", "density"),
              ("tray position (m)", "share of the pass"), ("bout width (m)", "CV at that width (%)")]
    for ax, (xlabel, ylabel) in zip(axes.flat, titles):
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    axes[0, 0].legend()
    axes[1, 2].legend(fontsize=8)
    axes[1, 2].set_ylim(0, 40)
    fig.suptitle(f"{name}: fast against full, converged")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def fidelity_markdown(rows: list[dict], model: str = "compiled", full: str = "pymunk") -> str:
    """The rows as a markdown table with the targets met marked."""
    head = ["scene", f"CV {model} (%)", f"CV {full} (%)", "diff ± SE (pp)", "swath (m)", "azimuth TV",
            "median time ratio", "speed ratio", "exit angle diff (deg)"]
    lines = [f"# Fidelity: {model} against {full}\n",
             f"Targets: |CV diff| <= {TARGET_CV_PP} pp, same effective swath, azimuth TV <= {TARGET_AZIMUTH_TV}, "
             f"median time within {100 * TARGET_TIME_RATIO:g} %. A value missing its target is marked ✗.\n",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        def mark(ok):
            return "" if ok else " ✗"
        swath = (f"{r['swath_fast_m']:g}" if r["meets_swath"] else f"{r['swath_fast_m']:g} vs {r['swath_full_m']:g} ✗")
        lines.append("| " + " | ".join([
            r["scene"], f"{r['cv_fast_percent']:.2f}", f"{r['cv_full_percent']:.2f}",
            f"{r['cv_diff_pp']:+.2f} ± {r['cv_diff_se_pp']:.2f}{mark(r['meets_cv'])}", swath,
            f"{r['azimuth_tv']:.3f}{mark(r['meets_azimuth'])}", f"{r['median_time_ratio']:.3f}{mark(r['meets_time'])}",
            f"{r['speed_ratio']:.3f}", f"{r['exit_angle_diff_deg']:+.2f}"]) + " |")
    return "\n".join(lines) + "\n"
