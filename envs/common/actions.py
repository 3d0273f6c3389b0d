"""Actions <-> spreader settings.

The action is a float32 vector in [-1, 1]^A, one entry per setting, in this order:

    [rpm, pitch (one shared, or one per vane), angle of each adjustable deflector]

Entry u maps linearly onto the setting's range [lo, hi] (config `settings` for rpm
and pitch, the deflector's own `angle_range_deg`):

    value = lo + (u + 1) / 2 * (hi - lo)

so -1 is the lower end, 0 the middle and +1 the upper end. Entries outside [-1, 1]
are clipped to it (an action of 5.0 acts like 1.0); an entry that is NaN or infinite
is a `ValueError` saying the action is not finite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces
from spreadgym.envs.common.config import SettingsConfig

from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError


@dataclass(frozen=True)
class Settings:
    """What the operator sets on the machine."""

    rpm: float
    pitch_deg: tuple[float, ...]  # one shared value, or one per vane
    deflector_angle_deg: tuple[float, ...]  # one per adjustable deflector (SettingsMap order)

    def as_dict(self) -> dict:
        return {
            "rpm": float(self.rpm),
            "pitch_deg": [float(p) for p in self.pitch_deg],
            "deflector_angle_deg": [float(a) for a in self.deflector_angle_deg],
        }


def check_action(action, size: int) -> np.ndarray:
    """The action as float64 of shape (size,), clipped to [-1, 1]; anything else is refused
    (ValueError naming what was given): other shapes, non-numbers, non-finite entries."""
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"action must be {size} finite numbers, got {action!r}") from None
    if a.shape != (size,):
        raise ValueError(f"action must have shape ({size},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(
            f"action is not finite: {a.tolist()}; every entry must be a finite number "
            "(values outside [-1, 1] are clipped)"
        )
    return np.clip(a, -1.0, 1.0)


class SettingsMap:
    """The linear map between unit actions and settings, for one base scene."""

    def __init__(self, scene: Scene, cfg: SettingsConfig):
        self.vane_count = scene.vanes.count
        self.pitch_count = scene.vanes.count if cfg.pitch_per_vane else 1
        self.deflector_index: list[int] = []
        ranges = []
        if cfg.deflectors:
            for i, plate in enumerate(scene.deflectors):
                if plate.angle_range_deg is None:
                    continue
                lo, hi = (float(v) for v in plate.angle_range_deg)
                key = f"deflectors.{i}.angle_range_deg"
                if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
                    raise ConfigError(key, f"expected [low, high] with low <= high, got [{lo}, {hi}]")
                _check_plate_stays_outside(scene, i, lo, hi)
                self.deflector_index.append(i)
                ranges.append((lo, hi))
        self.names = (
            ["rpm"]
            + (["pitch_deg"] if self.pitch_count == 1 else [f"pitch_deg[{k}]" for k in range(self.pitch_count)])
            + [f"deflectors[{i}].angle_deg" for i in self.deflector_index]
        )
        self.size = len(self.names)
        self.low = np.array([cfg.rpm[0]] + [cfg.pitch_deg[0]] * self.pitch_count + [r[0] for r in ranges])
        self.high = np.array([cfg.rpm[1]] + [cfg.pitch_deg[1]] * self.pitch_count + [r[1] for r in ranges])

    @property
    def space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, shape=(self.size,), dtype=np.float32)

    def to_settings(self, unit: np.ndarray) -> Settings:
        """Settings of a (clipped) unit vector."""
        u = np.clip(np.asarray(unit, dtype=np.float64).reshape(self.size), -1.0, 1.0)
        v = self.low + 0.5 * (u + 1.0) * (self.high - self.low)
        p = 1 + self.pitch_count
        return Settings(float(v[0]), tuple(float(x) for x in v[1:p]), tuple(float(x) for x in v[p:]))

    def to_unit(self, settings: Settings) -> np.ndarray:
        """Unit vector of settings (clipped to [-1, 1]; 0 for a range of zero width)."""
        v = np.array([settings.rpm, *settings.pitch_deg, *settings.deflector_angle_deg], dtype=np.float64)
        span = self.high - self.low
        safe = np.where(span > 0, span, 1.0)
        u = np.where(span > 0, 2.0 * (v - self.low) / safe - 1.0, 0.0)
        return np.clip(u, -1.0, 1.0)

    def from_scene(self, scene: Scene) -> Settings:
        """The scene's own settings, clipped into the ranges (a shared pitch is the vanes' mean)."""
        pitches = scene.vanes.pitch_deg
        if not isinstance(pitches, list):
            pitches = [pitches] * self.vane_count
        pitch = (float(np.mean(pitches)),) if self.pitch_count == 1 else tuple(float(p) for p in pitches)
        angles = tuple(float(scene.deflectors[i].angle_deg) for i in self.deflector_index)
        return self.to_settings(self.to_unit(Settings(float(scene.spinner.rpm), pitch, angles)))

    def scene_overrides(self, settings: Settings) -> dict:
        """Dotted scene keys that put `settings` into a scene."""
        pitch = settings.pitch_deg[0] if self.pitch_count == 1 else list(settings.pitch_deg)
        out = {"spinner.rpm": float(settings.rpm), "vanes.pitch_deg": pitch}
        for i, angle in zip(self.deflector_index, settings.deflector_angle_deg):
            out[f"deflectors.{i}.angle_deg"] = float(angle)
        return out


def _check_plate_stays_outside(scene: Scene, index: int, lo: float, hi: float) -> None:
    """Every angle of the range must keep the plate clear of the disc (checked on a fine grid)."""
    plate = scene.deflectors[index]
    for angle in np.linspace(lo, hi, 73):
        a = math.radians(float(angle))
        dx, dy = 0.5 * plate.length_m * math.cos(a), 0.5 * plate.length_m * math.sin(a)
        if _distance_to_axis(plate.x_m - dx, plate.y_m - dy, 2 * dx, 2 * dy) <= scene.spinner.radius_m:
            raise ConfigError(
                f"deflectors.{index}.angle_range_deg",
                f"at {angle:.4g} deg the plate reaches inside the disc radius {scene.spinner.radius_m} m",
            )


def _distance_to_axis(ax: float, ay: float, dx: float, dy: float) -> float:
    """Distance from the origin to the segment a + t d, t in [0, 1]."""
    t = max(0.0, min(1.0, -(ax * dx + ay * dy) / (dx * dx + dy * dy)))
    return math.hypot(ax + t * dx, ay + t * dy)
