"""Environment configs: `configs/envs/<name>.yaml`, validated, with `gym.make` kwargs on top.

Every key of the YAML can be overridden by a keyword argument of `gym.make` (or of
the env class):

* a top-level key replaces the value (`granules=100`, `model="pymunk"`);
* a section (`context`, `settings`, `reward`, `fallback_restitution`, `render`,
  `observation`) given as a dict is merged key by key into the YAML's section
  (`reward={"cv_weight": 2.0}` keeps the other reward weights);
* a dotted key sets one nested value (`**{"reward.cv_weight": 2.0}`);
* `config="path/to/file.yaml"` (or a shipped name) replaces the YAML the rest is
  applied to.

A key the schema does not know is an error (`ConfigError`) naming it, as is any
value out of range. The checks that need the scene or the material library (known
fertilizers and surfaces, a target range on the tray grid, model name) are made by
the environment when it is built (see `spreadgym.envs.common.task.Task`).
"""

from __future__ import annotations

import math
from typing import Any, Literal, Mapping, Optional

from pydantic import BaseModel, Field, field_validator, model_validator

from spreadgym.config.base import Integer, Real, StrictModel, brief, validate
from spreadgym.config.overrides import apply_overrides
from spreadgym.config.resources import read_yaml, resolve_named
from spreadgym.errors import ConfigError

DESIGN = "spinner_design"
TUNING = "spreader_tuning"


def _check_range(value: tuple[float, float], lo: float, hi: float, unit: str,
                 positive: bool = False) -> tuple[float, float]:
    """An ordered, finite [low, high] within [lo, hi]; with `positive`, low > 0."""
    a, b = float(value[0]), float(value[1])
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError(f"both ends must be finite, got [{a}, {b}]")
    if a > b:
        raise ValueError(f"lower end {a} is above the upper end {b}")
    if a < lo or b > hi:
        raise ValueError(f"[{a}, {b}] must lie within [{lo}, {hi}] {unit}")
    if positive and a <= 0:
        raise ValueError(f"the lower end must be > 0, got {a}")
    return a, b


class ContextConfig(StrictModel):
    """What `reset` samples (uniformly) with the env's `np_random`."""

    fertilizers: list[str] = Field(min_length=1, description="library names, one drawn per episode")
    spinner_materials: list[str] = Field(min_length=1, description="library surfaces, one drawn per episode")
    target_swath_m: tuple[Real, Real] = Field(description="range; the draw is a multiple of the tray width")
    forward_speed_m_s: tuple[Real, Real] = (0.0, 0.0)
    wind_x_m_s: tuple[Real, Real] = (0.0, 0.0)
    wind_y_m_s: tuple[Real, Real] = (0.0, 0.0)

    @field_validator("fertilizers", "spinner_materials")
    @classmethod
    def _each_once(cls, v):
        twice = next((name for i, name in enumerate(v) if name in v[:i]), None)
        if twice is not None:
            raise ValueError(f"{brief(twice)} is listed twice; give each name once")
        return v

    @field_validator("target_swath_m")
    @classmethod
    def _swath(cls, v):
        return _check_range(v, 0.0, 100.0, "m", positive=True)

    @field_validator("forward_speed_m_s")
    @classmethod
    def _speed(cls, v):
        return _check_range(v, 0.0, 20.0, "m/s")

    @field_validator("wind_x_m_s", "wind_y_m_s")
    @classmethod
    def _wind(cls, v):
        return _check_range(v, -30.0, 30.0, "m/s")


class SettingsConfig(StrictModel):
    """Ranges of the settings the action chooses (action -1 maps to the lower end)."""

    rpm: tuple[Real, Real] = (200.0, 1100.0)
    pitch_deg: tuple[Real, Real] = (-30.0, 30.0)
    pitch_per_vane: bool = Field(default=False, description="one pitch per vane instead of a shared one")
    deflectors: bool = Field(default=True, description="adjustable deflectors (angle_range_deg) are actions")
    feed: bool = Field(default=True, description="the drop point is an action where the scene gives it a range "
                                                 "(feed.radius_range_m, feed.angle_range_deg)")

    @field_validator("rpm")
    @classmethod
    def _rpm(cls, v):
        return _check_range(v, 0.0, 5000.0, "rpm", positive=True)

    @field_validator("pitch_deg")
    @classmethod
    def _pitch(cls, v):
        return _check_range(v, -60.0, 60.0, "deg")


class RewardConfig(StrictModel):
    """Weights of the penalty terms (see docs/environments.md)."""

    cv_weight: Real = Field(default=1.0, ge=0.0, le=1e3)
    swath_weight: Real = Field(default=0.5, ge=0.0, le=1e3)
    retained_weight: Real = Field(default=1.0, ge=0.0, le=1e3)
    cv_worst_percent: Real = Field(default=100.0, gt=0.0, le=1e4, description="CV that scores as worst")


class TuningRewardConfig(RewardConfig):
    step_cost: Real = Field(default=0.05, ge=0.0, le=1e3, description="subtracted every step")
    goal_bonus: Real = Field(default=1.0, ge=0.0, le=1e3, description="added on the step that reaches the goal")


class FallbackRestitution(StrictModel):
    """Restitution used only for pairs the library did not measure (and the scene does not set)."""

    disc: Real = Field(default=0.43, ge=0.0, le=1.0)
    vane: Real = Field(default=0.43, ge=0.0, le=1.0)
    deflector: Real = Field(default=0.43, ge=0.0, le=1.0)


class RenderConfig(StrictModel):
    width_px: Integer = Field(default=640, ge=64, le=4096)
    height_px: Integer = Field(default=640, ge=64, le=4096)
    trajectories: Integer = Field(default=150, ge=0, le=100_000, description="granule flights drawn (field view)")
    disc_tracks: Integer = Field(
        default=10, ge=0, le=1000,
        description="granule paths over the disc recorded for the picture (render modes only)",
    )


class ObservationConfig(StrictModel):
    """The measured pattern in the tuning env's observation."""

    single_pass_bins: Integer = Field(default=40, ge=1, le=1000)
    single_pass_half_width_m: Real = Field(default=10.0, gt=0.0, le=200.0)
    bout_bins: Integer = Field(default=16, ge=1, le=1000)


CONTEXT_SETS = {
    "fertilizer": "context.fertilizers",
    "spinner.material": "context.spinner_materials",
    "pattern.target_swath_m": "context.target_swath_m",
    "flight.forward_speed_m_s": "context.forward_speed_m_s",
    "flight.wind_m_s": "context.wind_x_m_s and context.wind_y_m_s",
    "sim.granules": "granules",
    "sim.seed": "the seed of reset() (a granule sample is drawn from np_random each episode)",
}
"""Scene keys the env sets itself, and what sets them: a scene override of one would be ignored."""


def _sets(key: str, value: Any, replaced: str) -> bool:
    """Whether the override `key: value` sets the scene key `replaced` (or part of it)."""
    if key == replaced or key.startswith(replaced + "."):
        return True
    if not replaced.startswith(key + "."):
        return False
    for part in replaced[len(key) + 1:].split("."):
        if not isinstance(value, Mapping) or part not in value:
            return False
        value = value[part]
    return True


class DesignConfig(StrictModel):
    scene: str = Field(default="paper", description="shipped scene name or YAML path")
    scene_overrides: dict[str, Any] = Field(default_factory=dict, description="dotted scene keys")
    model: str = Field(default="auto", description="spinner model (see spreadgym.physics.selection)")
    device: Optional[Literal["cpu", "cuda"]] = Field(
        default=None, description="where the compiled spinner runs: cpu, or cuda (a GPU: `pip install "
                                  "spreadgym[cuda]`); null: SPREADGYM_DEVICE, else cpu (spreadgym.device)")
    granules: Optional[Integer] = Field(
        default=None, ge=1, le=1_000_000,
        description="granules simulated per step, each at sim.angle_copies release angles; null: the scene's own "
                    "sim.granules (2048 on every shipped scene)")
    precision: Optional[Real] = Field(
        default=None, ge=0.001, le=100.0,
        description="null: a fixed budget per step (one run of `granules`; the env's speed is its contract); "
                    "PP: runs pooled until the CV's standard error reaches PP percentage points, as "
                    "`spreadgym simulate --precision` does (slower, and the cost varies per step)")
    confidence_interval: bool = Field(default=False, description="the CV's 95 % t interval in info[\"metrics\"]")
    fallback_restitution: FallbackRestitution = FallbackRestitution()
    context: ContextConfig
    settings: SettingsConfig = SettingsConfig()
    reward: RewardConfig = RewardConfig()
    render: RenderConfig = RenderConfig()

    @model_validator(mode="after")
    def _overrides_not_replaced(self) -> "DesignConfig":
        for key, value in self.scene_overrides.items():
            for replaced, source in CONTEXT_SETS.items():
                if _sets(key, value, replaced):
                    raise ValueError(f"scene_overrides.{key}: the env sets {replaced} itself from {source}, "
                                     "so this override would be ignored; set that instead")
        return self


class TuningConfig(DesignConfig):
    reward: TuningRewardConfig = TuningRewardConfig()
    max_steps: Integer = Field(default=20, ge=1, le=100_000, description="truncation after this many steps")
    goal_cv_percent: Real = Field(default=15.0, gt=0.0, le=1e4, description="terminate at or below")
    max_change: Real = Field(
        default=0.25, gt=0.0, le=2.0,
        description="largest change per step, in normalised setting units (the full range is 2)",
    )
    initial_settings: Literal["random", "middle", "scene"] = Field(
        default="random", description="settings of the first tray test of an episode"
    )
    observation: ObservationConfig = ObservationConfig()


SCHEMAS: dict[str, type[DesignConfig]] = {DESIGN: DesignConfig, TUNING: TuningConfig}


def _sections(schema: type[BaseModel]) -> set[str]:
    """Top-level keys whose value is a sub-model (merged rather than replaced)."""
    out = set()
    for name, field in schema.model_fields.items():
        ann = field.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            out.add(name)
    return out


def load_env_config(name: str, overrides: Optional[Mapping[str, Any]] = None) -> DesignConfig:
    """Validated config of env `name` (`spinner_design` or `spreader_tuning`) with overrides."""
    if name not in SCHEMAS:
        raise ConfigError("env", f"unknown env config {brief(name)}; known: {', '.join(SCHEMAS)}")
    schema = SCHEMAS[name]
    overrides = dict(overrides or {})
    source = overrides.pop("config", name)
    if not isinstance(source, str):
        raise ConfigError("config", f"expected a config name or YAML path, got {brief(source)}")
    raw = read_yaml(resolve_named("envs", source))
    if not isinstance(raw, dict):
        raise ConfigError("config", f"{brief(source)} does not hold a mapping")
    # Validate the file alone first, so its own errors are reported as such, then work
    # on the full dump (defaults included) so any key can be overridden.
    tree = validate(schema, dict(raw), "config").model_dump(mode="python")
    sections = _sections(schema)
    known = set(schema.model_fields) | {"config"}
    assignments: dict[str, Any] = {}
    for key, value in overrides.items():
        if not isinstance(key, str):
            raise ConfigError(str(key), "keys must be strings")
        if "." not in key and key not in known:
            raise ConfigError(key, f"unknown key; known keys: {', '.join(sorted(known))}")
        if key in sections and isinstance(value, Mapping):
            assignments.update({f"{key}.{sub_key}": sub_value for sub_key, sub_value in value.items()})
        else:
            assignments[key] = value
    return validate(schema, apply_overrides(tree, assignments, schema), "config")
