"""Spin in flight (`flight.magnus`): what it costs, how exact it is, and what it changes.

Behind docs/magnus.md and `spreadgym bench --only magnus`. Three measurements:
- cost: flight of one run's launch states (compiled model, paper and field scenes) with
  the lift on against off, interleaved repeats of process time, median and quartiles;
- accuracy: landing points of a scrambled Sobol sample of launch states against a
  DOP853 solve (rtol 1e-10) of the same equations;
- effect: how far the lift moves each granule's landing point (the same granules with
  it on and off), and the converged CV at the target swath (pooled runs) for free
  rotation with the lift off and on and for locked rotation (no spin: on = off exactly).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from scipy.stats import qmc

from spreadgym.config.scene import Flight, load_scene, scene_with
from spreadgym.spread.flight import fly, reference_landing
from spreadgym.spread.pipeline import run_scene
from spreadgym.spread.reference import pool_runs, reference_from

SCENES = ("paper", "field")
MODEL = "compiled"
TIE_SE = 2.0  # a CV difference under this many standard errors is a tie


def _row(measure: str, scene: str, case: str, value: float, spread: Optional[float], unit: str) -> dict:
    return {"measure": measure, "scene": scene, "case": case, "value": value, "spread": spread, "unit": unit}


def _launch(result):
    """fly()'s arguments and the spins of one run's flying granules."""
    launch, flying = result.launch, result.landed
    args = (launch.position_m[flying], result.scene.spinner.height_m + launch.height_m[flying],
            np.column_stack([launch.velocity_m_s[flying], launch.vertical_velocity_m_s[flying]]),
            result.granules.diameter_m[flying], result.granules.density_kg_m3)
    return args, launch.spin_rad_s[flying]


def cost_rows(granules: int = 8192, repeats: int = 15) -> list[dict]:
    """Process time of one run's flight, lift on over lift off (interleaved repeats)."""
    rows = []
    for name in SCENES:
        scene = load_scene(name, {"sim.granules": granules})
        args, spin = _launch(run_scene(scene, model=MODEL))
        on = scene.flight.model_copy(update={"magnus": True})
        off_s, on_s = [], []
        for _ in range(repeats):
            for flight, times in ((scene.flight, off_s), (on, on_s)):
                start = time.process_time()
                fly(*args, flight, spin_rad_s=spin)
                times.append(time.process_time() - start)
        ratios = np.array(on_s) / np.array(off_s)
        q1, q3 = np.percentile(ratios, [25, 75])
        rows += [_row("flight time, lift off", name, f"{spin.size} granules", statistics.median(off_s), None, "s"),
                 _row("flight time, lift on", name, f"{spin.size} granules", statistics.median(on_s), None, "s"),
                 _row("cost ratio on/off (median; spread = IQR)", name, f"{repeats} repeats",
                      statistics.median(on_s) / statistics.median(off_s), float(q3 - q1), "x")]
    return rows


def accuracy_rows(m: int = 8, seed: int = 0) -> list[dict]:
    """Largest landing-point distance from the tight solve over 2^m Sobol launch states
    (speed 8-32 m/s, elevation -10..25 deg, spin 2000-17000 rad/s either sense, 2-4 mm,
    877-1734 kg/m3, 0.8-0.9 m: the paper and field scenes' launches), per flight case."""
    u = qmc.Sobol(8, scramble=True, seed=seed).random_base2(m)
    speed, el, az = 8.0 + 24.0 * u[:, 0], np.radians(-10.0 + 35.0 * u[:, 1]), 2.0 * np.pi * u[:, 2]
    spin = np.where(u[:, 3] < 0.5, -1.0, 1.0) * (2000.0 + 15000.0 * u[:, 4])
    args = (0.3 * np.stack([np.cos(az), np.sin(az)], axis=1), 0.8 + 0.1 * u[:, 7],
            np.stack([speed * np.cos(el) * np.cos(az), speed * np.cos(el) * np.sin(az), speed * np.sin(el)], axis=1),
            2e-3 + 2e-3 * u[:, 5], 877.0 + 857.0 * u[:, 6])
    rows = []
    for case, flight in (("still air", Flight(magnus=True)),
                         ("4 m/s forward, wind (5, -3) m/s", Flight(magnus=True, forward_speed_m_s=4.0,
                                                                   wind_m_s=(5.0, -3.0)))):
        error = np.hypot(*(fly(*args, flight, spin_rad_s=spin).position_m
                           - reference_landing(*args, flight, spin_rad_s=spin).position_m).T)
        rows.append(_row(f"landing error vs solve_ivp, max over {2 ** m}", "launch sample", case,
                         1e3 * float(error.max()), 1e3 * float(np.median(error)), "mm (spread = median)"))
    return rows


def landing_shifts(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Landing points (N, 2) of one run of the scene with the lift off and on (same granules)."""
    scene = load_scene(name)
    args, spin = _launch(result := run_scene(scene, model=MODEL))
    on = fly(*args, scene.flight.model_copy(update={"magnus": True}), spin_rad_s=spin).position_m
    return result.landing.position_m, on


def effect_rows(runs: int = 64, progress: Optional[Callable[[str], None]] = None) -> tuple[list[dict], dict]:
    """Landing shifts and converged CVs per scene; also what the figure draws: the pooled
    references by (scene, case) and the landing points off/on by scene."""
    rows, drawn = [], {}
    for name in SCENES:
        off, on = landing_shifts(name)
        drawn[name] = (off, on)
        shift = np.hypot(*(on - off).T)
        across = on[:, 0] - off[:, 0]
        rows += [_row("landing shift |on - off|, median", name, "free", float(np.median(shift)),
                      float(np.percentile(shift, 90)), "m (spread = 90th pct)"),
                 _row("landing shift across the track, mean", name, "free", float(across.mean()),
                      float(across.std(ddof=1)), "m (spread = s.d.)")]
        base = load_scene(name)
        cases = {"free, lift off": {}, "free, lift on": {"flight.magnus": True},
                 "locked (no spin: on = off)": {"granule.rotation": "locked"}}
        for case, overrides in cases.items():
            if progress:
                progress(f"magnus: {name}, {case}, {runs} runs")
            scene = scene_with(base, overrides) if overrides else base
            reference = reference_from(scene, pool_runs(scene, runs, model=MODEL))
            drawn[(name, case)] = reference
            rows.append(_row(f"CV at {scene.pattern.target_swath_m:g} m ({scene.pattern.driving})", name, case,
                             reference.at_target.cv_percent, reference.at_target.standard_error_percent,
                             "% (spread = SE)"))
        a, b = drawn[(name, "free, lift off")].at_target, drawn[(name, "free, lift on")].at_target
        diff, se = b.cv_percent - a.cv_percent, float(np.hypot(a.standard_error_percent, b.standard_error_percent))
        rows.append(_row("CV change, lift on - off", name, "tie" if abs(diff) < TIE_SE * se else "differs",
                         diff, se, "pp (spread = SE, conservative)"))
    return rows, drawn


def plot_effect(drawn: dict, path: Path) -> None:
    """Tray patterns (free off/on, locked) and landing points (free off/on) per scene."""
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 8), dpi=100)
    axes = fig.subplots(2, len(SCENES))
    styles = {"free, lift off": ("tab:blue", "-"), "free, lift on": ("tab:red", "-"),
              "locked (no spin: on = off)": ("grey", "--")}
    for col, name in enumerate(SCENES):
        ax = axes[0, col]
        for case, (colour, style) in styles.items():
            ref = drawn[(name, case)]
            share = ref.trays.mass_kg / ref.trays.mass_kg.sum()
            ax.step(ref.trays.center_m, 100 * share, where="mid", color=colour, ls=style,
                    label=f"{case}: CV {ref.at_target.cv_percent:.1f} ± {ref.at_target.standard_error_percent:.1f} %")
        ax.set_title(f"{name}: single-pass pattern ({ref.pooled.granules} granules per case)", fontsize=10)
        ax.set_xlabel("across the track x (m)")
        ax.set_ylabel("mass per 0.5 m tray (%)")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        off, on = drawn[name]
        pick = np.random.default_rng(0).choice(off.shape[0], size=min(400, off.shape[0]), replace=False)
        ax = axes[1, col]
        ax.add_collection(LineCollection(np.stack([off[pick], on[pick]], axis=1), colors="0.6", linewidths=0.5))
        ax.scatter(off[pick, 0], off[pick, 1], s=3, color="tab:blue", label="lift off")
        ax.scatter(on[pick, 0], on[pick, 1], s=3, color="tab:red", label="lift on (same granule, joined)")
        ax.set_aspect("equal")
        ax.set_title(f"{name}: landing points of 400 granules, plan view (drive +y)", fontsize=10)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.legend(fontsize=7, markerscale=4)
        ax.grid(alpha=0.3)
    fig.suptitle("Magnus lift in flight: free rotation with the lift off and on, locked rotation", fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)


def magnus_rows(figure: Path, runs: int = 64, repeats: int = 15,
                progress: Optional[Callable[[str], None]] = None) -> list[dict]:
    """Every measurement of this study as rows; writes the figure."""
    effect, drawn = effect_rows(runs, progress)
    plot_effect(drawn, figure)
    return cost_rows(repeats=repeats) + accuracy_rows() + effect
