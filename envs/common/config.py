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
from spreadgym.config.scene import MAX_WIND_M_S
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
    swath_draw: Literal["tray_grid", "continuous"] = Field(
        default="tray_grid",
        description="tray_grid: the target is a whole number of trays of pattern.tray_width_m (v0); continuous: "
                    "uniform in the range, each job's trays W / round(W / tray_width_m) wide")
    held_out_swath_m: list[tuple[Real, Real]] = Field(
        default_factory=list, max_length=16,
        description="bands of target swath never drawn in training (the evaluation's); continuous draws only")
    encoding: Literal["one_hot", "properties"] = Field(
        default="one_hot",
        description="one_hot: fertilizer and spinner material one-hot, then every property and job entry (v0); "
                    "properties: the material properties and only the job entries whose range is not one value, "
                    "so an unseen fertilizer is observed by what it is")

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
        return _check_range(v, -MAX_WIND_M_S, MAX_WIND_M_S, "m/s")  # the scene's own bound

    @field_validator("held_out_swath_m")
    @classmethod
    def _bands(cls, v):
        return [_check_range(band, 0.0, 100.0, "m") for band in v]

    @model_validator(mode="after")
    def _bands_need_continuous(self) -> "ContextConfig":
        if self.held_out_swath_m and self.swath_draw != "continuous":
            raise ValueError("held_out_swath_m needs swath_draw: continuous (bands of a tray grid would be "
                             "a few tray counts; list them as evaluation jobs instead)")
        lo, hi = self.target_swath_m
        covered = sum(max(0.0, min(b, hi) - max(a, lo)) for a, b in _merged(self.held_out_swath_m))
        if self.held_out_swath_m and covered >= hi - lo:
            raise ValueError(f"held_out_swath_m leaves nothing of target_swath_m [{lo}, {hi}] to train on")
        return self


def _merged(bands) -> list[tuple[float, float]]:
    """Bands sorted and merged where they overlap."""
    out: list[tuple[float, float]] = []
    for a, b in sorted(bands):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


class EvaluationConfig(StrictModel):
    """The evaluation jobs: every combination of these lists (`spreadgym evaluate` and
    `compare` score them; `split: eval` draws among them). With `held_out`, each job must lie
    outside the training contexts (an unseen fertilizer or material, a held-out swath band,
    or a speed or wind outside the training ranges): checked when the env is built."""

    fertilizers: list[str] = Field(min_length=1, max_length=64)
    spinner_materials: list[str] = Field(min_length=1, max_length=64)
    target_swath_m: list[Real] = Field(min_length=1, max_length=64)
    forward_speed_m_s: list[Real] = Field(default=[0.0], min_length=1, max_length=16)
    wind_m_s: list[tuple[Real, Real]] = Field(default=[(0.0, 0.0)], min_length=1, max_length=16)
    held_out: bool = Field(default=True, description="every job lies outside the training contexts (checked)")


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
        default=None, description="where the compiled spinner runs: cpu, or cuda "
                                  "(a GPU: `pip install spreadgym[cuda]`); null: SPREADGYM_DEVICE, else cpu "
                                  "(spreadgym.device)")
    materials: Optional[str] = Field(
        default=None, description="a materials file (configs/materials.yaml's layout) merged over the library, "
                                  "as `--materials`: its fertilizers can be named in context.fertilizers; null: "
                                  "SPREADGYM_MATERIALS's file, else the shipped library")
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
    evaluation: Optional[EvaluationConfig] = Field(
        default=None, description="the evaluation jobs (null: the v0 set of spreadgym evaluate)")
    split: Literal["train", "eval"] = Field(
        default="train", description="train: reset draws training contexts; eval: it draws among the evaluation jobs")
    variability: Optional[dict[str, Real]] = Field(
        default=None,
        description="null: the material properties are exact; a mapping (half-ranges of "
                    "configs/chart_variability.yaml, {} for its values): each episode draws a hidden batch from "
                    "that model, and the observation shows the nominal properties only")
    settings: SettingsConfig = SettingsConfig()
    reward: RewardConfig = RewardConfig()
    render: RenderConfig = RenderConfig()

    @field_validator("variability")
    @classmethod
    def _variability(cls, v):
        if v is None:
            return None
        from spreadgym.spread.variability import FACTORS, OFFSETS, check_half_range, default_variability

        known = FACTORS + OFFSETS
        merged = {key: float(value) for key, value in default_variability().items() if key in known}
        for key, value in v.items():
            if key not in known:
                raise ValueError(f"{key}: unknown key; known: {', '.join(known)}")
            merged[key] = check_half_range(key, key, value)
        return merged

    @model_validator(mode="after")
    def _split_needs_jobs(self) -> "DesignConfig":
        if self.split == "eval" and self.evaluation is None:
            raise ValueError("split: eval needs an evaluation section (the jobs to draw among)")
        return self

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
    start: Literal["any", "unsolved"] = Field(
        default="any",
        description="any: the first tray test is whatever the initial settings give (v0); unsolved: random initial "
                    "settings are redrawn until the first tray test misses the goal (at most start_draws draws)")
    start_draws: Integer = Field(default=16, ge=1, le=1000, description="draws of the unsolved start rule")
    observation: ObservationConfig = ObservationConfig()

    @model_validator(mode="after")
    def _start_needs_random(self) -> "TuningConfig":
        if self.start == "unsolved" and self.initial_settings != "random":
            raise ValueError("start: unsolved redraws the initial settings; it needs initial_settings: random")
        return self


SCHEMAS: dict[str, type[DesignConfig]] = {DESIGN: DesignConfig, TUNING: TuningConfig}


def _sections(schema: type[BaseModel]) -> set[str]:
    """Top-level keys whose value is a sub-model (merged rather than replaced)."""
    out = set()
    for name, field in schema.model_fields.items():
        ann = field.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            out.add(name)
    return out


MAX_EXTENDS = 8  # depth of `extends` chains
VECTOR_ONLY = {"workers": " (`workers` is an option of the SpinnerDesign vector env: "
                          "gym.make_vec(id, num_envs=N, workers=P))"}
"""Keys a SpinnerDesign env does not take because they belong to its vector env, with where they go."""


def read_env_yaml(source: str) -> dict:
    """The mapping of an env YAML (a shipped name or a path). A file may start from another
    with `extends: NAME`: its keys then go over that file's, sections merged key by key
    (as `gym.make` kwargs are), anything else replaced."""
    chain: list[dict] = []
    while source is not None:
        raw = read_yaml(resolve_named("envs", source))
        if not isinstance(raw, dict):
            raise ConfigError("config", f"{brief(source)} does not hold a mapping")
        chain.append(raw)
        source = raw.get("extends")
        if source is not None and not isinstance(source, str):
            raise ConfigError("extends", f"expected a config name or YAML path, got {brief(source)}")
        if len(chain) > MAX_EXTENDS:
            raise ConfigError("extends", f"more than {MAX_EXTENDS} files in the chain (a loop?)")
    merged: dict = {}
    for raw in reversed(chain):
        for key, value in raw.items():
            if key == "extends":
                continue
            if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
                merged[key] = {**merged[key], **value}
            else:
                merged[key] = value
    return merged


def load_env_config(name: str, overrides: Optional[Mapping[str, Any]] = None) -> DesignConfig:
    """Validated config of env `name` (`spinner_design` or `spreader_tuning`) with overrides."""
    if name not in SCHEMAS:
        raise ConfigError("env", f"unknown env config {brief(name)}; known: {', '.join(SCHEMAS)}")
    schema = SCHEMAS[name]
    overrides = dict(overrides or {})
    source = overrides.pop("config", name)
    if not isinstance(source, str):
        raise ConfigError("config", f"expected a config name or YAML path, got {brief(source)}")
    raw = read_env_yaml(source)
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
            hint = VECTOR_ONLY.get(key, "") if name == DESIGN else ""
            raise ConfigError(key, f"unknown key; known keys: {', '.join(sorted(known))}{hint}")
        if key in sections and isinstance(value, Mapping):
            assignments.update({f"{key}.{sub_key}": sub_value for sub_key, sub_value in value.items()})
        else:
            assignments[key] = value
    return validate(schema, apply_overrides(tree, assignments, schema), "config")
