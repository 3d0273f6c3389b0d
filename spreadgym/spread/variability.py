"""The variability model: how a real batch of fertilizer and a machine set by hand differ
from the nominal scene (configs/chart_variability.yaml). Robust chart cells
(`spreadgym chart --objective robust`) and the hidden-parameter environment
(`spreadgym/SpinnerDesignRobust-v1`) both draw from it.

A draw is one perturbed batch: factors on the disc and vane friction, the restitution
(disc and vanes alike), the median granule size and the particle density, a factor on
the disc speed and an offset of the vane pitch, each uniform within its half-range
(relative half-ranges, 0.15 = +-15 % of the nominal value; the pitch offset in degrees).

The perturbations map onto scene keys: `contact.disc_friction`, `contact.vane_friction`,
`contact.disc_restitution`, `contact.vane_restitution` (the nominal values are the
scene's resolved pairs), `granule.diameter_m` (the nominal d50), `spinner.rpm` and
`vanes.pitch_deg` (the candidate's settings). The density has no scene key: each draw
gets its own copy of the fertilizer in a library made for it (`draw_library`), named
`<fertilizer>~<draw>`, with the scaled particle density.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from spreadgym.config.materials import MaterialLibrary
from spreadgym.config.resources import config_dir, read_yaml
from spreadgym.config.scene import MAX_PITCH_DEG, MAX_RPM, MIN_RPM, Scene
from spreadgym.errors import SpreadgymError
from spreadgym.physics.contacts import resolve_contacts

VARIABILITY_FILE = "chart_variability.yaml"
FACTORS = ("disc_friction", "vane_friction", "restitution", "size_median", "density", "disc_speed")
OFFSETS = ("vane_pitch_deg",)
MAX_FACTOR = 0.5  # a relative half-range: a quantity within +-50 %
MAX_PITCH_OFFSET_DEG = 10.0


def default_variability() -> dict:
    """The shipped variability model (configs/chart_variability.yaml), counts included."""
    return dict(read_yaml(config_dir() / VARIABILITY_FILE)["variability"])


def check_half_range(where: str, key: str, value: Any) -> float:
    """A half-range of FACTORS (relative, [0, MAX_FACTOR]) or OFFSETS (degrees, [0,
    MAX_PITCH_OFFSET_DEG]); anything else is a SpreadgymError naming `where`."""
    high = MAX_PITCH_OFFSET_DEG if key in OFFSETS else MAX_FACTOR
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not (number and math.isfinite(value) and 0.0 <= value <= high):
        raise SpreadgymError(f"{where}: {value!r} is out of range; allowed [0, {high:g}]")
    return float(value)


@dataclass(frozen=True)
class Draw:
    """One perturbed batch: factors on each quantity of FACTORS, a pitch offset (rad), a granule seed."""

    index: int
    factors: dict
    pitch_offset_rad: float
    seed: int


def draw_from_unit(variability: dict, unit, index: int, seed: int) -> Draw:
    """The draw at `unit` (one value in [-1, 1] per FACTORS + OFFSETS entry, in that order)."""
    unit = [float(u) for u in unit]
    factors = {name: float(1.0 + variability[name] * u) for name, u in zip(FACTORS, unit)}
    return Draw(index, factors, math.radians(variability["vane_pitch_deg"] * unit[-1]), int(seed))


def draw_name(fertilizer: str, draw: Draw) -> str:
    return f"{fertilizer}~{draw.index}"


def draw_library(library: MaterialLibrary, fertilizer: str, cell_draws: list[Draw]) -> MaterialLibrary:
    """`library` plus one copy of `fertilizer` per draw, its particle density scaled."""
    base = library.fertilizer(fertilizer)
    extra = {draw_name(fertilizer, d): replace(base, name=draw_name(fertilizer, d),
                                               particle_density_kg_m3=base.particle_density_kg_m3
                                               * d.factors["density"]) for d in cell_draws}
    return replace(library, fertilizers={**library.fertilizers, **extra})


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
