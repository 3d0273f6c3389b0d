"""The fitted keys and their search ranges (`--fit KEY=LO:HI[,KEY=LO:HI ...]`).

The optimiser works in the unit cube: u_j in [0, 1] maps to LO_j + u_j (HI_j - LO_j),
each key in its own unit (as the scene file writes it).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

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


def parse_fit_specs(texts: Iterable[str], scene: Scene, fixed: Iterable[str] = ()) -> FitSpace:
    """Parse `KEY=LO:HI` items (comma-separated, flags repeatable) and check, before any
    work, that each key is a real-valued scene key not also given by `--set` (`fixed`),
    and that the scene accepts every corner of the search box (and its centre): keys
    that constrain each other (a feed radius inside a fitted disc radius) fail here,
    naming the corner, not mid-fit at a point nobody typed."""
    fixed = set(fixed)
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
            if key in fixed:
                raise ConfigError(key, "is set by --set and fitted by --fit; give it one way (--set fixes it, "
                                       "--fit searches it)")
            if key.startswith(NOT_FITTED):
                raise ConfigError(key, "cannot be fitted: sim.*, pattern.* and the names describe the run and "
                                       "the test, not the material (set them with --set)")
            try:
                lo, hi = float(lo_text), float(hi_text)
            except ValueError:
                raise ConfigError(key, f"range {brief(span)} is not two numbers LO:HI") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ConfigError(key, f"range {lo:g}:{hi:g} must be finite with LO < HI")
            section = key.split(".")[0]
            if getattr(scene, section, "") is None:  # scene_with would add the section: another machine
                raise ConfigError(key, f"this scene has no {section} section; --fit searches what the scene has "
                                       f"(give a scene with {section})")
            current = _value(scene, key)
            if isinstance(current, int) and not isinstance(current, bool):
                raise ConfigError(key, f"is a whole number ({key} = {current}); --fit searches real-valued keys "
                                       "only: fit at each count with --set instead")
            for value in (lo, hi):
                scene_with(scene, {key: value})  # a ConfigError naming the key, value and range
            keys.append(key)
            low.append(lo)
            high.append(hi)
    if not keys:
        raise SpreadgymError("--fit: give at least one KEY=LO:HI")
    if len(keys) > MAX_KEYS:
        raise SpreadgymError(f"--fit: {len(keys)} keys; allowed: at most {MAX_KEYS}")
    space = FitSpace(tuple(keys), np.asarray(low), np.asarray(high))
    _check_box(space, scene)
    return space


def _value(scene: Scene, key: str) -> Any:
    """The scene's value at a dotted key (None where there is none: `scene_with` names the problem)."""
    node: Any = scene.model_dump()
    for part in key.split("."):
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return None
    return node


def _box_points(space: FitSpace) -> list[tuple[float, ...]]:
    """Every corner of the search box (2^d, d <= MAX_KEYS) and its centre, in the unit cube."""
    return [*itertools.product((0.0, 1.0), repeat=space.dims), (0.5,) * space.dims]


def _check_box(space: FitSpace, scene: Scene) -> None:
    """Every corner of the search box and its centre make a valid scene."""
    for corner in _box_points(space):
        values = space.overrides(corner)
        try:
            scene_with(scene, values)
        except ConfigError as exc:
            point = ", ".join(f"{k}={v:g}" for k, v in values.items())
            raise SpreadgymError(f"--fit: the search box's {'centre' if 0.5 in corner else 'corner'} {point} is not "
                                 f"a valid scene ({exc}); narrow the ranges") from None


def full_model_corner(space: FitSpace, scene: Scene, model: str = "auto") -> str:
    """Where `auto` leaves the compiled model inside the search box: "" when every corner of the box (and
    its centre) runs `model` as the compiled one, else the first such corner and auto's reason. The
    evaluations there run the full model, a hundred times slower (a rolling resistance fitted past the
    compiled model's validated envelope, for one)."""
    from spreadgym.physics.selection import choose_model

    if model != "auto":
        return ""
    for corner in _box_points(space):
        values = space.overrides(corner)
        chosen, reason = choose_model(scene_with(scene, values), model)
        if chosen != "compiled":
            return f"{', '.join(f'{k}={v:g}' for k, v in values.items())}: {reason}"
    return ""
