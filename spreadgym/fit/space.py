"""The fitted keys and their search ranges (`--fit KEY=LO:HI[,KEY=LO:HI ...]`).

The optimiser works in the unit cube: u_j in [0, 1] maps to LO_j + u_j (HI_j - LO_j),
each key in its own unit (as the scene file writes it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from spreadgym.config.base import brief
from spreadgym.config.scene import Scene, scene_with
from spreadgym.errors import ConfigError, SpreadgymError

MAX_KEYS = 8  # every key adds a profile (about 100 evaluations) and a dimension to the search
NOT_FITTED = ("sim.", "pattern.", "name", "description", "fertilizer")  # sampling, scoring and names: not physics


@dataclass(frozen=True)
class FitSpace:
    """Fitted dotted keys with their ranges (LO < HI)."""

    keys: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray

    @property
    def dims(self) -> int:
        return len(self.keys)

    def values(self, unit: Sequence[float]) -> np.ndarray:
        """Key values at unit-cube point `unit` (clipped into the cube)."""
        u = np.clip(np.asarray(unit, dtype=float), 0.0, 1.0)
        return self.low + u * (self.high - self.low)

    def unit(self, values: Sequence[float]) -> np.ndarray:
        return (np.asarray(values, dtype=float) - self.low) / (self.high - self.low)

    def overrides(self, unit: Sequence[float]) -> dict[str, float]:
        return {key: float(v) for key, v in zip(self.keys, self.values(unit))}


def parse_fit_specs(texts: Iterable[str], scene: Scene) -> FitSpace:
    """Parse `KEY=LO:HI` items (comma-separated, flags repeatable) and check each key is a
    numeric scene key whose whole range the scene accepts."""
    keys, low, high = [], [], []
    for text in texts:
        for item in text.split(","):
            key, sep, span = item.partition("=")
            key = key.strip()
            lo_text, colon, hi_text = span.partition(":")
            if not sep or not colon or not key:
                raise SpreadgymError(f"--fit: expected KEY=LO:HI, got {brief(item)}")
            if key in keys:
                raise ConfigError(key, "is fitted twice in --fit")
            if key.startswith(NOT_FITTED):
                raise ConfigError(key, "cannot be fitted: sim.*, pattern.* and the names describe the run and "
                                       "the test, not the material (set them with --set)")
            try:
                lo, hi = float(lo_text), float(hi_text)
            except ValueError:
                raise ConfigError(key, f"range {brief(span)} is not two numbers LO:HI") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ConfigError(key, f"range {lo:g}:{hi:g} must be finite with LO < HI")
            for value in (lo, 0.5 * (lo + hi), hi):  # the middle catches whole-number keys
                scene_with(scene, {key: value})  # a ConfigError naming the key, value and range
            keys.append(key)
            low.append(lo)
            high.append(hi)
    if not keys:
        raise SpreadgymError("--fit: give at least one KEY=LO:HI")
    if len(keys) > MAX_KEYS:
        raise SpreadgymError(f"--fit: {len(keys)} keys; allowed: at most {MAX_KEYS}")
    return FitSpace(tuple(keys), np.asarray(low), np.asarray(high))
