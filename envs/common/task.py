"""What both environments share: the base scene, the job (context) drawn per episode and
its encoding, the evaluation jobs, the hidden batch of the robust variant, one simulated
tray test, reset options and infos.

Determinism: `Task.sample_context` draws, in this order, the fertilizer, the spinner
material, the target swath (a number of trays, or one uniform over the training widths
with `swath_draw: continuous`), the forward speed and the wind (x, y) from the env's
`np_random`; with `split: eval` it draws one job index instead. `Task.sample_batch`
(the robust variant only) then draws the batch's factors, one uniform each.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Optional

import numpy as np

from spreadgym import device
from spreadgym.config.base import brief
from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.config.scene import MIN_BOUT_TRAYS, Scene, load_scene, scene_with
from spreadgym.envs.common.actions import Settings, SettingsMap
from spreadgym.envs.common.config import DesignConfig
from spreadgym.errors import ConfigError, MaterialError
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.selection import choose_model
from spreadgym.spread.batch import run_batch
from spreadgym.spread.metrics import RunMetrics
from spreadgym.spread.pipeline import SimulationResult, run_scene
from spreadgym.spread.precision import simulate_precisely
from spreadgym.spread.variability import FACTORS, OFFSETS, Draw, draw_from_unit, draw_library, perturbed

SEED_BOUND = 2**31 - 1

# Fixed normalisation ranges of the material features of the context (value at -1, at +1).
D50_RANGE_M = (1e-3, 7e-3)
SIZE_SD_RANGE_M = (0.0, 2e-3)
DENSITY_RANGE_KG_M3 = (500.0, 2500.0)
FRICTION_RANGE = (0.0, 1.5)
RESTITUTION_RANGE = (0.0, 1.0)


@dataclass(frozen=True)
class Context:
    """The job of one episode."""

    fertilizer: str
    spinner_material: str
    target_swath_m: float
    forward_speed_m_s: float
    wind_m_s: tuple[float, float]

    def as_dict(self) -> dict:
        return {
            "fertilizer": self.fertilizer,
            "spinner_material": self.spinner_material,
            "target_swath_m": float(self.target_swath_m),
            "forward_speed_m_s": float(self.forward_speed_m_s),
            "wind_m_s": [float(self.wind_m_s[0]), float(self.wind_m_s[1])],
        }


CONTEXT_KEYS = tuple(Context.__dataclass_fields__)
PROPERTY_NAMES = ["d50", "size_sd", "particle_density", "disc_friction", "vane_friction", "disc_restitution",
                  "vane_restitution"]
JOB_NAMES = ["target_swath", "forward_speed", "wind_x", "wind_y"]


def job_tray_width_m(target_swath_m: float, tray_width_m: float) -> float:
    """The tray width of a continuous-swath job: the target in a whole number of trays as
    near `tray_width_m` as can be (at least MIN_BOUT_TRAYS trays), as a tester lays trays
    for the working width under test."""
    trays = max(MIN_BOUT_TRAYS, int(round(target_swath_m / tray_width_m)))
    return target_swath_m / trays


@dataclass(frozen=True)
class Batch:
    """The hidden batch of one episode (robust variant): a variability draw and the
    library holding its fertilizer copy (particle density scaled), named after the draw
    (`<fertilizer>~<crc32 of the draw>`), so that the copies of many episodes can share
    one library (`batches_library`) and their tray tests run as one batch."""

    draw: Draw
    library: MaterialLibrary

    def as_dict(self) -> dict:
        out = {name: float(self.draw.factors[name]) for name in FACTORS}
        out[OFFSETS[0]] = float(math.degrees(self.draw.pitch_offset_rad))
        return out


def batches_library(library: MaterialLibrary, batches: list) -> Optional[MaterialLibrary]:
    """`library` with the fertilizer copies of every hidden batch in `batches` (None where an
    episode has none), or None when two different copies share a name (then each episode
    runs with its own library)."""
    extra: dict = {}
    for batch in batches:
        if batch is None:
            continue
        for name, fertilizer in batch.library.fertilizers.items():
            if name in library.fertilizers:
                continue
            if name in extra and extra[name] != fertilizer:
                return None
            extra[name] = fertilizer
    return replace(library, fertilizers={**library.fertilizers, **extra})


def to_unit(value: float, lo: float, hi: float) -> float:
    """Linear map of [lo, hi] onto [-1, 1], clipped; 0 for an empty range."""
    if not hi > lo:
        return 0.0
    return float(min(1.0, max(-1.0, 2.0 * (value - lo) / (hi - lo) - 1.0)))


CONTEXT_SCENES_KEPT = 256
"""Jobs whose scenes a task keeps (all are dropped when it is full): the shipped contexts are fewer."""


class Task:
    """Base scene, context draw and encoding, and one simulated tray test."""

    def __init__(self, cfg: DesignConfig):
        self.cfg = cfg
        if cfg.device is not None:
            device.checked(cfg.device, "device")  # a GPU asked for where there is none: fail at make
        self.library = self._library(cfg.materials)
        # a job's scene would be rebuilt and re-validated every episode (scenes are immutable);
        # a plain dict, so the task still pickles and deep-copies
        self._jobs: dict[Context, tuple[Scene, dict[str, float]]] = {}
        base = load_scene(cfg.scene, cfg.scene_overrides)
        try:
            self.base_scene = base if cfg.granules is None else scene_with(base, {"sim.granules": cfg.granules})
        except ConfigError as exc:  # the bound on a run's work: `granules` is the env's key for it
            raise ConfigError("granules" if exc.key == "sim.granules" else exc.key, exc.message) from None
        ctx, ev = cfg.context, cfg.evaluation
        self.fertilizers = list(dict.fromkeys([*ctx.fertilizers, *(ev.fertilizers if ev else [])]))
        self.spinner_materials = list(dict.fromkeys([*ctx.spinner_materials, *(ev.spinner_materials if ev else [])]))
        for name in self.fertilizers:
            try:
                self.library.fertilizer(name)
            except MaterialError as exc:
                where = "context.fertilizers" if name in ctx.fertilizers else "evaluation.fertilizers"
                raise ConfigError(where, str(exc)) from None
        for name in self.spinner_materials:
            try:
                self.library.check_surface(name)
            except MaterialError as exc:
                where = "context.spinner_materials" if name in ctx.spinner_materials else "evaluation.spinner_materials"
                raise ConfigError(where, str(exc)) from None
        self.tray_width_m = self.base_scene.pattern.tray_width_m
        lo, hi = ctx.target_swath_m
        self.continuous = ctx.swath_draw == "continuous"
        self.tray_counts = (
            max(MIN_BOUT_TRAYS, math.ceil(lo / self.tray_width_m - 1e-9)),
            math.floor(hi / self.tray_width_m + 1e-9),
        )
        if self.continuous:
            self.training_swaths_m = _free_segments((lo, hi), ctx.held_out_swath_m)
            if lo < MIN_BOUT_TRAYS * self.tray_width_m * 0.5:
                raise ConfigError("context.target_swath_m", f"[{lo}, {hi}] m: the narrowest job must be at least "
                                  f"{MIN_BOUT_TRAYS} trays of about {self.tray_width_m} m")
        elif self.tray_counts[0] > self.tray_counts[1]:
            raise ConfigError(
                "context.target_swath_m",
                f"[{lo}, {hi}] m holds no multiple of the tray width {self.tray_width_m} m of at least "
                f"{MIN_BOUT_TRAYS} trays",
            )
        self.settings_map = SettingsMap(self.base_scene, cfg.settings)
        first_width = lo if self.continuous else self.tray_counts[0] * self.tray_width_m
        # Every fertilizer/material pair must resolve and the model must accept the scene.
        for fertilizer in self.fertilizers:
            for material in self.spinner_materials:
                probe = Context(fertilizer, material, first_width,
                                ctx.forward_speed_m_s[0], (ctx.wind_x_m_s[0], ctx.wind_y_m_s[0]))
                scene = self.context_scene(probe)
                try:
                    resolve_contacts(scene, self.library)
                except MaterialError as exc:
                    raise ConfigError("context", f"{fertilizer} on {material}: {exc}") from None
                choose_model(scene, cfg.model, self.library)
        for end in (-1.0, 1.0):
            settings = self.settings_map.to_settings(np.full(self.settings_map.size, end))
            scene_with(self.base_scene, self.settings_map.scene_overrides(settings))
        if ctx.encoding == "one_hot":
            self.job_entries = list(JOB_NAMES)
            self.context_names = ([f"fertilizer={f}" for f in ctx.fertilizers]
                                  + [f"spinner_material={m}" for m in ctx.spinner_materials]
                                  + PROPERTY_NAMES + self.job_entries)
        else:  # what a fertilizer is, not which: an unseen one is observed by its properties
            ranges = [ctx.target_swath_m, ctx.forward_speed_m_s, ctx.wind_x_m_s, ctx.wind_y_m_s]
            self.job_entries = [name for name, (a, b) in zip(JOB_NAMES, ranges) if b > a]
            self.context_names = PROPERTY_NAMES + self.job_entries
        self.context_size = len(self.context_names)
        self.evaluation_jobs = self._evaluation_jobs()

    # -- context ---------------------------------------------------------------------
    def sample_context(self, rng: np.random.Generator) -> Context:
        if self.cfg.split == "eval":
            return self.evaluation_jobs[int(rng.integers(len(self.evaluation_jobs)))]
        ctx = self.cfg.context
        fertilizer = ctx.fertilizers[int(rng.integers(len(ctx.fertilizers)))]
        material = ctx.spinner_materials[int(rng.integers(len(ctx.spinner_materials)))]
        if self.continuous:
            swath = _point_in(self.training_swaths_m, float(rng.uniform()))
        else:
            swath = int(rng.integers(self.tray_counts[0], self.tray_counts[1] + 1)) * self.tray_width_m
        speed = float(rng.uniform(*ctx.forward_speed_m_s))
        wind = (float(rng.uniform(*ctx.wind_x_m_s)), float(rng.uniform(*ctx.wind_y_m_s)))
        return Context(fertilizer, material, swath, speed, wind)

    def is_training_context(self, context: Context) -> bool:
        """Whether training (`split: train`) can draw `context`."""
        ctx = self.cfg.context
        swath = context.target_swath_m
        if self.continuous:
            on_swath = any(a <= swath <= b for a, b in self.training_swaths_m)
        else:
            trays = swath / self.tray_width_m
            on_swath = abs(trays - round(trays)) < 1e-9 and self.tray_counts[0] <= round(trays) <= self.tray_counts[1]
        return (context.fertilizer in ctx.fertilizers and context.spinner_material in ctx.spinner_materials
                and on_swath and _within(context.forward_speed_m_s, ctx.forward_speed_m_s)
                and _within(context.wind_m_s[0], ctx.wind_x_m_s) and _within(context.wind_m_s[1], ctx.wind_y_m_s))

    def _evaluation_jobs(self) -> list[Context]:
        """The evaluation section's jobs (fertilizer-major order), each checked held out where it says so."""
        ev = self.cfg.evaluation
        if ev is None:
            return []
        jobs = [Context(f, m, float(w), float(v), (float(wind[0]), float(wind[1])))
                for f in ev.fertilizers for w in ev.target_swath_m for m in ev.spinner_materials
                for v in ev.forward_speed_m_s for wind in ev.wind_m_s]
        for job in jobs:
            self.context_scene(job)  # on the tray grid, speeds and wind in range
            if ev.held_out and self.is_training_context(job):
                raise ConfigError("evaluation", f"the job {job.as_dict()} is also a training context; evaluation "
                                  "jobs must be held out (an unseen fertilizer or material, a width in "
                                  "context.held_out_swath_m, or a speed or wind outside the training ranges)")
        return jobs

    def sample_batch(self, context: Context, rng: np.random.Generator) -> Optional[Batch]:
        """The hidden batch of an episode (robust variant: one uniform per quantity of the
        variability model, in its order), or None where the properties are exact."""
        variability = self.cfg.variability
        if variability is None:
            return None
        unit = rng.uniform(-1.0, 1.0, len(FACTORS) + len(OFFSETS))
        draw = draw_from_unit(variability, unit, zlib.crc32(unit.tobytes()), 0)
        return Batch(draw, draw_library(self.library, context.fertilizer, [draw]))

    def replace_context(self, context: Context, given: Any) -> Context:
        """`context` with the fields of reset's `options["context"]` put in (checked)."""
        if not isinstance(given, dict):
            raise ConfigError("options.context", f"expected a mapping, got {type(given).__name__}")
        values = context.as_dict()
        for key, value in given.items():
            if key not in CONTEXT_KEYS:
                raise ConfigError(f"options.context.{key}", f"unknown key; known: {', '.join(CONTEXT_KEYS)}")
            values[key] = value
        if values["fertilizer"] not in self.fertilizers:
            raise ConfigError("options.context.fertilizer", f"must be one of {self.fertilizers}")
        if values["spinner_material"] not in self.spinner_materials:
            raise ConfigError("options.context.spinner_material", f"must be one of {self.spinner_materials}")
        wind = values["wind_m_s"]
        if not (isinstance(wind, (list, tuple)) and len(wind) == 2):
            raise ConfigError("options.context.wind_m_s", f"expected [x, y], got {brief(wind)}")
        out = Context(values["fertilizer"], values["spinner_material"],
                      _real("target_swath_m", values["target_swath_m"]),
                      _real("forward_speed_m_s", values["forward_speed_m_s"]),
                      (_real("wind_m_s.0", wind[0]), _real("wind_m_s.1", wind[1])))
        self.context_scene(out)  # validates swath on the tray grid, speeds
        return out

    def check_context(self, given: Any) -> None:
        """Refuse reset's `options["context"]` as `replace_context` would refuse it, on a
        fixed context (what the vector env checks before any sub-env resets)."""
        self.replace_context(self.sample_context(np.random.default_rng(0)), given)

    def context_scene(self, context: Context) -> Scene:
        """The base scene set up for one job, with the fallback restitution where needed."""
        return self._job(context)[0]

    def _job(self, context: Context) -> tuple[Scene, dict[str, float]]:
        """The job's scene and the fallback restitutions it took (dotted keys), kept."""
        job = self._jobs.get(context)
        if job is None:
            if len(self._jobs) >= CONTEXT_SCENES_KEPT:
                self._jobs.clear()
            job = self._jobs[context] = self._build_job(context)
        return job

    def _build_job(self, context: Context) -> tuple[Scene, dict[str, float]]:
        overrides: dict[str, Any] = {
            "fertilizer": context.fertilizer,
            "spinner.material": context.spinner_material,
            "pattern.target_swath_m": context.target_swath_m,
            "flight.forward_speed_m_s": context.forward_speed_m_s,
            "flight.wind_m_s": list(context.wind_m_s),
        }
        if self.continuous:
            overrides["pattern.tray_width_m"] = job_tray_width_m(context.target_swath_m, self.tray_width_m)
        scene = scene_with(self.base_scene, overrides)
        extra = self.fallbacks(scene)
        return (scene_with(scene, extra) if extra else scene), extra

    def fallbacks(self, scene: Scene) -> dict[str, float]:
        """Dotted scene keys of the restitutions the library lacks and the scene leaves unset."""
        fallback = self.cfg.fallback_restitution
        measured = self.library.fertilizer_of(scene).restitution
        extra: dict[str, float] = {}
        if scene.contact.disc_restitution is None and measured.get(scene.spinner.material) is None:
            extra["contact.disc_restitution"] = fallback.disc
        if scene.contact.vane_restitution is None and measured.get(scene.vane_material) is None:
            extra["contact.vane_restitution"] = fallback.vane
        for i, plate in enumerate(scene.deflectors):
            if plate.restitution is None and measured.get(plate.material) is None:
                extra[f"deflectors.{i}.restitution"] = fallback.deflector
        return extra

    def encode_context(self, context: Context, scene: Scene) -> np.ndarray:
        """The normalised context (float32, every entry in [-1, 1])."""
        ctx = self.cfg.context
        fert = self.library.fertilizer(context.fertilizer)
        contacts = resolve_contacts(scene, self.library)
        d50 = scene.granule.diameter_m if scene.granule.diameter_m is not None else fert.size.d50_m
        sd = scene.granule.diameter_sd_m if scene.granule.diameter_sd_m is not None else fert.size.sd_m
        values = []
        if ctx.encoding == "one_hot":
            values += [1.0 if f == context.fertilizer else 0.0 for f in ctx.fertilizers]
            values += [1.0 if m == context.spinner_material else 0.0 for m in ctx.spinner_materials]
        values += [
            to_unit(d50, *D50_RANGE_M),
            to_unit(sd, *SIZE_SD_RANGE_M),
            to_unit(fert.particle_density_kg_m3, *DENSITY_RANGE_KG_M3),
            to_unit(contacts.disc_friction, *FRICTION_RANGE),
            to_unit(contacts.vane_friction, *FRICTION_RANGE),
            to_unit(contacts.disc_restitution, *RESTITUTION_RANGE),
            to_unit(contacts.vane_restitution, *RESTITUTION_RANGE),
        ]
        job = {"target_swath": to_unit(context.target_swath_m, *ctx.target_swath_m),
               "forward_speed": to_unit(context.forward_speed_m_s, *ctx.forward_speed_m_s),
               "wind_x": to_unit(context.wind_m_s[0], *ctx.wind_x_m_s),
               "wind_y": to_unit(context.wind_m_s[1], *ctx.wind_y_m_s)}
        values += [job[name] for name in self.job_entries]
        return np.asarray(values, dtype=np.float32)

    def context_info(self, context: Context) -> dict:
        """The context as plain data, with the fallback restitutions it needed (dotted keys)."""
        info = context.as_dict()
        info["fallback_restitution"] = dict(self._job(context)[1])  # a copy: the kept one stays
        return info

    @staticmethod
    def _library(materials: Optional[str]) -> MaterialLibrary:
        """The shipped library, with the user's `materials` file merged over it (the key's one-line error)."""
        if materials is None:
            return load_library()
        try:
            return load_library(extra=Path(materials))
        except (ConfigError, MaterialError) as exc:
            flag = isinstance(exc, ConfigError) and exc.key == "--materials"
            raise ConfigError("materials", exc.message if flag else str(exc)) from None

    # -- simulation ------------------------------------------------------------------
    def settings_scene(self, context_scene: Scene, settings: Settings, seed: int,
                       batch: Optional[Batch] = None) -> Scene:
        """The job's scene at `settings` with granule seed `seed`; under a hidden `batch`, its
        perturbed properties and the machine's offsets (the variability model's)."""
        overrides = self.settings_map.scene_overrides(settings)
        if batch is not None:
            overrides = perturbed(context_scene, overrides, batch.draw, batch.library)
        return scene_with(context_scene, {**overrides, "sim.seed": int(seed)})

    def run(self, scene: Scene, rendering: bool = False, batch: Optional[Batch] = None) -> SimulationResult:
        """One tray test (one run; with the `precision` option, runs pooled to that standard
        error); with `rendering`, a few paths over the disc are kept for the picture; under
        a hidden `batch`, with its library (the perturbed density)."""
        tracks = self.cfg.render.disc_tracks if rendering else 0
        library = self.library if batch is None else batch.library
        with device.using(self.cfg.device):
            if self.cfg.precision is not None:
                return simulate_precisely(scene, self.cfg.precision, model=self.cfg.model, library=library,
                                          tracks=tracks).as_result()
            return run_scene(scene, model=self.cfg.model, library=library, ci=self.cfg.confidence_interval,
                             tracks=tracks)

    def run_batch(self, scenes: list[Scene], library: Optional[MaterialLibrary] = None) -> list[SimulationResult]:
        """The tray tests of `scenes` as one batch (spreadgym.spread.batch), on the env's device,
        with `library` (default the task's; a hidden batch's holds each episode's fertilizer copy)."""
        with device.using(self.cfg.device):
            return run_batch(scenes, model=self.cfg.model, library=library or self.library,
                             ci=self.cfg.confidence_interval)


def _free_segments(span: tuple[float, float], bands) -> list[tuple[float, float]]:
    """`span` less the `bands` (each clipped to it), as sorted closed segments of positive length."""
    lo, hi = span
    out, at = [], lo
    for a, b in sorted(bands):
        if a > at:
            out.append((at, min(a, hi)))
        at = max(at, b)
        if at >= hi:
            break
    if at < hi:
        out.append((at, hi))
    return [(a, b) for a, b in out if b > a]


def _point_in(segments: list[tuple[float, float]], u: float) -> float:
    """The point at fraction `u` of the segments' total length, walking them in order."""
    total = sum(b - a for a, b in segments)
    left = u * total
    for a, b in segments:
        if left <= b - a:
            return a + left
        left -= b - a
    return segments[-1][1]


def _within(value: float, span) -> bool:
    return span[0] <= value <= span[1]


def _real(key: str, value: Any) -> float:
    """A context number of reset's options as a float; anything but a finite real number is a ConfigError."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(f"options.context.{key}", f"expected a number, got {brief(value)}")
    if not math.isfinite(value):
        raise ConfigError(f"options.context.{key}", f"expected a finite number, got {value}")
    return float(value)


RESET_OPTIONS = ("context",)


def check_reset_options(options: Any) -> None:
    """Reset options are a mapping of known keys; anything else is a ConfigError naming it."""
    if not isinstance(options, dict):
        raise ConfigError("options", f"expected a mapping, got {type(options).__name__}")
    for key in options:
        if key not in RESET_OPTIONS:
            raise ConfigError(f"options.{key}", f"unknown reset option; known: {', '.join(RESET_OPTIONS)}")


def info_metrics(metrics: RunMetrics) -> dict:
    """`simulate --json` metrics as plain Python data, without the wall-clock time.

    Arrays become lists (their length varies from run to run, which vector envs cannot
    stack) and the wall time is dropped so that infos are reproducible bit for bit."""
    return {k: _plain(v) for k, v in metrics.to_json().items() if k != "wall_s"}


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    return value
