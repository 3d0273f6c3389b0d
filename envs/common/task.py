"""What both environments share: the base scene, the job (context) drawn per episode and
its encoding, one simulated tray test, reset options and infos.

Determinism: `Task.sample_context` draws, in this order, the fertilizer, the spinner
material, the target swath (as a number of trays), the forward speed and the wind
(x, y) from the env's `np_random`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from spreadgym import device
from spreadgym.config.base import brief
from spreadgym.config.materials import load_library
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
        self.library = load_library()
        # a job's scene would be rebuilt and re-validated every episode (scenes are immutable);
        # a plain dict, so the task still pickles and deep-copies
        self._jobs: dict[Context, tuple[Scene, dict[str, float]]] = {}
        base = load_scene(cfg.scene, cfg.scene_overrides)
        try:
            self.base_scene = base if cfg.granules is None else scene_with(base, {"sim.granules": cfg.granules})
        except ConfigError as exc:  # the bound on a run's work: `granules` is the env's key for it
            raise ConfigError("granules" if exc.key == "sim.granules" else exc.key, exc.message) from None
        ctx = cfg.context
        for name in ctx.fertilizers:
            try:
                self.library.fertilizer(name)
            except MaterialError as exc:
                raise ConfigError("context.fertilizers", str(exc)) from None
        for name in ctx.spinner_materials:
            try:
                self.library.check_surface(name)
            except MaterialError as exc:
                raise ConfigError("context.spinner_materials", str(exc)) from None
        self.tray_width_m = self.base_scene.pattern.tray_width_m
        lo, hi = ctx.target_swath_m
        self.tray_counts = (
            max(MIN_BOUT_TRAYS, math.ceil(lo / self.tray_width_m - 1e-9)),
            math.floor(hi / self.tray_width_m + 1e-9),
        )
        if self.tray_counts[0] > self.tray_counts[1]:
            raise ConfigError(
                "context.target_swath_m",
                f"[{lo}, {hi}] m holds no multiple of the tray width {self.tray_width_m} m of at least "
                f"{MIN_BOUT_TRAYS} trays",
            )
        self.settings_map = SettingsMap(self.base_scene, cfg.settings)
        # Every fertilizer/material pair must resolve and the model must accept the scene.
        for fertilizer in ctx.fertilizers:
            for material in ctx.spinner_materials:
                probe = Context(fertilizer, material, self.tray_counts[0] * self.tray_width_m,
                                ctx.forward_speed_m_s[0], (ctx.wind_x_m_s[0], ctx.wind_y_m_s[0]))
                scene = self.context_scene(probe)
                try:
                    resolve_contacts(scene, self.library)
                except MaterialError as exc:
                    raise ConfigError("context", f"{fertilizer} on {material}: {exc}") from None
                choose_model(scene, cfg.model)
        for end in (-1.0, 1.0):
            settings = self.settings_map.to_settings(np.full(self.settings_map.size, end))
            scene_with(self.base_scene, self.settings_map.scene_overrides(settings))
        self.context_names = (
            [f"fertilizer={f}" for f in ctx.fertilizers]
            + [f"spinner_material={m}" for m in ctx.spinner_materials]
            + ["d50", "size_sd", "particle_density", "disc_friction", "vane_friction", "disc_restitution",
               "vane_restitution", "target_swath", "forward_speed", "wind_x", "wind_y"]
        )
        self.context_size = len(self.context_names)

    # -- context ---------------------------------------------------------------------
    def sample_context(self, rng: np.random.Generator) -> Context:
        ctx = self.cfg.context
        fertilizer = ctx.fertilizers[int(rng.integers(len(ctx.fertilizers)))]
        material = ctx.spinner_materials[int(rng.integers(len(ctx.spinner_materials)))]
        trays = int(rng.integers(self.tray_counts[0], self.tray_counts[1] + 1))
        speed = float(rng.uniform(*ctx.forward_speed_m_s))
        wind = (float(rng.uniform(*ctx.wind_x_m_s)), float(rng.uniform(*ctx.wind_y_m_s)))
        return Context(fertilizer, material, trays * self.tray_width_m, speed, wind)

    def replace_context(self, context: Context, given: Any) -> Context:
        """`context` with the fields of reset's `options["context"]` put in (checked)."""
        if not isinstance(given, dict):
            raise ConfigError("options.context", f"expected a mapping, got {type(given).__name__}")
        values = context.as_dict()
        for key, value in given.items():
            if key not in CONTEXT_KEYS:
                raise ConfigError(f"options.context.{key}", f"unknown key; known: {', '.join(CONTEXT_KEYS)}")
            values[key] = value
        ctx = self.cfg.context
        if values["fertilizer"] not in ctx.fertilizers:
            raise ConfigError("options.context.fertilizer", f"must be one of {ctx.fertilizers}")
        if values["spinner_material"] not in ctx.spinner_materials:
            raise ConfigError("options.context.spinner_material", f"must be one of {ctx.spinner_materials}")
        wind = values["wind_m_s"]
        if not (isinstance(wind, (list, tuple)) and len(wind) == 2):
            raise ConfigError("options.context.wind_m_s", f"expected [x, y], got {brief(wind)}")
        out = Context(values["fertilizer"], values["spinner_material"],
                      _real("target_swath_m", values["target_swath_m"]),
                      _real("forward_speed_m_s", values["forward_speed_m_s"]),
                      (_real("wind_m_s.0", wind[0]), _real("wind_m_s.1", wind[1])))
        self.context_scene(out)  # validates swath on the tray grid, speeds
        return out

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
        values = [1.0 if f == context.fertilizer else 0.0 for f in ctx.fertilizers]
        values += [1.0 if m == context.spinner_material else 0.0 for m in ctx.spinner_materials]
        values += [
            to_unit(d50, *D50_RANGE_M),
            to_unit(sd, *SIZE_SD_RANGE_M),
            to_unit(fert.particle_density_kg_m3, *DENSITY_RANGE_KG_M3),
            to_unit(contacts.disc_friction, *FRICTION_RANGE),
            to_unit(contacts.vane_friction, *FRICTION_RANGE),
            to_unit(contacts.disc_restitution, *RESTITUTION_RANGE),
            to_unit(contacts.vane_restitution, *RESTITUTION_RANGE),
            to_unit(context.target_swath_m, *ctx.target_swath_m),
            to_unit(context.forward_speed_m_s, *ctx.forward_speed_m_s),
            to_unit(context.wind_m_s[0], *ctx.wind_x_m_s),
            to_unit(context.wind_m_s[1], *ctx.wind_y_m_s),
        ]
        return np.asarray(values, dtype=np.float32)

    def context_info(self, context: Context) -> dict:
        """The context as plain data, with the fallback restitutions it needed (dotted keys)."""
        info = context.as_dict()
        info["fallback_restitution"] = dict(self._job(context)[1])  # a copy: the kept one stays
        return info

    # -- simulation ------------------------------------------------------------------
    def settings_scene(self, context_scene: Scene, settings: Settings, seed: int) -> Scene:
        return scene_with(context_scene, {**self.settings_map.scene_overrides(settings), "sim.seed": int(seed)})

    def run(self, scene: Scene, rendering: bool = False) -> SimulationResult:
        """One tray test (one run; with the `precision` option, runs pooled to that standard
        error); with `rendering`, a few paths over the disc are kept for the picture."""
        tracks = self.cfg.render.disc_tracks if rendering else 0
        with device.using(self.cfg.device):
            if self.cfg.precision is not None:
                return simulate_precisely(scene, self.cfg.precision, model=self.cfg.model, library=self.library,
                                          tracks=tracks).as_result()
            return run_scene(scene, model=self.cfg.model, library=self.library, ci=self.cfg.confidence_interval,
                             tracks=tracks)

    def run_batch(self, scenes: list[Scene]) -> list[SimulationResult]:
        """The tray tests of `scenes` as one batch (spreadgym.spread.batch), on the env's device."""
        with device.using(self.cfg.device):
            return run_batch(scenes, model=self.cfg.model, library=self.library, ci=self.cfg.confidence_interval)


def _real(key: str, value: Any) -> float:
    """A context number of reset's options as a float; anything but a real number is a ConfigError."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(f"options.context.{key}", f"expected a number, got {brief(value)}")
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
