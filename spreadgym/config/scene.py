"""Scene configuration: the validated, typed form of configs/scenes/*.yaml.

Units are SI; rpm and degrees appear only in keys that say so (`rpm`, `*_deg`), and
the properties here convert them once (`omega_rad_s`, `pitch_rad`, ...).
Validation errors name the dotted key, the bad value and the allowed range.
"""

from __future__ import annotations

import math
import re
from typing import Any, Literal, Mapping, Optional, Union

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from spreadgym.errors import ConfigError
from spreadgym.config.overrides import apply_overrides
from spreadgym.config.resources import read_yaml, resolve_named

RPM_TO_RAD_S = 2.0 * math.pi / 60.0
MAX_RPM = 5000.0
MAX_PITCH_DEG = 60.0


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Spinner(_Strict):
    radius_m: float = Field(gt=0, le=2.0, description="disc radius")
    rpm: float = Field(gt=0, le=MAX_RPM, description="disc speed, revolutions per minute")
    height_m: float = Field(ge=0, le=5.0, description="disc height above ground")
    direction: Literal["ccw", "cw"] = Field(description="sense of rotation seen from above")
    material: str

    @property
    def omega_rad_s(self) -> float:
        """Signed angular velocity about +z (ccw positive), rad/s."""
        sign = 1.0 if self.direction == "ccw" else -1.0
        return sign * self.rpm * RPM_TO_RAD_S


class Vanes(_Strict):
    count: int = Field(ge=1, le=16)
    inner_radius_m: float = Field(ge=0)
    outer_radius_m: Optional[float] = Field(default=None, gt=0, description="default: disc radius")
    thickness_m: float = Field(gt=0, le=0.05)
    pitch_deg: Union[float, list[float]] = Field(
        default=0.0, description="angle from radial, + = tip leans in the direction of rotation"
    )
    height_m: float = Field(default=0.03, gt=0, description="vane height (plan view: informational)")
    material: Optional[str] = Field(default=None, description="default: spinner material")

    @model_validator(mode="after")
    def _pitch_in_range(self) -> "Vanes":
        pitches = self.pitch_deg if isinstance(self.pitch_deg, list) else [self.pitch_deg]
        if isinstance(self.pitch_deg, list) and len(pitches) != self.count:
            raise ValueError(
                f"pitch_deg: one value or one per vane ({self.count}), got {len(pitches)}"
            )
        for p in pitches:
            if not math.isfinite(p) or abs(p) > MAX_PITCH_DEG:
                raise ValueError(f"pitch_deg: {p} outside [-{MAX_PITCH_DEG}, {MAX_PITCH_DEG}] deg")
        return self

    def pitches_rad(self) -> list[float]:
        """Pitch of each vane in radians (length `count`)."""
        if isinstance(self.pitch_deg, list):
            return [math.radians(p) for p in self.pitch_deg]
        return [math.radians(self.pitch_deg)] * self.count


class Feed(_Strict):
    radius_m: float = Field(ge=0, description="release radius from the spinner axis")
    angle_deg: float = Field(description="release angle in the machine frame, from +x, ccw")
    spread_m: float = Field(default=0.0, ge=0, description="s.d. of the release point, each axis")
    drop_height_m: float = Field(ge=0, le=1.0, description="release height above the disc")

    @property
    def angle_rad(self) -> float:
        return math.radians(self.angle_deg)


class Granule(_Strict):
    diameter_m: Optional[float] = Field(default=None, gt=0, le=0.02, description="default: fertilizer d50")
    diameter_sd_m: Optional[float] = Field(default=None, ge=0, le=0.01, description="default: fertilizer")
    rotation: Literal["free", "locked"] = "free"


class Contact(_Strict):
    """Overrides of the library's pair values; null uses the library."""

    disc_friction: Optional[float] = Field(default=None, ge=0, le=2.0)
    vane_friction: Optional[float] = Field(default=None, ge=0, le=2.0)
    vane_restitution: Optional[float] = Field(default=None, ge=0, le=1.0)
    disc_restitution: Optional[float] = Field(default=None, ge=0, le=1.0)
    vane_contact_time_s: Optional[float] = Field(default=None, gt=0, le=0.01)


class Deflector(_Strict):
    """A fixed straight plate in the machine frame, outside the disc."""

    x_m: float = Field(description="plate centre, machine frame")
    y_m: float
    angle_deg: float = Field(description="plate direction from +x, ccw")
    length_m: float = Field(gt=0, le=2.0)
    thickness_m: float = Field(default=0.003, gt=0, le=0.05)
    material: str
    friction: Optional[float] = Field(default=None, ge=0, le=2.0)
    restitution: Optional[float] = Field(default=None, ge=0, le=1.0)
    angle_range_deg: Optional[tuple[float, float]] = Field(
        default=None, description="if set, environments may turn the plate within this range"
    )

    def endpoints(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The plate's two end points (m) in the machine frame."""
        a = math.radians(self.angle_deg)
        dx, dy = 0.5 * self.length_m * math.cos(a), 0.5 * self.length_m * math.sin(a)
        return (self.x_m - dx, self.y_m - dy), (self.x_m + dx, self.y_m + dy)


class Flight(_Strict):
    drag_coefficient: float = Field(default=0.44, ge=0, le=2.0)
    air_density_kg_m3: float = Field(default=1.2, ge=0, le=2.0)
    forward_speed_m_s: float = Field(default=0.0, ge=0, le=20.0, description="machine speed along +y")
    wind_m_s: tuple[float, float] = Field(default=(0.0, 0.0), description="wind (x, y) over ground")


class Pattern(_Strict):
    tray_width_m: float = Field(default=0.5, gt=0, le=5.0)
    driving: Literal["racetrack", "back-and-forth"] = "racetrack"
    cv_threshold_percent: float = Field(default=15.0, gt=0, le=100.0)
    target_swath_m: float = Field(gt=0, le=100.0)

    @model_validator(mode="after")
    def _target_on_tray_grid(self) -> "Pattern":
        ratio = self.target_swath_m / self.tray_width_m
        if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
            raise ValueError(
                f"target_swath_m: {self.target_swath_m} is not a positive multiple of "
                f"tray_width_m ({self.tray_width_m})"
            )
        return self


class Sim(_Strict):
    granules: int = Field(ge=1, le=1_000_000)
    dt_s: Optional[float] = Field(default=None, gt=0, le=0.01, description="null: chosen from the scene")
    seed: int = Field(default=0, ge=0)
    sampler: Literal["qmc", "mc"] = Field(
        default="qmc", description="qmc: scrambled Sobol points per replicate; mc: independent uniform draws")
    replicates: int = Field(default=8, ge=1, le=4096,
                            description="independent replicates per run (the CV's bias correction and "
                                        "standard error rest on them); the most that divide sim.granules")


class Scene(_Strict):
    name: str
    description: str = ""
    fertilizer: str
    spinner: Spinner
    vanes: Vanes
    feed: Feed
    granule: Granule = Granule()
    contact: Contact = Contact()
    deflectors: list[Deflector] = Field(default_factory=list)
    flight: Flight = Flight()
    pattern: Pattern
    sim: Sim

    @model_validator(mode="after")
    def _geometry(self) -> "Scene":
        radius = self.spinner.radius_m
        outer = self.vane_outer_radius_m
        if outer > radius + 1e-12:
            raise ValueError(f"vanes.outer_radius_m: {outer} m is longer than the disc radius {radius} m")
        if self.vanes.inner_radius_m >= outer:
            raise ValueError(
                f"vanes.inner_radius_m: {self.vanes.inner_radius_m} m must be below the outer radius {outer} m"
            )
        if self.feed.radius_m >= radius:
            raise ValueError(f"feed.radius_m: {self.feed.radius_m} m must be inside the disc radius {radius} m")
        for i, plate in enumerate(self.deflectors):
            if _segment_distance_to_origin(*plate.endpoints()) <= radius:
                raise ValueError(f"deflectors[{i}]: the plate reaches inside the disc radius {radius} m")
        return self

    @property
    def vane_outer_radius_m(self) -> float:
        return self.vanes.outer_radius_m if self.vanes.outer_radius_m is not None else self.spinner.radius_m

    @property
    def vane_material(self) -> str:
        return self.vanes.material or self.spinner.material


def _segment_distance_to_origin(a: tuple[float, float], b: tuple[float, float]) -> float:
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    t = max(0.0, min(1.0, -(ax * dx + ay * dy) / (dx * dx + dy * dy)))
    return math.hypot(ax + t * dx, ay + t * dy)


def _format_validation_error(exc: ValidationError) -> ConfigError:
    first = exc.errors()[0]
    key = ".".join(str(p) for p in first["loc"]) or "scene"
    message = first["msg"].removeprefix("Value error, ")
    named = re.match(r"^([\w.\[\]]+): (.*)$", message, flags=re.S)
    if named and key == "scene":  # whole-scene checks name their key in the message
        key, message = named.groups()
    if first["type"] != "value_error":
        message += f" (got {first.get('input')!r})"
    return ConfigError(key, message)


def scene_from_dict(raw: Mapping[str, Any]) -> Scene:
    """Validate a scene mapping; the first problem becomes a ConfigError naming its key."""
    try:
        return Scene.model_validate(dict(raw))
    except ValidationError as exc:
        raise _format_validation_error(exc) from None


def load_scene_dict(name_or_path: str = "paper") -> dict:
    """The raw mapping of a shipped scene name or a YAML path."""
    raw = read_yaml(resolve_named("scenes", name_or_path))
    if not isinstance(raw, dict):
        raise ConfigError("scene", f"{name_or_path!r} does not hold a mapping")
    return raw


def load_scene(name_or_path: str = "paper", overrides: Optional[Mapping[str, Any]] = None) -> Scene:
    """Load, override (dotted keys) and validate a scene."""
    scene = scene_from_dict(load_scene_dict(name_or_path))
    return scene_with(scene, overrides) if overrides else scene


def scene_with(scene: Scene, overrides: Mapping[str, Any]) -> Scene:
    """A validated copy of `scene` with dotted-key overrides applied.

    Overrides act on the full dump (defaults included), so an optional key the YAML
    left out can still be set.
    """
    return scene_from_dict(apply_overrides(scene.model_dump(), overrides))
