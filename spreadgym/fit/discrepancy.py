"""The compiled model's own difference from the full model, carried into the intervals.

The fit simulates with the compiled model; the full model (pymunk) stands for the
spreader. At the same parameters the two differ by a small smooth pattern change (a
shift or stretch of a few tenths of a per cent of the mass per tray), and a smooth change
looks like a parameter change (measured on the shipped scenes: a move of 0.001-0.008 in
vane friction and restitution, s.d., against a simulation s.d. of about 0.007; docs/fit.md).
A per-tray variance in the
likelihood cannot carry it (a relative variance the same on every tray only adds to
sigma^2, and sigma is fitted from the residuals: the intervals stay as they were), so it
is carried the way the simulation's own error is: measured discrepancies are moved
through the Gauss-Newton step at the fit's estimate, and their root-mean-square move,
less its Monte Carlo part, is the model's s.d. per key, added to the interval in
quadrature (`uncertainty.widened`).

A discrepancy: log tray masses of the full model minus those of the compiled model at
the same parameters, granules and seed (paired: the same granules, so their sampling
noise mostly cancels), per tray where both caught something in every leave-one-out
replicate set; its Monte Carlo variance from the delete-one-replicate jackknife over the
paired replicates. They are measured at calibration points drawn over the search box
(`sobol_points`, a Sobol sequence of its own seed and seeds of their own, never
the bench's truths) for each shipped single-disc scene, fertilizer and granule rotation,
and stored in `discrepancy.csv` beside this module (`spreadgym.studies.fit_discrepancy`
writes it). A fit of another scene has no stored discrepancy and reports none.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np
from scipy.stats import qmc

from spreadgym.config.scene import Scene, scene_with
from spreadgym.fit.synthetic import SimulatedPass, simulated_pass

STORED = Path(__file__).with_name("discrepancy.csv")
CALIBRATION_SEED = 2_000_003  # sim.seed of the first calibration point (the next ones count up)
CALIBRATION_GRANULES = 8192
CALIBRATION_REPLICATES = 16
_ON_GRID = 1e-6  # a tray centre this close (in tray widths) to a grid tray is on it


@dataclass(frozen=True)
class Discrepancy:
    """Measured full-minus-compiled log tray masses at C calibration points of one scene."""

    x_m: list[np.ndarray]  # per point: the tray centres (m) where it is measured
    delta: list[np.ndarray]  # per point: log(full) - log(compiled) there
    variance: list[np.ndarray]  # per point: its Monte Carlo variance

    @property
    def points(self) -> int:
        return len(self.delta)

    def on_trays(self, x_m: np.ndarray, width_m: float) -> tuple[np.ndarray, np.ndarray]:
        """(C, n) discrepancies and their variances on trays centred at `x_m` (any layout):
        a tray on the calibration's grid (multiples of `width_m`) takes its tray's values,
        one between two grid trays the linear interpolation of theirs; 0 where a point did
        not measure a tray it needs (a tray the calibration runs left empty)."""
        x_m = np.asarray(x_m, float)
        delta, variance = np.zeros((self.points, x_m.size)), np.zeros((self.points, x_m.size))
        grid = x_m / width_m
        low = np.floor(grid + _ON_GRID)
        weight = np.clip(grid - low, 0.0, 1.0)
        weight[weight <= _ON_GRID] = 0.0
        for c, (x, d, v) in enumerate(zip(self.x_m, self.delta, self.variance)):
            index = {int(i): k for k, i in enumerate(np.rint(x / width_m))}
            for i, (tray, share) in enumerate(zip(low.astype(int), weight)):
                ends = [(tray, 1.0 - share)] + ([(tray + 1, share)] if share > 0 else [])
                if all(t in index for t, _ in ends):
                    delta[c, i] = sum(s * d[index[t]] for t, s in ends)
                    variance[c, i] = sum(s * s * v[index[t]] for t, s in ends)
        return delta, variance


def sobol_points(ranges: Mapping[str, tuple[float, float]], count: int, seed: int = 1) -> list[dict]:
    """`count` points over `ranges` (key -> (low, high)) from a scrambled Sobol sequence of
    `seed`, each value rounded to 4 decimals (the calibration points; the fit bench's truths)."""
    m = int(np.ceil(np.log2(max(count, 1))))
    units = qmc.Sobol(len(ranges), scramble=True, seed=seed).random_base2(m)[:count]
    return [{key: round(float(lo + u * (hi - lo)), 4) for (key, (lo, hi)), u in zip(ranges.items(), unit)}
            for unit in units]


def measure(scene: Scene, point: Mapping[str, float], seed: int, granules: int = CALIBRATION_GRANULES,
            cache: Optional[Path] = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tray centres m, discrepancy, its variance) of `scene` at `point` (see the module's docstring)."""
    paired = scene_with(scene, {**point, "sim.granules": granules, "sim.seed": seed,
                                "sim.replicates": CALIBRATION_REPLICATES})
    try:
        return paired_log_ratio(simulated_pass(paired, "pymunk", cache), simulated_pass(paired, "compiled", cache))
    except ValueError as exc:
        raise ValueError(f"discrepancy of {scene.name} at {dict(point)}: {exc}") from None


def paired_log_ratio(top: SimulatedPass, bottom: SimulatedPass) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tray centres m, log(top) - log(bottom) of the tray shares, its jackknife variance) of
    two passes with the same replicates (paired seeds), on the trays where both caught
    something with any one replicate left out."""
    width = top.width_m
    if bottom.width_m != width or top.replicate_kg.shape[0] != bottom.replicate_kg.shape[0]:
        raise ValueError("the two passes differ in tray width or replicates")
    lo = int(round(min(top.center_m[0], bottom.center_m[0]) / width))
    hi = int(round(max(top.center_m[-1], bottom.center_m[-1]) / width))
    grids = []
    for run in (top, bottom):
        grid = np.zeros((run.replicate_kg.shape[0], hi - lo + 1))
        grid[:, np.rint(run.center_m / width).astype(int) - lo] = run.replicate_kg
        grids.append(grid)
    k = grids[0].shape[0]
    left_out = [g.sum(axis=0)[None, :] - g for g in grids]  # (K, T): replicate k left out
    kept = np.all(left_out[0] > 0, axis=0) & np.all(left_out[1] > 0, axis=0)
    if k < 2 or not kept.any():
        raise ValueError("no tray caught granules in both passes with every replicate left out")

    def log_ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        share = [np.log(m[..., kept] / m.sum(axis=-1, keepdims=True)) for m in (a, b)]
        return share[0] - share[1]

    delta = log_ratio(grids[0].sum(axis=0), grids[1].sum(axis=0))
    jack = log_ratio(left_out[0], left_out[1])
    variance = (k - 1) / k * np.sum((jack - jack.mean(axis=0)) ** 2, axis=0)
    return (np.arange(lo, hi + 1) * width)[kept], delta, variance


def scene_label(scene: Scene) -> tuple[str, str, str]:
    """What a stored discrepancy is keyed by: scene name, fertilizer, granule rotation."""
    return scene.name, scene.fertilizer_name, scene.granule.rotation


def stored_discrepancy(scene: Scene, path: Path = STORED) -> Optional[Discrepancy]:
    """The stored discrepancy of `scene`'s name, fertilizer and rotation; None when there is none."""
    if not path.exists():
        return None
    label = scene_label(scene)
    by_point: dict[str, list[tuple[float, float, float]]] = {}
    with path.open(encoding="utf-8") as handle:
        for row in csv.DictReader(line for line in handle if not line.startswith("#")):
            if (row["scene"], row["fertilizer"], row["rotation"]) == label:
                by_point.setdefault(row["point"], []).append(
                    (float(row["x_m"]), float(row["delta"]), float(row["delta_var"])))
    if not by_point:
        return None
    columns = [np.array(rows).T for rows in by_point.values()]
    return Discrepancy([c[0] for c in columns], [c[1] for c in columns], [c[2] for c in columns])


def write_discrepancy(path: Path, rows: Sequence[Mapping[str, object]], header: str) -> None:
    """Write measured rows (scene, fertilizer, rotation, point, x_m, delta, delta_var) under `header` comments."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", encoding="utf-8", newline="") as handle:
        for line in header.splitlines():
            handle.write(f"# {line}\n")
        writer = csv.DictWriter(handle, ["scene", "fertilizer", "rotation", "point", "x_m", "delta", "delta_var"])
        writer.writeheader()
        writer.writerows(rows)
