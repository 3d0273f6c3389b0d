"""Scene configuration: the validated, typed form of configs/scenes/*.yaml.

Units are SI; rpm and degrees appear only in keys that say so (`rpm`, `*_deg`), and
the properties here convert them once (`omega_rad_s`, `pitch_rad`, ...).
Validation errors name the dotted key, the bad value and the allowed range.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal, Mapping, Optional, TypeVar, Union

from pydantic import Field, Strict, ValidationError, field_validator, model_validator

from spreadgym.config.base import Integer, Real, StrictModel, brief, format_validation_error, validate
from spreadgym.config.materials import FertilizerSpec, fertilizer_name, load_library
from spreadgym.config.overrides import set_in_place
from spreadgym.config.resources import read_yaml, resolve_named
from spreadgym.errors import ConfigError, MaterialError

RPM_TO_RAD_S = 2.0 * math.pi / 60.0
MAX_RPM = 5000.0
MIN_RPM = 10.0  # slower discs throw nothing; the closed forms overflow as rpm -> 0
MAX_PITCH_DEG = 60.0
MAX_TIP_SPEED_M_S = 100.0  # disc rim speed; spreaders run 15-45 m/s, beyond 100 throws leave any field
MAX_WIND_M_S = 20.0  # each component; nobody spreads in a gale, and the flight stays bounded
MAX_ANGLE_DEG = 360.0
MAX_PLANE_M = 5.0  # plates and feed points lie within this distance of the disc axis
MAX_SPACING_M = 3.0  # between the axes of twin discs; machines carry them 0.6-1.2 m apart
MIN_DT_S = 1e-6  # far below every model's automatic step (5e-5 to 2e-4 s): smaller only costs time
MAX_DEFLECTORS = 32  # plates on one machine; spreaders carry a handful
MAX_GRANULE_COPIES = 4_000_000
"""Landing points one run may hold: sim.granules x sim.angle_copies x discs (about 100 bytes
each at the peak, so a run stays near 0.4 GiB of arrays)."""
MIN_BOUT_TRAYS = 2  # a bout of one tray has no spread to measure: its CV is 0 whatever the pattern
ModelT = TypeVar("ModelT", bound=StrictModel)
WindComponent = Annotated[Real, Field(ge=-MAX_WIND_M_S, le=MAX_WIND_M_S)]
Angle = Annotated[Real, Field(ge=-MAX_ANGLE_DEG, le=MAX_ANGLE_DEG)]


MAX_CONE_DEG = 15.0  # a tilted flat-disc launch misses the longer time on a cone: 1/cos = 3.5 % at 15 deg


class Spinner(StrictModel):
    radius_m: Real = Field(gt=0, le=2.0, description="disc radius")
    rpm: Real = Field(ge=MIN_RPM, le=MAX_RPM, description="disc speed, revolutions per minute")
    height_m: Real = Field(ge=0, le=5.0,
                           description="disc height above ground, where granules leave it (a dished disc's rim)")
    direction: Literal["ccw", "cw"] = Field(description="sense of rotation seen from above")
    material: str
    cone_deg: Real = Field(default=0.0, ge=0.0, le=MAX_CONE_DEG,
                           description="the disc surface rises outward at this angle (dished disc): launch elevation")

    @property
    def omega_rad_s(self) -> float:
        """Signed angular velocity about +z (ccw positive), rad/s."""
        sign = 1.0 if self.direction == "ccw" else -1.0
        return sign * self.rpm * RPM_TO_RAD_S


class Vanes(StrictModel):
    count: Integer = Field(ge=1, le=16)
    inner_radius_m: Union[Real, list[Real]] = Field(
        description="radius of the vanes' inner ends; one value, or one per vane (short and long vanes), each 0..2 m"
    )
    outer_radius_m: Optional[Real] = Field(default=None, gt=0, description="default: disc radius")
    thickness_m: Real = Field(gt=0, le=0.05)
    pitch_deg: Union[Real, list[Real]] = Field(
        default=0.0, description="angle from radial, + = tip leans in the direction of rotation; each within +-60 deg"
    )
    height_m: Real = Field(default=0.03, gt=0, le=0.5,
                           description="vane height above the disc: a falling or bouncing granule above it passes "
                                       "over the vanes, so it moves the pattern")
    material: Optional[str] = Field(default=None, description="default: spinner material")

    @model_validator(mode="after")
    def _per_vane_values_in_range(self) -> "Vanes":
        for key, allowed, (lo, hi) in (("pitch_deg", f"[-{MAX_PITCH_DEG}, {MAX_PITCH_DEG}] deg",
                                        (-MAX_PITCH_DEG, MAX_PITCH_DEG)),
                                       ("inner_radius_m", "[0, 2] m", (0.0, 2.0))):
            values = self.per_vane(key)
            if len(values) != self.count:
                raise ValueError(f"{key}: one value or one per vane ({self.count}), got {len(values)}")
            for value in values:
                if not (math.isfinite(value) and lo <= value <= hi):
                    raise ValueError(f"{key}: {value} outside {allowed}")
        return self

    def per_vane(self, key: str) -> list[float]:
        """A key that takes one value or one per vane (`pitch_deg`, `inner_radius_m`), one
        entry per vane (length `count` once validated), in its own unit."""
        value = getattr(self, key)
        return list(value) if isinstance(value, list) else [value] * self.count

    def inner_radii_m(self) -> list[float]:
        """Radius (m) of each vane's inner end (length `count`)."""
        return self.per_vane("inner_radius_m")

    def pitches_rad(self) -> list[float]:
        """Pitch of each vane in radians (length `count`)."""
        return [math.radians(p) for p in self.per_vane("pitch_deg")]


class Feed(StrictModel):
    radius_m: Real = Field(ge=0, le=2.0, description="release radius from the spinner axis")
    angle_deg: Real = Field(ge=-MAX_ANGLE_DEG, le=MAX_ANGLE_DEG,
                            description="release angle in the machine frame, from +x, ccw")
    spread_m: Real = Field(default=0.0, ge=0, le=2.0,
                           description="s.d. of the release point, each axis; at most the disc radius")
    drop_height_m: Real = Field(ge=0, le=1.0, description="release height above the disc")
    radius_range_m: Optional[tuple[Real, Real]] = Field(
        default=None, description="if set, environments, searches and charts may move the release radius within it")
    angle_range_deg: Optional[tuple[Angle, Angle]] = Field(
        default=None, description="if set, environments, searches and charts may move the release angle within it")

    @model_validator(mode="after")
    def _ranges_ordered(self) -> "Feed":
        for key in ("radius_range_m", "angle_range_deg"):
            value = getattr(self, key)
            if value is not None and value[0] > value[1]:
                raise ValueError(f"{key}: [{value[0]:g}, {value[1]:g}] is reversed; give [low, high]")
        return self

    @property
    def angle_rad(self) -> float:
        return math.radians(self.angle_deg)


class Granule(StrictModel):
    diameter_m: Optional[Real] = Field(default=None, gt=0, le=0.02, description="default: fertilizer d50")
    diameter_sd_m: Optional[Real] = Field(default=None, ge=0, le=0.01, description="default: fertilizer")
    rotation: Literal["free", "locked"] = "free"


class Contact(StrictModel):
    """Overrides of the library's pair values; null uses the library."""

    disc_friction: Optional[Real] = Field(default=None, ge=0, le=2.0)
    vane_friction: Optional[Real] = Field(default=None, ge=0, le=2.0)
    vane_restitution: Optional[Real] = Field(default=None, ge=0, le=1.0)
    disc_restitution: Optional[Real] = Field(default=None, ge=0, le=1.0)
    vane_contact_time_s: Optional[Real] = Field(default=None, gt=0, le=0.01)
    rolling_resistance: Optional[Real] = Field(
        default=None, ge=0, le=2.0,
        description="vane rolling resistance mu_r: a torque mu_r r N against the granule's spin relative to the vane "
                    "(0: loss-free rolling; >= the vane friction: sliding); docs/physics.md")


class Deflector(StrictModel):
    """A fixed straight plate in the machine frame, outside the disc."""

    x_m: Real = Field(ge=-MAX_PLANE_M, le=MAX_PLANE_M, description="plate centre, machine frame")
    y_m: Real = Field(ge=-MAX_PLANE_M, le=MAX_PLANE_M)
    angle_deg: Real = Field(ge=-MAX_ANGLE_DEG, le=MAX_ANGLE_DEG, description="plate direction from +x, ccw")
    length_m: Real = Field(ge=0.001, le=2.0)
    thickness_m: Real = Field(default=0.003, gt=0, le=0.05)
    material: str
    friction: Optional[Real] = Field(default=None, ge=0, le=2.0)
    restitution: Optional[Real] = Field(default=None, ge=0, le=1.0)
    angle_range_deg: Optional[tuple[Angle, Angle]] = Field(
        default=None, description="if set, environments may turn the plate within this range (low, high)"
    )

    @model_validator(mode="after")
    def _range_ordered(self) -> "Deflector":
        if self.angle_range_deg is not None and self.angle_range_deg[0] > self.angle_range_deg[1]:
            lo, hi = self.angle_range_deg
            raise ValueError(f"angle_range_deg: [{lo:g}, {hi:g}] is reversed; give [low, high]")
        return self

    def endpoints(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The plate's two end points (m) in the machine frame."""
        a = math.radians(self.angle_deg)
        dx, dy = 0.5 * self.length_m * math.cos(a), 0.5 * self.length_m * math.sin(a)
        return (self.x_m - dx, self.y_m - dy), (self.x_m + dx, self.y_m + dy)


class Flight(StrictModel):
    drag_coefficient: Real = Field(default=0.44, ge=0, le=2.0)
    air_density_kg_m3: Real = Field(default=1.2, ge=0, le=2.0)
    forward_speed_m_s: Real = Field(default=0.0, ge=0, le=20.0, description="machine speed along +y")
    wind_m_s: tuple[WindComponent, WindComponent] = Field(default=(0.0, 0.0), description="wind (x, y) over ground")
    magnus: Annotated[bool, Strict()] = Field(default=False, description="keep the departure spin in flight: "
                                              "Magnus lift and air-torque spin decay (docs/magnus.md)")
    lift_coefficient_max: Real = Field(default=0.37, ge=0, le=1.0, description="Magnus lift coefficient plateau")
    lift_saturation_spin_parameter: Real = Field(
        default=0.34, gt=0, le=5.0, description="spin parameter (r omega / v_rel) at the knee of the lift curve")
    air_viscosity_pa_s: Real = Field(default=1.81e-5, gt=0, le=1e-3, description="dynamic viscosity (spin decay)")


class Pattern(StrictModel):
    tray_width_m: Real = Field(default=0.5, ge=0.05, le=5.0)
    driving: Literal["racetrack", "back-and-forth"] = "racetrack"
    cv_threshold_percent: Real = Field(default=15.0, gt=0, le=100.0)
    target_swath_m: Real = Field(gt=0, le=100.0, description="at least two trays wide")

    @model_validator(mode="after")
    def _target_on_tray_grid(self) -> "Pattern":
        try:
            bout_trays(self.target_swath_m, self.tray_width_m)
        except ValueError as exc:
            raise ValueError(f"target_swath_m: {exc}") from None
        return self


def bout_trays(width_m: float, tray_width_m: float) -> int:
    """Trays in a bout `width_m` wide; a ValueError unless the width is on the tray grid
    and at least `MIN_BOUT_TRAYS` trays wide."""
    ratio = width_m / tray_width_m
    if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
        raise ValueError(f"{width_m:g} m is off the tray grid: not a positive multiple of tray_width_m "
                         f"({tray_width_m:g} m)")
    if round(ratio) < MIN_BOUT_TRAYS:
        raise ValueError(f"{width_m:g} m is narrower than {MIN_BOUT_TRAYS} trays of {tray_width_m:g} m: a bout of "
                         f"fewer has no spread to measure (its CV is 0 whatever the pattern); allowed: >= "
                         f"{MIN_BOUT_TRAYS * tray_width_m:g} m")
    return int(round(ratio))


class Sim(StrictModel):
    granules: Integer = Field(ge=1, le=1_000_000, description="x sim.angle_copies x discs at most 4e6 (memory)")
    dt_s: Optional[Real] = Field(default=None, ge=MIN_DT_S, le=0.01, description="null: chosen from the scene")
    seed: Integer = Field(default=0, ge=0)
    sampler: Literal["qmc", "mc"] = Field(
        default="qmc", description="qmc: scrambled Sobol points per replicate; mc: independent uniform draws")
    replicates: Integer = Field(default=8, ge=1, le=4096,
                            description="independent replicates per run (the CV's bias correction and "
                                        "standard error rest on them); the most that divide sim.granules")
    angle_copies: Integer = Field(default=32, ge=1, le=256,
                              description="release angles per simulated granule: each spinner run is reused "
                                          "at this many release angles drawn from the feed spot, exactly "
                                          "(docs/estimate.md); 1 for none; wind, forward speed and a point "
                                          "feed take 1")


class TwinSpinner(StrictModel):
    """`spinner` keys of the second disc that differ from the first's mirror image (null: mirrored)."""

    radius_m: Optional[Real] = Field(default=None, gt=0, le=2.0)
    rpm: Optional[Real] = Field(default=None, ge=MIN_RPM, le=MAX_RPM)
    height_m: Optional[Real] = Field(default=None, ge=0, le=5.0)
    direction: Optional[Literal["ccw", "cw"]] = Field(default=None, description="null: opposite to the first disc")
    material: Optional[str] = None


class TwinVanes(StrictModel):
    """`vanes` keys of the second disc (null: the first disc's, pitches in mirrored order)."""

    count: Optional[Integer] = Field(default=None, ge=1, le=16)
    inner_radius_m: Optional[Union[Real, list[Real]]] = None
    outer_radius_m: Optional[Real] = Field(default=None, gt=0)
    thickness_m: Optional[Real] = Field(default=None, gt=0, le=0.05)
    pitch_deg: Optional[Union[Real, list[Real]]] = None
    height_m: Optional[Real] = Field(default=None, gt=0, le=0.5)
    material: Optional[str] = None


class TwinFeed(StrictModel):
    """`feed` keys of the second disc (null: the first disc's; the angle mirrored, 180 deg - angle)."""

    radius_m: Optional[Real] = Field(default=None, ge=0, le=2.0)
    angle_deg: Optional[Real] = Field(default=None, ge=-MAX_ANGLE_DEG, le=MAX_ANGLE_DEG,
                                      description="about the second disc's axis, from +x, ccw")
    spread_m: Optional[Real] = Field(default=None, ge=0, le=2.0)
    drop_height_m: Optional[Real] = Field(default=None, ge=0, le=1.0)


class Twin(StrictModel):
    """A second disc. `spinner`, `vanes`, `feed` of the scene describe the first disc, on the
    right of the track at x = +spacing/2; the second, at x = -spacing/2, is its mirror
    image unless the keys here say otherwise. Both throw through the same plates."""

    spacing_m: Real = Field(gt=0, le=MAX_SPACING_M, description="distance between the disc axes, across the track")
    spinner: TwinSpinner = TwinSpinner()
    vanes: TwinVanes = TwinVanes()
    feed: TwinFeed = TwinFeed()


class Scene(StrictModel):
    name: str
    description: str = ""
    fertilizer: Union[str, FertilizerSpec] = Field(
        description="a name from the material library (or a --materials file), or the fertilizer itself as a "
                    "mapping (density, size, friction, restitution, rolling_resistance per surface; docs/materials.md)")
    spinner: Spinner
    vanes: Vanes
    feed: Feed
    granule: Granule = Granule()
    contact: Contact = Contact()
    deflectors: list[Deflector] = Field(default_factory=list, max_length=MAX_DEFLECTORS,
                                        description="at most 32 plates")
    twin: Optional[Twin] = Field(default=None, description="a second disc (null: one disc)")
    flight: Flight = Flight()
    pattern: Pattern
    sim: Sim

    @field_validator("fertilizer", mode="before")
    @classmethod
    def _fertilizer_named_or_given(cls, value: Any) -> Any:
        """A name, or an inline fertilizer validated with the library's schema (its first
        problem named by its key under `fertilizer.`)."""
        if isinstance(value, FertilizerSpec):
            return value
        if isinstance(value, Mapping):
            try:
                return FertilizerSpec.model_validate(dict(value))
            except ValidationError as exc:
                problem = format_validation_error(exc, FertilizerSpec, "")
                raise ValueError(f"{problem.key}: {problem.message}") from None
        if not isinstance(value, str) or not value:
            raise ValueError(f"a fertilizer name or a mapping of its properties, got {brief(value)}")
        return value

    @model_validator(mode="after")
    def _work_bounded(self) -> "Scene":
        copies = granule_copies(self)
        if copies > MAX_GRANULE_COPIES:
            discs = "" if self.twin is None else " x 2 discs"
            raise ValueError(f"sim.granules: {self.sim.granules} x sim.angle_copies {self.sim.angle_copies}{discs} "
                             f"= {copies} landing points per run; allowed: at most {MAX_GRANULE_COPIES} "
                             "(lower sim.granules or sim.angle_copies)")
        return self

    @model_validator(mode="after")
    def _one_pass_models_the_field(self) -> "Scene":
        """Back-and-forth driving overlaps the simulated pass with its mirror image, which is
        the return pass only where the flight is the same both ways: a wind, fixed to the
        ground, blows the other way in a returning machine's frame, so those passes would
        need a second flight. Not modelled: refused rather than answered wrongly."""
        if self.pattern.driving == "back-and-forth" and any(w != 0.0 for w in self.flight.wind_m_s):
            raise ValueError(f"flight.wind_m_s: {list(self.flight.wind_m_s)} m/s with back-and-forth driving is not "
                             "modelled (the return passes fly in the reversed wind); allowed: [0, 0], or "
                             "pattern.driving racetrack")
        return self

    @model_validator(mode="after")
    def _geometry(self) -> "Scene":
        _check_disc(self.spinner, self.vanes, self.feed, "")
        centres = self.disc_centres_m
        radii = [self.spinner.radius_m]
        if self.twin is not None:
            second = self.second_disc()
            _check_disc(*second, "twin.")
            radii.append(second[0].radius_m)
            least = radii[0] + radii[1]
            if self.twin.spacing_m <= least:
                raise ValueError(f"twin.spacing_m: {self.twin.spacing_m:g} m puts the discs (radii {radii[0]:g} m, "
                                 f"{radii[1]:g} m) over each other; allowed: > {least:g} m, <= {MAX_SPACING_M:g} m")
        for i, plate in enumerate(self.deflectors):
            for (cx, cy), radius in zip(centres, radii):
                a, b = plate.endpoints()
                if _segment_distance_to_origin((a[0] - cx, a[1] - cy), (b[0] - cx, b[1] - cy)) <= radius:
                    where = f"the disc at x = {cx:g} m" if self.twin is not None else "the disc"
                    raise ValueError(f"deflectors[{i}]: the plate reaches inside {where} (radius {radius} m); "
                                     f"plates must stay outside every disc")
        return self

    @property
    def fertilizer_name(self) -> str:
        """The fertilizer's name for results and labels (an inline one's `name`, or "inline")."""
        return fertilizer_name(self.fertilizer)

    @property
    def vane_outer_radius_m(self) -> float:
        return _vane_outer_radius_m(self.spinner, self.vanes)

    @property
    def vane_material(self) -> str:
        return self.vanes.material or self.spinner.material

    @property
    def disc_centres_m(self) -> list[tuple[float, float]]:
        """Disc axes in the machine frame (m): (0, 0) for one disc; with `twin`, the first
        disc at (+spacing/2, 0), right of the track, and the second at (-spacing/2, 0)."""
        if self.twin is None:
            return [(0.0, 0.0)]
        half = 0.5 * self.twin.spacing_m
        return [(half, 0.0), (-half, 0.0)]

    def second_disc(self) -> tuple[Spinner, Vanes, Feed]:
        """The second disc of a twin scene: the first disc's mirror image across the
        machine's centreline (opposite sense of rotation, feed angle 180 deg - angle, the
        per-vane pitches in mirrored order), with the keys `twin` sets replacing these."""
        if self.twin is None:
            raise ValueError("twin: this scene has one disc")
        spinner, vanes, feed = mirror_disc(self.spinner, self.vanes, self.feed)
        return (_merged(Spinner, spinner, self.twin.spinner, "twin.spinner"),
                _merged(Vanes, vanes, self.twin.vanes, "twin.vanes"), _merged(Feed, feed, self.twin.feed, "twin.feed"))


def mirror_disc(spinner: Spinner, vanes: Vanes, feed: Feed) -> tuple[Spinner, Vanes, Feed]:
    """The mirror image (x -> -x) of a disc about its own axis.

    Vane k stands at angle 2 pi k / N with its pitch leaning in the direction of
    rotation, so the mirror keeps every pitch and reverses the order of the vanes after
    the first (vane k of the mirror is vane N - k of the original); so does a list of
    inner radii."""

    def reordered(values):
        return [values[0], *values[:0:-1]] if isinstance(values, list) else values

    pitch, inner = reordered(vanes.pitch_deg), reordered(vanes.inner_radius_m)
    mirrored_angle = 180.0 - feed.angle_deg
    if mirrored_angle > MAX_ANGLE_DEG:
        mirrored_angle -= 360.0
    return (spinner.model_copy(update={"direction": "cw" if spinner.direction == "ccw" else "ccw"}),
            vanes.model_copy(update={"pitch_deg": pitch, "inner_radius_m": inner}),
            feed.model_copy(update={"angle_deg": mirrored_angle}))


def _merged(model: type[ModelT], base: StrictModel, overrides: StrictModel, key: str) -> ModelT:
    """`base` with the keys `overrides` sets (non-null), validated as `model`; a problem
    is a ValueError naming the key under `key`."""
    changes = {k: v for k, v in overrides.model_dump().items() if v is not None}
    try:
        return model.model_validate({**base.model_dump(), **changes})
    except ValidationError as exc:
        raise ValueError(f"{key}.{format_validation_error(exc, model, key)}") from None


def _vane_outer_radius_m(spinner: Spinner, vanes: Vanes) -> float:
    return vanes.outer_radius_m if vanes.outer_radius_m is not None else spinner.radius_m


def _check_disc(spinner: Spinner, vanes: Vanes, feed: Feed, prefix: str) -> None:
    """The checks within one disc; `prefix` ("" or "twin.") names the keys of the second disc."""
    radius = spinner.radius_m
    outer = _vane_outer_radius_m(spinner, vanes)
    if outer > radius + 1e-12:
        raise ValueError(f"{prefix}vanes.outer_radius_m: {outer} m is longer than the disc radius {radius} m")
    longest_start = max(vanes.inner_radii_m())
    if longest_start >= outer:
        raise ValueError(
            f"{prefix}vanes.inner_radius_m: {longest_start} m must be below the outer radius {outer} m"
        )
    tip_speed = spinner.rpm * RPM_TO_RAD_S * radius
    if tip_speed > MAX_TIP_SPEED_M_S:
        raise ValueError(f"{prefix}spinner.rpm: {spinner.rpm:g} rpm on a {radius:g} m disc is a rim speed of "
                         f"{tip_speed:.0f} m/s; allowed up to {MAX_TIP_SPEED_M_S:g} m/s")
    if feed.spread_m > radius:
        raise ValueError(f"{prefix}feed.spread_m: {feed.spread_m:g} m is wider than the disc radius {radius:g} m")
    if feed.radius_m >= radius:
        raise ValueError(f"{prefix}feed.radius_m: {feed.radius_m} m must be inside the disc radius {radius} m")
    if feed.radius_range_m is not None and not (0.0 <= feed.radius_range_m[0] and feed.radius_range_m[1] < radius):
        lo, hi = feed.radius_range_m
        raise ValueError(f"{prefix}feed.radius_range_m: [{lo:g}, {hi:g}] m must lie within [0, {radius:g}) m, "
                         "inside the disc")


def _segment_distance_to_origin(a: tuple[float, float], b: tuple[float, float]) -> float:
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    length2 = dx * dx + dy * dy
    t = max(0.0, min(1.0, -(ax * dx + ay * dy) / length2)) if length2 > 0 else 0.0
    return math.hypot(ax + t * dx, ay + t * dy)


def granule_copies(scene: Scene, runs: int = 1) -> int:
    """Landing points `runs` runs of `scene` hold at most: granules x angle copies x discs x runs."""
    return int(runs) * scene.sim.granules * scene.sim.angle_copies * (1 if scene.twin is None else 2)


def check_pooled_work(scene: Scene, runs: int, flag: str) -> None:
    """Refuse `runs` pooled runs of `scene` (all landing points kept) beyond
    `MAX_GRANULE_COPIES`, naming `flag` (e.g. "--replicates") and the keys that set the rest."""
    copies = granule_copies(scene, runs)
    if copies > MAX_GRANULE_COPIES:
        raise ConfigError(flag, f"{runs} runs x {granule_copies(scene)} landing points per run (sim.granules x "
                                f"sim.angle_copies{'' if scene.twin is None else ' x 2 discs'}) = {copies}; "
                                f"allowed: at most {MAX_GRANULE_COPIES} in all (fewer runs or granules)")


def scene_from_dict(raw: Mapping[str, Any]) -> Scene:
    """Validate a scene mapping; the first problem becomes a ConfigError naming its key."""
    return validate(Scene, dict(raw), "scene")


def load_scene_dict(name_or_path: str = "paper") -> dict:
    """The raw mapping of a shipped scene name or a YAML path."""
    raw = read_yaml(resolve_named("scenes", name_or_path))
    if not isinstance(raw, dict):
        raise ConfigError("scene", f"{name_or_path!r} does not hold a mapping")
    return raw


def load_scene(name_or_path: str = "paper", overrides: Optional[Mapping[str, Any]] = None,
               materials: Optional[Path] = None) -> Scene:
    """Load, override (dotted keys) and validate a scene. With a user's `materials` file, a
    fertilizer it adds or changes is put inline into the scene (`fertilizer_value`)."""
    scene = scene_from_dict(load_scene_dict(name_or_path))
    scene = scene_with(scene, overrides) if overrides else scene
    if materials is None or not isinstance(scene.fertilizer, str):
        return scene
    try:
        value = load_library(extra=materials).fertilizer_value(scene.fertilizer)
    except MaterialError as exc:
        raise ConfigError("fertilizer", str(exc)) from None
    return scene if isinstance(value, str) else scene_with(scene, {"fertilizer": value})


def scene_with(scene: Scene, overrides: Mapping[str, Any]) -> Scene:
    """A validated copy of `scene` with dotted-key overrides applied.

    Overrides act on the full dump (defaults included), so an optional key the YAML
    left out can still be set. The dump is a fresh tree: it is changed in place.
    """
    return scene_from_dict(set_in_place(scene.model_dump(), overrides, Scene))
