"""Actions <-> spreader settings.

The action is a float32 vector in [-1, 1]^A, one entry per setting, in this order:

    [rpm, pitch (one shared, or one per vane), angle of each adjustable deflector,
     feed radius, feed angle (each where the scene gives it a range)]

Entry u maps linearly onto the setting's range [lo, hi] (config `settings` for rpm
and pitch, the deflector's own `angle_range_deg`, the scene's `feed.radius_range_m`
and `feed.angle_range_deg`):

    value = lo + (u + 1) / 2 * (hi - lo)

so -1 is the lower end, 0 the middle and +1 the upper end. Entries outside [-1, 1]
are clipped to it (an action of 5.0 acts like 1.0); an entry that is NaN or infinite
is a `ValueError` saying the action is not finite. The box itself is the core's
`SettingsSpace` (the one the chart searches too); this module names its entries for
the environments and turns them into `Settings`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Optional

import numpy as np
from gymnasium import spaces

from spreadgym.config.base import brief
from spreadgym.config.scene import Scene
from spreadgym.config.settings import SettingsSpace
from spreadgym.envs.common.config import SettingsConfig


@dataclass(frozen=True)
class Settings:
    """What the operator sets on the machine (rpm and degrees, as on its dials)."""

    rpm: float
    pitch_deg: tuple[float, ...]  # one shared value, or one per vane
    deflector_angle_deg: tuple[float, ...]  # one per adjustable deflector (SettingsMap order)
    feed_radius_m: Optional[float] = None  # the drop point, where the scene makes it adjustable
    feed_angle_deg: Optional[float] = None

    def as_dict(self) -> dict:
        out = {
            "rpm": float(self.rpm),
            "pitch_deg": [float(p) for p in self.pitch_deg],
            "deflector_angle_deg": [float(a) for a in self.deflector_angle_deg],
        }
        for key in ("feed_radius_m", "feed_angle_deg"):
            if getattr(self, key) is not None:
                out[key] = float(getattr(self, key))
        return out

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "Settings":
        """The inverse of `as_dict` (as found in `info["settings"]`)."""
        optional = {k: float(values[k]) for k in ("feed_radius_m", "feed_angle_deg") if values.get(k) is not None}
        return cls(float(values["rpm"]), tuple(float(p) for p in values["pitch_deg"]),
                   tuple(float(a) for a in values.get("deflector_angle_deg", ())), **optional)


def check_action(action, size: int) -> np.ndarray:
    """The action as float64 of shape (size,), clipped to [-1, 1]; anything else is refused
    (ValueError naming what was given): other shapes, non-numbers (complex ones included),
    non-finite entries."""
    try:
        given = np.asarray(action)
    except (TypeError, ValueError):  # ragged nesting
        given = np.asarray(None)
    if given.dtype.kind not in "biuf":
        kind = "real numbers (no imaginary part)" if given.dtype.kind == "c" else "finite numbers"
        raise ValueError(f"action must be {size} {kind}, got {brief(action)}")
    a = given.astype(np.float64)
    if a.shape != (size,):
        raise ValueError(f"action must have shape ({size},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(
            f"action is not finite: {a.tolist()}; every entry must be a finite number "
            "(values outside [-1, 1] are clipped)"
        )
    return np.clip(a, -1.0, 1.0)


def _entry_name(axis_name: str) -> str:
    """The environments' name of a settings axis: scene-key style, unit in the name."""
    if axis_name.startswith("vane_"):
        return f"pitch_deg[{axis_name.split('_')[1]}]"
    if axis_name.startswith("deflector_"):
        return f"deflectors[{axis_name.split('_')[1]}].angle_deg"
    return {"feed_radius_m": "feed.radius_m", "feed_angle_deg": "feed.angle_deg"}.get(axis_name, axis_name)


class SettingsMap:
    """The linear map between unit actions and settings, for one base scene."""

    def __init__(self, scene: Scene, cfg: SettingsConfig):
        self.box = SettingsSpace(scene, rpm=cfg.rpm, pitch_deg=cfg.pitch_deg, pitch_per_vane=cfg.pitch_per_vane,
                                 deflectors=cfg.deflectors, feed=cfg.feed)
        self.vane_count = scene.vanes.count
        self.pitch_count = scene.vanes.count if cfg.pitch_per_vane else 1
        keys = [axis.key for axis in self.box.axes]
        self.deflector_index = [int(key.split(".")[1]) for key in keys if key.startswith("deflectors.")]
        self.feed_keys = [key for key in keys if key.startswith("feed.")]
        self.names = [_entry_name(axis.name) for axis in self.box.axes]
        self.size = self.box.size
        self.low, self.high = self.box.named_low, self.box.named_high  # rpm, deg, m

    @property
    def space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, shape=(self.size,), dtype=np.float32)

    def to_settings(self, unit: np.ndarray) -> Settings:
        """Settings of a (clipped) unit vector."""
        v = list(self.box.values(unit).values())
        p, d = 1 + self.pitch_count, 1 + self.pitch_count + len(self.deflector_index)
        feed = dict(zip(("feed_radius_m" if k == "feed.radius_m" else "feed_angle_deg" for k in self.feed_keys), v[d:]))
        return Settings(v[0], tuple(v[1:p]), tuple(v[p:d]), **feed)

    def to_unit(self, settings: Settings) -> np.ndarray:
        """Unit vector of settings (clipped to [-1, 1]; 0 for a range of zero width)."""
        feed = [settings.feed_radius_m if k == "feed.radius_m" else settings.feed_angle_deg for k in self.feed_keys]
        if any(value is None for value in feed):
            raise ValueError(f"settings lack the drop point this scene makes adjustable ({', '.join(self.feed_keys)})")
        values = np.array([settings.rpm, *settings.pitch_deg, *settings.deflector_angle_deg, *feed], dtype=np.float64)
        return self.box.named_unit(values)

    def from_scene(self, scene: Scene) -> Settings:
        """The scene's own settings, clipped into the ranges (a shared pitch is the vanes' mean)."""
        return self.to_settings(self.box.scene_unit(scene))

    def scene_overrides(self, settings: Settings) -> dict:
        """Dotted scene keys that put `settings` into a scene."""
        pitch = settings.pitch_deg[0] if self.pitch_count == 1 else list(settings.pitch_deg)
        out = {"spinner.rpm": float(settings.rpm), "vanes.pitch_deg": pitch}
        for i, angle in zip(self.deflector_index, settings.deflector_angle_deg):
            out[f"deflectors.{i}.angle_deg"] = float(angle)
        if settings.feed_radius_m is not None and "feed.radius_m" in self.feed_keys:
            out["feed.radius_m"] = float(settings.feed_radius_m)
        if settings.feed_angle_deg is not None and "feed.angle_deg" in self.feed_keys:
            out["feed.angle_deg"] = float(settings.feed_angle_deg)
        return out
