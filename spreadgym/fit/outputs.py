"""What a fit hands over: the JSON, the fitted scene as YAML, the predicted pattern and
CV curve with their 90 % band, and a picture of measured against fitted.

The band: the fitted model at the estimate and at both ends of every key's profile
interval (each end a whole parameter point, the other keys at their profile optimum:
the corners of the 90 % region along every key), tray by tray and width by width the
lowest and highest of these. Each pattern is scaled to the measured trays by its own
fitted scale, so the band shows the shape's uncertainty in grams per tray.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path
from typing import Optional

import numpy as np
import yaml

from spreadgym.config.scene import Scene
from spreadgym.fit.likelihood import residuals
from spreadgym.fit.measured import MeasuredPattern, measured_pattern
from spreadgym.fit.run import FitResult
from spreadgym.fit.uncertainty import TRADE_OFF_CORRELATION
from spreadgym.spread import estimate, pattern
from spreadgym.spread.batch import run_batch


@dataclass(frozen=True)
class Prediction:
    """The fitted pattern (single pass, g per tray, scaled to the measured trays) and CV
    curve at the estimate, with the band over the interval ends."""

    center_m: np.ndarray  # (T,)
    mass_g: np.ndarray  # (T,) at the estimate
    mass_low_g: np.ndarray
    mass_high_g: np.ndarray
    widths_m: np.ndarray  # (W,) bout widths
    cv_percent: np.ndarray  # (W,)
    cv_low_percent: np.ndarray
    cv_high_percent: np.ndarray
    cv_percent_at_target: Optional[float]
    cv_band_at_target: tuple[float, float]
    effective_swath_m: float
    effective_swath_band_m: tuple[float, float]
    measured: MeasuredPattern  # the tray test's own pattern and CV curve on the same grid and widths


def predict(fit: FitResult) -> Prediction:
    """Simulate the estimate and the interval ends in one batch (the fit's granules and seed)."""
    units = [fit.space.unit(fit.estimate), *fit.interval_points]
    results = run_batch([fit.model.scene_at(u) for u in units], model=fit.model.model, ci=False)
    scales = [np.exp(residuals(fit.model.log_mass, fit.model.prediction(r), fit.catch_sd)[1]) for r in results]
    p = fit.scene.pattern
    reach = max(r.metrics.trays.count for r in results) // 2
    center = np.arange(-reach, reach + 1) * p.tray_width_m
    masses = np.zeros((len(results), center.size))
    for row, (result, scale) in zip(masses, zip(results, scales)):
        half = result.metrics.trays.count // 2
        row[reach - half: reach + half + 1] = result.metrics.trays.mass_kg * scale * 1e3
    head = results[0].metrics
    widths = head.curve_bout_width_m
    cvs = np.array([estimate.cv_curve(r.replicate_masses_kg, p.tray_width_m, p.driving, widths)[0] for r in results])
    at_target = [r.metrics.cv_percent_at_target for r in results]
    known = [c for c in at_target if c is not None]
    swaths = [pattern.swath_from_curve(widths, c, p.cv_threshold_percent) for c in cvs]
    measured = measured_pattern(fit.model.test, fit.scene, center, masses[0], widths)
    return Prediction(center, masses[0], masses.min(axis=0), masses.max(axis=0), widths, cvs[0], cvs.min(axis=0),
                      cvs.max(axis=0), head.cv_percent_at_target,
                      (min(known), max(known)) if known else (float("nan"), float("nan")),
                      head.effective_swath_m, (min(swaths), max(swaths)), measured)


def scene_yaml(fit: FitResult) -> str:
    """The fitted scene as a scene file (every key written out), headed by the fit."""
    scene: Scene = fit.fitted_scene
    lines = [f"# {scene.name} fitted to the tray test {fit.model.test.source}",
             "# estimates and 90 % profile-likelihood intervals:"]
    for key, e, lo, hi in zip(fit.space.keys, fit.estimate, fit.low, fit.high):
        state = "" if fit.identifiable[key] else " (not determined by the test)"
        lines.append(f"#   {key} = {e:.6g} [{lo:.6g}, {hi:.6g}]{state}")
    return "\n".join(lines) + "\n" + yaml.safe_dump(scene.model_dump(mode="json"), sort_keys=False)


def payload(fit: FitResult, prediction: Prediction, scene_path: Optional[Path]) -> dict:
    """The JSON of `spreadgym fit`."""
    keys = fit.space.keys
    corr = fit.correlation
    trade_offs = [{"keys": [keys[i], keys[j]], "correlation": float(corr[i, j])}
                  for i, j in combinations(range(len(keys)), 2) if abs(corr[i, j]) >= TRADE_OFF_CORRELATION]
    return {
        "scene": fit.scene.name,
        "trays_file": fit.model.test.source,
        "trays_used": fit.model.trays,
        "model": fit.model.model,
        "granules_per_evaluation": fit.model.scene.sim.granules,
        "evaluations": fit.model.evaluations,
        "parameters": {k: {"estimate": float(e), "low": float(lo), "high": float(hi)}
                       for k, e, lo, hi in zip(keys, fit.estimate, fit.low, fit.high)},
        "interval_level": 0.9,
        "search_ranges": {k: [float(lo), float(hi)] for k, lo, hi in zip(keys, fit.space.low, fit.space.high)},
        "interval_reaches_search_bound": {k: list(ends) for k, ends in zip(keys, fit.open_ends)},
        "estimate_at_search_bound": {k: edge for k, edge in zip(keys, fit.at_bound)},
        "identifiable": dict(fit.identifiable),
        "regime_switch": {k: float(v) for k, v in zip(keys, fit.regime_switch)},
        "trade_offs": trade_offs,
        "correlation": {k: {k2: float(corr[i, j]) for j, k2 in enumerate(keys)} for i, k in enumerate(keys)},
        "weakest_direction": dict(fit.weakest),
        "catch_noise_sd": fit.catch_sd,
        "simulation_sd": {k: float(v) for k, v in zip(keys, fit.simulation_sd)},
        "model_discrepancy_sd": {k: float(v) for k, v in zip(keys, fit.model_sd)},
        "discrepancy_points": fit.discrepancy_points,
        "cv_percent_at_target": prediction.cv_percent_at_target,
        "cv_percent_at_target_band": list(prediction.cv_band_at_target),
        "measured_cv_percent_at_target": prediction.measured.cv_percent_at_target,
        "measured_span_share": prediction.measured.spanned_share,
        "target_swath_m": fit.scene.pattern.target_swath_m,
        "driving": fit.scene.pattern.driving,
        "effective_swath_m": prediction.effective_swath_m,
        "effective_swath_band_m": list(prediction.effective_swath_band_m),
        "scene_yaml": None if scene_path is None else str(scene_path),
        "wall_s": fit.wall_s,
    }


OUTPUT_FILES = ("scene.yaml", "parameters.csv", "pattern.csv", "cv_curve.csv", "fit.png", "fit.json")


def write_outputs(fit: FitResult, prediction: Prediction, out: Path) -> dict:
    """Write the OUTPUT_FILES (scene.yaml, parameters.csv, pattern.csv, cv_curve.csv, fit.png
    and fit.json) into `out`; the JSON payload (its scene_yaml the written path)."""
    out.mkdir(parents=True, exist_ok=True)
    scene_path = out / "scene.yaml"
    scene_path.write_text(scene_yaml(fit), encoding="utf-8")
    data = payload(fit, prediction, scene_path)
    _write_csv(out / "parameters.csv", ["key", "estimate", "low", "high", "search_low", "search_high",
                                        "identifiable"],
               [[k, v["estimate"], v["low"], v["high"], *data["search_ranges"][k], data["identifiable"][k]]
                for k, v in data["parameters"].items()])
    _write_csv(out / "pattern.csv", ["x_m", "fitted_g", "low_g", "high_g"],
               zip(prediction.center_m, prediction.mass_g, prediction.mass_low_g, prediction.mass_high_g))
    measured = prediction.measured.cv_percent
    _write_csv(out / "cv_curve.csv", ["bout_width_m", "cv_percent", "low_percent", "high_percent", "measured_percent"],
               zip(prediction.widths_m, prediction.cv_percent, prediction.cv_low_percent, prediction.cv_high_percent,
                   [""] * prediction.widths_m.size if measured is None else measured))
    plot_fit(fit, prediction, out / "fit.png")
    (out / "fit.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    return data


def _write_csv(path: Path, header: list[str], rows) -> None:
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)


def plot_fit(fit: FitResult, prediction: Prediction, path: Path) -> None:
    """Two panels: measured trays against the fitted single pass (band: 90 % region), and
    the predicted CV curve with its band. Measured passes on other lanes are drawn in
    their own pass's frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax_pattern, ax_cv = fig.subplots(1, 2)
    test, p = fit.model.test, fit.scene.pattern
    w = p.tray_width_m
    ax_pattern.fill_between(prediction.center_m, prediction.mass_low_g, prediction.mass_high_g, step="mid",
                            color="tab:blue", alpha=0.25, label="90 % band")
    ax_pattern.step(prediction.center_m, prediction.mass_g, where="mid", color="tab:blue", label="fitted")
    for lane in np.unique(test.lane):
        rows = test.lane == lane
        local = test.x_m[rows] - lane * p.target_swath_m
        if p.driving == "back-and-forth" and lane % 2:
            local = -local
        ax_pattern.plot(local, test.mass_kg[rows] * 1e3, "o", ms=4, label=f"measured, pass {lane}")
    ax_pattern.set_xlabel(f"across the track (m), trays of {w:g} m")
    ax_pattern.set_ylabel("mass per tray (g)")
    ax_pattern.set_title(f"{fit.scene.name}: measured vs fitted single pass")
    ax_pattern.legend(fontsize=8)
    ax_cv.fill_between(prediction.widths_m, prediction.cv_low_percent, prediction.cv_high_percent,
                       color="tab:blue", alpha=0.25, label="90 % band")
    ax_cv.plot(prediction.widths_m, prediction.cv_percent, color="tab:blue", label="fitted")
    if prediction.measured.cv_percent is not None:
        ax_cv.plot(prediction.widths_m, prediction.measured.cv_percent, color="black", ls=":",
                   label="measured trays")
    ax_cv.axhline(p.cv_threshold_percent, color="grey", ls="--", lw=1, label=f"{p.cv_threshold_percent:g} %")
    ax_cv.set_xlabel(f"bout width (m), {p.driving}")
    ax_cv.set_ylabel("CV (%)")
    ax_cv.set_title("predicted CV curve")
    ax_cv.legend(fontsize=8)
    text = "\n".join(f"{k} = {e:.4g} [{lo:.4g}, {hi:.4g}]" + ("" if fit.identifiable[k] else " (not determined)")
                     for k, e, lo, hi in zip(fit.space.keys, fit.estimate, fit.low, fit.high))
    ax_pattern.text(0.01, 0.99, text, transform=ax_pattern.transAxes, va="top", fontsize=7)
    fig.savefig(path)
