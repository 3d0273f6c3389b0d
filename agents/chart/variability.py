"""The variability model of a robust chart cell (configs/chart_variability.yaml): the
model itself (draws, their scene overrides, the library of perturbed densities) is the
core's `spreadgym.spread.variability`; this module adds what a chart cell does with it.

A cell's draws are a scrambled Sobol set seeded from the cell's seed sequence, each with
its own granule seed, and every candidate of the cell is scored on the same draws
(common random numbers), so two candidates differ by their settings only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Optional, Union

import numpy as np

from spreadgym.config.resources import read_yaml
from spreadgym.errors import SpreadgymError
from spreadgym.spread.variability import (  # noqa: F401  (the chart's names for the model)
    FACTORS,
    OFFSETS,
    Draw,
    check_half_range,
    default_variability,
    draw_from_unit,
    draw_library,
    draw_name,
    perturbed,
)

COUNTS = {"draws": (2, 1024), "verify_draws": (2, 1024), "verify_runs_per_draw": (1, 8)}  # integers, ranges


def check_variability(given: Union[None, str, Path, Mapping[str, Any]]) -> dict:
    """The defaults with `given` (a mapping, or a YAML file with a `variability` section)
    over them; an unknown key or a value out of range is a SpreadgymError naming it."""
    merged = default_variability()
    if given is None:
        return merged
    if isinstance(given, (str, Path)):
        raw = read_yaml(Path(given))
        if not (isinstance(raw, dict) and isinstance(raw.get("variability"), dict)):
            raise SpreadgymError(f"--variability {given}: expected a mapping under 'variability:'")
        given = raw["variability"]
    for key, value in given.items():
        where = f"variability.{key}"
        if key not in merged:
            raise SpreadgymError(f"{where}: unknown key; known: {', '.join(merged)}")
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if key in COUNTS:
            low, high = COUNTS[key]
            if not (number and float(value).is_integer() and low <= value <= high):
                raise SpreadgymError(f"{where}: {value!r} is out of range; allowed an integer in [{low}, {high}]")
            value = int(value)
        elif key == "quantile":
            if not (number and 0.5 <= value < 1.0):
                raise SpreadgymError(f"{where}: {value!r} is out of range; allowed [0.5, 1)")
        else:
            value = check_half_range(where, key, value)
        merged[key] = value
    return merged


def child(seq: np.random.SeedSequence, i: int) -> np.random.SeedSequence:
    """The `i`-th child of `seq` (what `seq.spawn(n)[i]` gives a fresh sequence), without changing `seq`."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, i), pool_size=seq.pool_size)


def draws(variability: dict, count: int, seq: np.random.SeedSequence) -> list[Draw]:
    """`count` draws: a scrambled Sobol set over the half-ranges and one granule seed each."""
    from scipy.stats import qmc

    points_seq, seeds_seq = child(seq, 0), child(seq, 1)
    names = FACTORS + OFFSETS
    u = qmc.Sobol(len(names), scramble=True, seed=np.random.default_rng(points_seq)).random(count)
    seeds = seeds_seq.generate_state(count)
    return [draw_from_unit(variability, row, k, seeds[k]) for k, row in enumerate(2.0 * u - 1.0)]


def quantile(values, q: float) -> float:
    """The `q` quantile (linear between order statistics) of `values`."""
    return float(np.quantile(np.asarray(values, dtype=float), q))


def bootstrap_se(values, q: float, seq: np.random.SeedSequence, resamples: int = 1000) -> Optional[float]:
    """Standard error of the `q` quantile of `values`, by a seeded bootstrap."""
    values = np.asarray(values, dtype=float)
    if values.size < 2:
        return None
    rng = np.random.default_rng(seq)
    picks = rng.integers(0, values.size, (resamples, values.size))
    return float(np.std(np.quantile(values[picks], q, axis=1), ddof=1))

