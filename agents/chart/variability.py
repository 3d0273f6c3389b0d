"""The variability model of a robust chart cell: how a real batch of fertilizer and a
machine set by hand differ from the nominal scene (configs/chart_variability.yaml).

A draw is one perturbed batch: factors on the disc and vane friction, the restitution
(disc and vanes alike), the median granule size and the particle density, a factor on
the disc speed and an offset of the vane pitch, each uniform within its half-range. A
cell's draws are a scrambled Sobol set seeded from the cell's seed sequence, each with
its own granule seed, and every candidate of the cell is scored on the same draws
(common random numbers), so two candidates differ by their settings only.

The perturbations map onto scene keys: `contact.disc_friction`, `contact.vane_friction`,
`contact.disc_restitution`, `contact.vane_restitution` (the nominal values are the
scene's resolved pairs), `granule.diameter_m` (the nominal d50), `spinner.rpm` and
`vanes.pitch_deg` (the candidate's settings). The density has no scene key: each draw
gets its own copy of the fertilizer in a library made for the cell (`draw_library`),
named `<fertilizer>~<draw>`, with the scaled particle density.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping, Optional, Union

import numpy as np

from spreadgym.config.materials import MaterialLibrary
from spreadgym.config.resources import config_dir, read_yaml
from spreadgym.config.scene import MAX_PITCH_DEG, MAX_RPM, MIN_RPM, Scene
from spreadgym.errors import SpreadgymError
from spreadgym.physics.contacts import resolve_contacts

VARIABILITY_FILE = "chart_variability.yaml"
FACTORS = ("disc_friction", "vane_friction", "restitution", "size_median", "density", "disc_speed")
OFFSETS = ("vane_pitch_deg",)
COUNTS = {"draws": (2, 1024), "verify_draws": (2, 1024), "verify_runs_per_draw": (1, 8)}  # integers, ranges
MAX_FACTOR = 0.5  # a relative half-range: a quantity within +-50 %
MAX_PITCH_OFFSET_DEG = 10.0


def default_variability() -> dict:
    """The shipped variability model (configs/chart_variability.yaml)."""
    return dict(read_yaml(config_dir() / VARIABILITY_FILE)["variability"])


def check_variability(given: Union[None, str, Path, Mapping[str, Any]]) -> dict:
    """The defaults with `given` (a mapping, or a YAML file with a `variability` section)
    over them; an unknown key or a value out of range is a SpreadgymError naming it."""
    merged = default_variability()
    if given is None:
        return merged
    if isinstance(given, (str, Path)):
        raw = read_yaml(Path(given))
        if not (isinstance(raw, dict) and isinstance(raw.get("variability"), dict)):
            raise SpreadgymError(f"--variability {given}: expected a mapping under 'variability:'")
        given = raw["variability"]
    for key, value in given.items():
        where = f"variability.{key}"
        if key not in merged:
            raise SpreadgymError(f"{where}: unknown key; known: {', '.join(merged)}")
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if key in COUNTS:
            low, high = COUNTS[key]
            if not (number and float(value).is_integer() and low <= value <= high):
                raise SpreadgymError(f"{where}: {value!r} is out of range; allowed an integer in [{low}, {high}]")
            value = int(value)
        elif key == "quantile":
            if not (number and 0.5 <= value < 1.0):
                raise SpreadgymError(f"{where}: {value!r} is out of range; allowed [0.5, 1)")
        else:
            high = MAX_PITCH_OFFSET_DEG if key in OFFSETS else MAX_FACTOR
            if not (number and math.isfinite(value) and 0.0 <= value <= high):
                raise SpreadgymError(f"{where}: {value!r} is out of range; allowed [0, {high:g}]")
            value = float(value)
        merged[key] = value
    return merged


@dataclass(frozen=True)
class Draw:
    """One perturbed batch: factors on each quantity of FACTORS, a pitch offset (rad), a granule seed."""

    index: int
    factors: dict
    pitch_offset_rad: float
    seed: int


def child(seq: np.random.SeedSequence, i: int) -> np.random.SeedSequence:
    """The `i`-th child of `seq` (what `seq.spawn(n)[i]` gives a fresh sequence), without changing `seq`."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, i), pool_size=seq.pool_size)


def draws(variability: dict, count: int, seq: np.random.SeedSequence) -> list[Draw]:
    """`count` draws: a scrambled Sobol set over the half-ranges and one granule seed each."""
    from scipy.stats import qmc

    points_seq, seeds_seq = child(seq, 0), child(seq, 1)
    names = FACTORS + OFFSETS
    u = qmc.Sobol(len(names), scramble=True, seed=np.random.default_rng(points_seq)).random(count)
    seeds = seeds_seq.generate_state(count)
    out = []
    for k, row in enumerate(2.0 * u - 1.0):
        factors = {name: float(1.0 + variability[name] * v) for name, v in zip(FACTORS, row)}
        out.append(Draw(k, factors, math.radians(variability["vane_pitch_deg"] * float(row[-1])), int(seeds[k])))
    return out


def draw_name(fertilizer: str, draw: Draw) -> str:
    return f"{fertilizer}~{draw.index}"


def draw_library(library: MaterialLibrary, fertilizer: str, cell_draws: list[Draw]) -> MaterialLibrary:
    """`library` plus one copy of `fertilizer` per draw, its particle density scaled."""
    base = library.fertilizer(fertilizer)
    extra = {draw_name(fertilizer, d): replace(base, name=draw_name(fertilizer, d),
                                               particle_density_kg_m3=base.particle_density_kg_m3
                                               * d.factors["density"]) for d in cell_draws}
    return MaterialLibrary(fertilizers={**library.fertilizers, **extra}, surfaces=library.surfaces)


def perturbed(scene: Scene, settings: dict, draw: Draw, library: MaterialLibrary) -> dict:
    """Scene overrides of `settings` (the settings space's overrides) under `draw`, its granule seed included."""
    contacts = resolve_contacts(scene, library)
    fertilizer = library.fertilizer_of(scene)
    d50 = scene.granule.diameter_m if scene.granule.diameter_m is not None else fertilizer.size.d50_m
    f = draw.factors
    out = dict(settings)
    out["spinner.rpm"] = min(MAX_RPM, max(MIN_RPM, settings["spinner.rpm"] * f["disc_speed"]))
    offset = math.degrees(draw.pitch_offset_rad)
    if "vanes.pitch_deg" in settings:
        pitch = np.clip(np.asarray(settings["vanes.pitch_deg"], dtype=float) + offset, -MAX_PITCH_DEG, MAX_PITCH_DEG)
        out["vanes.pitch_deg"] = pitch.tolist()
    out.update({
        "fertilizer": draw_name(scene.fertilizer_name, draw),
        "contact.disc_friction": min(2.0, contacts.disc_friction * f["disc_friction"]),
        "contact.vane_friction": min(2.0, contacts.vane_friction * f["vane_friction"]),
        "contact.disc_restitution": min(1.0, contacts.disc_restitution * f["restitution"]),
        "contact.vane_restitution": min(1.0, contacts.vane_restitution * f["restitution"]),
        "granule.diameter_m": min(0.02, d50 * f["size_median"]),
        "sim.seed": draw.seed,
    })
    return out


def quantile(values, q: float) -> float:
    """The `q` quantile (linear between order statistics) of `values`."""
    return float(np.quantile(np.asarray(values, dtype=float), q))


def bootstrap_se(values, q: float, seq: np.random.SeedSequence, resamples: int = 1000) -> Optional[float]:
    """Standard error of the `q` quantile of `values`, by a seeded bootstrap."""
    values = np.asarray(values, dtype=float)
    if values.size < 2:
        return None
    rng = np.random.default_rng(seq)
    picks = rng.integers(0, values.size, (resamples, values.size))
    return float(np.std(np.quantile(values[picks], q, axis=1), ddof=1))

