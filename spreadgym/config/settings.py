"""The adjustable settings of a scene as one box, and its map to scene overrides.

What an operator can set on a spreader: the disc speed, the vane pitch (one for all
vanes, or one per vane when the scene gives one pitch per vane), the angle of every
deflector plate the scene makes turnable (`angle_range_deg`), and the drop point (feed
radius and angle) when a range is given for it. Each setting is one axis with bounds
in SI units (disc speed rad/s, angles rad, lengths m); rpm and degrees appear only in
the names of the values handed out (`rpm`, `*_deg`) and in the scene keys.

A point of the space is a unit vector u in [-1, 1]^d; axis i maps linearly:

    value_i = low_i + (u_i + 1) / 2 * (high_i - low_i)

so -1 is the lower end, 0 the middle and +1 the upper end. Entries outside [-1, 1]
are clipped to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from spreadgym.config.base import brief
from spreadgym.config.scene import (
    MAX_PITCH_DEG,
    MAX_RPM,
    MAX_TIP_SPEED_M_S,
    RPM_TO_RAD_S,
    Scene,
    _segment_distance_to_origin,
    scene_with,
)
from spreadgym.errors import ConfigError

DEFAULT_RPM = (200.0, 1100.0)
DEFAULT_PITCH_DEG = (-30.0, 30.0)
DEG = math.pi / 180.0
PLATE_CHECK_POINTS = 73  # angles of a plate's range checked against the disc (every 1/72 of the range)


def dialled(name: str, value: float) -> float:
    """A setting's value as an operator dials it, by the unit in its name: whole rpm, tenths of a degree,
    millimetres (what charts and advice print)."""
    decimals = 0 if name == "rpm" else 1 if name.endswith("_deg") else 3
    return round(float(value), decimals)


@dataclass(frozen=True)
class Axis:
    """One setting: its name (unit in the name), the scene key it sets and its SI bounds."""

    name: str  # e.g. "rpm", "pitch_deg", "vane_1_pitch_deg", "deflector_0_angle_deg", "feed_radius_m"
    key: str  # dotted scene key: "spinner.rpm", "vanes.pitch_deg", "deflectors.0.angle_deg", ...
    named_low: float  # bounds in the unit of the name (rpm, deg, m), exactly as given
    named_high: float
    per_unit: float  # SI value of one unit of the name and key (rpm: 2 pi / 60 rad/s, deg: pi / 180 rad)
    index: Optional[int] = None  # position in a list-valued key (one pitch per vane)

    @property
    def low(self) -> float:
        """Lower bound, SI."""
        return self.named_low * self.per_unit

    @property
    def high(self) -> float:
        """Upper bound, SI."""
        return self.named_high * self.per_unit


def _range(key: str, value, low: float, high: float, unit: str) -> tuple[float, float]:
    """A [low, high] pair within [low, high] (units of the key), finite and ordered."""
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ConfigError(key, f"expected [low, high] in {unit}, got {brief(value)}") from None
    if not (math.isfinite(a) and math.isfinite(b)) or a > b:
        raise ConfigError(key, f"expected finite [low, high] with low <= high, got [{a:g}, {b:g}]")
    if a < low or b > high:
        raise ConfigError(key, f"[{a:g}, {b:g}] must lie within [{low:g}, {high:g}] {unit}")
    return a, b


class SettingsSpace:
    """The settings box of one scene.

    `rpm` and `pitch_deg` are the disc-speed and pitch ranges (the scene has none of its
    own); `pitch_per_vane` defaults to what the scene gives (a list of pitches: one axis
    per vane); `deflectors` makes every plate with `angle_range_deg` an axis; `feed`
    makes the drop point adjustable where the scene gives `feed.radius_range_m` or
    `feed.angle_range_deg`, and `feed_radius_m` / `feed_angle_deg` give (or replace)
    those ranges.
    """

    def __init__(self, scene: Scene, rpm=DEFAULT_RPM, pitch_deg=DEFAULT_PITCH_DEG,
                 pitch_per_vane: Optional[bool] = None, deflectors: bool = True, feed: bool = True,
                 feed_radius_m=None, feed_angle_deg=None):
        radius = scene.spinner.radius_m
        top_rpm = min(MAX_RPM, MAX_TIP_SPEED_M_S / (radius * RPM_TO_RAD_S))
        lo, hi = _range("settings.rpm", rpm, 0.0, top_rpm, f"rpm (rim speed at most {MAX_TIP_SPEED_M_S:g} m/s)")
        if lo <= 0.0:
            raise ConfigError("settings.rpm", f"the lower end must be > 0 rpm, got {lo:g}")
        axes = [Axis("rpm", "spinner.rpm", lo, hi, RPM_TO_RAD_S)]
        lo, hi = _range("settings.pitch_deg", pitch_deg, -MAX_PITCH_DEG, MAX_PITCH_DEG, "deg")
        per_vane = isinstance(scene.vanes.pitch_deg, list) if pitch_per_vane is None else bool(pitch_per_vane)
        if per_vane:
            axes += [Axis(f"vane_{k}_pitch_deg", "vanes.pitch_deg", lo, hi, DEG, index=k)
                     for k in range(scene.vanes.count)]
        else:
            axes.append(Axis("pitch_deg", "vanes.pitch_deg", lo, hi, DEG))
        if deflectors:
            for i, plate in enumerate(scene.deflectors):
                if plate.angle_range_deg is not None:
                    lo, hi = (float(v) for v in plate.angle_range_deg)
                    _check_plate_clear(scene, i, lo, hi)
                    axes.append(Axis(f"deflector_{i}_angle_deg", f"deflectors.{i}.angle_deg", lo, hi, DEG))
        if not feed:
            feed_radius_m = feed_angle_deg = None
        else:
            feed_radius_m = scene.feed.radius_range_m if feed_radius_m is None else feed_radius_m
            feed_angle_deg = scene.feed.angle_range_deg if feed_angle_deg is None else feed_angle_deg
        if feed_radius_m is not None:
            lo, hi = _range("settings.feed_radius_m", feed_radius_m, 0.0, radius * (1.0 - 1e-9), "m (inside the disc)")
            axes.append(Axis("feed_radius_m", "feed.radius_m", lo, hi, 1.0))
        if feed_angle_deg is not None:
            lo, hi = _range("settings.feed_angle_deg", feed_angle_deg, -360.0, 360.0, "deg")
            axes.append(Axis("feed_angle_deg", "feed.angle_deg", lo, hi, DEG))
        self.axes: tuple[Axis, ...] = tuple(axes)
        self.vane_count = scene.vanes.count
        self.low = np.array([a.low for a in axes])
        self.high = np.array([a.high for a in axes])
        self.named_low = np.array([a.named_low for a in axes])
        self.named_high = np.array([a.named_high for a in axes])

    @property
    def names(self) -> list[str]:
        return [a.name for a in self.axes]

    @property
    def size(self) -> int:
        return len(self.axes)

    def si(self, unit) -> np.ndarray:
        """SI values of a unit vector (clipped to [-1, 1])."""
        u = np.clip(np.asarray(unit, dtype=np.float64).reshape(self.size), -1.0, 1.0)
        return self.low + 0.5 * (u + 1.0) * (self.high - self.low)

    def unit(self, si) -> np.ndarray:
        """Unit vector of SI values (clipped to [-1, 1]; 0 on an axis of zero width)."""
        per_unit = np.array([a.per_unit for a in self.axes])
        return self.named_unit(np.asarray(si, dtype=np.float64).reshape(self.size) / per_unit)

    def named_unit(self, values) -> np.ndarray:
        """Unit vector of values in the units of the names (rpm, deg, m); a value at a bound
        gives exactly -1 or +1 (clipped to [-1, 1]; 0 on an axis of zero width)."""
        v = np.asarray(values, dtype=np.float64).reshape(self.size)
        span = self.named_high - self.named_low
        u = np.where(span > 0, 2.0 * (v - self.named_low) / np.where(span > 0, span, 1.0) - 1.0, 0.0)
        return np.clip(u, -1.0, 1.0)

    def values(self, unit) -> dict[str, float]:
        """name -> value in the unit of the name (rpm, deg, m); the ends of the box give the
        bounds exactly as they were given."""
        u = np.clip(np.asarray(unit, dtype=np.float64).reshape(self.size), -1.0, 1.0)
        named = self.named_low + 0.5 * (u + 1.0) * (self.named_high - self.named_low)
        return {a.name: float(v) for a, v in zip(self.axes, named)}

    def overrides(self, unit) -> dict[str, Any]:
        """Dotted scene keys that put the settings of `unit` into a scene."""
        out: dict[str, Any] = {}
        for axis, value in zip(self.axes, self.values(unit).values()):
            if axis.index is None:
                out[axis.key] = value
            else:
                out.setdefault(axis.key, [0.0] * self.vane_count)[axis.index] = value
        return out

    def apply(self, scene: Scene, unit) -> Scene:
        """A validated copy of `scene` with the settings of `unit`."""
        return scene_with(scene, self.overrides(unit))

    def scene_unit(self, scene: Scene) -> np.ndarray:
        """The unit vector of the scene's own settings (clipped into the box; a shared
        pitch axis takes the vanes' mean pitch)."""
        return self.named_unit(self.scene_values(scene))

    def scene_values(self, scene: Scene) -> list[float]:
        """The scene's own settings on the axes, in the units of the names (rpm, deg, m), as the scene has
        them (not clipped into the box; a shared pitch axis takes the vanes' mean pitch)."""
        pitches = [float(p) for p in scene.vanes.per_vane("pitch_deg")]
        values = []
        for axis in self.axes:
            if axis.key == "spinner.rpm":
                values.append(scene.spinner.rpm)
            elif axis.key == "vanes.pitch_deg":
                values.append(pitches[axis.index] if axis.index is not None else float(np.mean(pitches)))
            elif axis.key.startswith("deflectors."):
                values.append(scene.deflectors[int(axis.key.split(".")[1])].angle_deg)
            elif axis.key == "feed.radius_m":
                values.append(scene.feed.radius_m)
            else:
                values.append(scene.feed.angle_deg)
        return [float(v) for v in values]


def _check_plate_clear(scene: Scene, index: int, lo_deg: float, hi_deg: float) -> None:
    """Every angle of the plate's range must keep it clear of the disc (checked on a fine grid)."""
    plate = scene.deflectors[index]
    for angle in np.linspace(lo_deg, hi_deg, PLATE_CHECK_POINTS):
        a = math.radians(float(angle))
        dx, dy = 0.5 * plate.length_m * math.cos(a), 0.5 * plate.length_m * math.sin(a)
        if _segment_distance_to_origin((plate.x_m - dx, plate.y_m - dy),
                                       (plate.x_m + dx, plate.y_m + dy)) <= scene.spinner.radius_m:
            raise ConfigError(f"deflectors.{index}.angle_range_deg",
                              f"at {angle:.4g} deg the plate reaches inside the disc radius {scene.spinner.radius_m} m")
