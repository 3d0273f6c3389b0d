"""The material library: fertilizers, surfaces and their measured pairs, with provenance.

`configs/materials.yaml` is the shipped library; a user's materials file (`--materials
FILE`, same layout) is merged over it, and a scene may give its fertilizer inline (a
mapping under `fertilizer:` instead of a name). All three are validated by the same
schema (`FertilizerSpec`): unknown keys, negative densities, sizes out of order and pair
values out of range are one-line errors naming the key.

All values are SI. Pair properties (friction, restitution, impact time, rolling
resistance) are looked up per fertilizer-surface pair; a pair nobody measured is null,
and a scene that needs it raises MaterialError naming the pair, so no scene runs on an
invented number. A shipped fertilizer states the source of every number it holds
(`provenance`, checked by the tests); a user's or an inline one may.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterator, Mapping, Optional

from pydantic import Field, model_validator

from spreadgym.config.base import Real, StrictModel, brief, validate
from spreadgym.config.resources import config_dir, read_yaml
from spreadgym.errors import ConfigError, MaterialError

PAIR_QUANTITIES = ("friction", "restitution", "impact_time_s", "rolling_resistance")
INLINE_NAME = "inline"
"""The name of a scene's inline fertilizer that gives none."""

Friction = Optional[Real]
PairTable = dict[str, Optional[Real]]
_PAIR_RANGES = {"friction": (0.0, 2.0), "restitution": (0.0, 1.0), "impact_time_s": (0.0, 0.01),
                "rolling_resistance": (0.0, 2.0)}


class SizeSpec(StrictModel):
    """Granule diameter distribution: normal(d50, sd) truncated to [min, max], metres."""

    d50_m: Real = Field(gt=0, le=0.02)
    sd_m: Real = Field(ge=0, le=0.01)
    min_m: Real = Field(gt=0, le=0.02)
    max_m: Real = Field(gt=0, le=0.02)

    @model_validator(mode="after")
    def _ordered(self) -> "SizeSpec":
        if not self.min_m <= self.d50_m <= self.max_m:
            raise ValueError(f"sizes out of order: need min_m <= d50_m <= max_m, got {self.min_m:g} <= "
                             f"{self.d50_m:g} <= {self.max_m:g} m")
        return self


class FertilizerSpec(StrictModel):
    """One fertilizer as data: the schema of a library entry, a user's entry and an inline
    scene fertilizer. Pair tables map surface names to a value or null (not measured);
    `rolling_resistance` left out is 0 on every surface of the friction table (the
    loss-free roller); `provenance` maps a key (`friction`, or `friction.steel` for one
    entry) to "SOURCE: what was measured and how it became this number"."""

    name: Optional[str] = Field(default=None, description="inline only: the name results print")
    description: str = ""
    particle_density_kg_m3: Optional[Real] = Field(gt=0, le=10_000, description="null: not measured (cannot run)")
    bulk_density_kg_m3: Optional[Real] = Field(default=None, gt=0, le=10_000, description="informational")
    repose_angle_deg: Optional[Real] = Field(default=None, ge=0, le=90, description="informational")
    test_conditions: dict[str, Optional[Real]] = Field(default_factory=dict, description="informational")
    friction: PairTable = Field(description="surface -> sliding friction on the vanes and disc, [0, 2] or null")
    restitution: PairTable = Field(description="surface -> restitution of an impact, [0, 1] or null")
    impact_time_s: PairTable = Field(default_factory=dict,
                                     description="surface -> contact time of an impact, (0, 0.01] s or null "
                                                 "(the spring-damper model only)")
    rolling_resistance: Optional[PairTable] = Field(
        default=None, description="surface -> rolling resistance at the vanes, [0, 2] or null; left out: 0 on "
                                  "every surface of `friction` (loss-free rolling)")
    paper_stiffness_n_per_m: dict[str, Real] = Field(default_factory=dict,
                                                     description="the seed study's Table 3 (its consistency check)")
    paper_damping_ns_per_m: dict[str, Real] = Field(default_factory=dict,
                                                    description="the seed study's Table 3 (its consistency check)")
    size: Optional[SizeSpec] = Field(description="null: not measured (cannot run)")
    provenance: dict[str, str] = Field(default_factory=dict,
                                       description="key -> 'SOURCE: what was measured, how it became the number'")

    @model_validator(mode="after")
    def _pairs_in_range(self) -> "FertilizerSpec":
        for quantity, (lo, hi) in _PAIR_RANGES.items():
            table = getattr(self, quantity) or {}
            for surface, value in table.items():
                if value is None:
                    continue
                low_ok = value > lo if quantity == "impact_time_s" else value >= lo
                if not (low_ok and value <= hi):
                    bound = "(" if quantity == "impact_time_s" else "["
                    raise ValueError(f"{quantity}.{surface}: {value:g} outside {bound}{lo:g}, {hi:g}]")
        return self


@dataclass(frozen=True)
class SizeDistribution:
    """Granule diameter distribution: normal(d50, sd) truncated to [min, max], metres."""

    d50_m: float
    sd_m: float
    min_m: float
    max_m: float


@dataclass(frozen=True)
class Fertilizer:
    """One granular material with its properties against each surface (SI units)."""

    name: str
    description: str
    particle_density_kg_m3: Optional[float]
    bulk_density_kg_m3: Optional[float]
    repose_angle_deg: Optional[float]
    test_conditions: Mapping[str, Optional[float]]
    friction: Mapping[str, Optional[float]]
    restitution: Mapping[str, Optional[float]]
    impact_time_s: Mapping[str, Optional[float]]
    rolling_resistance: Mapping[str, Optional[float]]
    paper_stiffness_n_per_m: Mapping[str, float]
    paper_damping_ns_per_m: Mapping[str, float]
    size: Optional[SizeDistribution]
    provenance: Mapping[str, str]

    @classmethod
    def from_spec(cls, name: str, spec: FertilizerSpec) -> "Fertilizer":
        rolling = spec.rolling_resistance
        if rolling is None:
            rolling = {surface: 0.0 for surface in spec.friction}
        return cls(
            name=name, description=spec.description, particle_density_kg_m3=spec.particle_density_kg_m3,
            bulk_density_kg_m3=spec.bulk_density_kg_m3, repose_angle_deg=spec.repose_angle_deg,
            test_conditions=dict(spec.test_conditions), friction=dict(spec.friction),
            restitution=dict(spec.restitution), impact_time_s=dict(spec.impact_time_s),
            rolling_resistance=dict(rolling), paper_stiffness_n_per_m=dict(spec.paper_stiffness_n_per_m),
            paper_damping_ns_per_m=dict(spec.paper_damping_ns_per_m),
            size=None if spec.size is None else SizeDistribution(spec.size.d50_m, spec.size.sd_m, spec.size.min_m,
                                                                 spec.size.max_m),
            provenance=dict(spec.provenance),
        )

    def granule_properties(self) -> tuple[float, SizeDistribution]:
        """(particle density, size distribution): what sampling granules needs, or a
        MaterialError naming what was not measured."""
        missing = [key for key, value in (("particle_density_kg_m3", self.particle_density_kg_m3),
                                          ("size", self.size)) if value is None]
        if missing:
            raise MaterialError(f"{' and '.join(missing)} of {self.name} not measured; give them in a materials "
                                "file (--materials) or an inline fertilizer")
        return float(self.particle_density_kg_m3), self.size

    def pair(self, quantity: str, surface: str) -> float:
        """Measured `quantity` (friction, restitution, impact_time_s, rolling_resistance) on `surface`."""
        table = getattr(self, quantity)
        if surface not in table:
            known = ", ".join(sorted(table)) or "none"
            raise MaterialError(f"{quantity} of {self.name} is not given for the surface {brief(surface)} "
                                f"(given for: {known}); set it in the scene under contact: or in a materials file")
        value = table[surface]
        if value is None:
            raise MaterialError(
                f"{quantity} of the pair {self.name}/{surface} was not measured; "
                f"set it in the scene under contact: (or choose a measured pair)"
            )
        return float(value)


@dataclass(frozen=True)
class MaterialLibrary:
    fertilizers: Mapping[str, Fertilizer]
    surfaces: Mapping[str, str]
    sources: Mapping[str, str] = field(default_factory=dict)
    user_entries: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """The fertilizers a user's materials file added or changed, merged, as data (`fertilizer_value`)."""

    def fertilizer(self, name: str) -> Fertilizer:
        try:
            return self.fertilizers[name]
        except KeyError:
            known = ", ".join(sorted(self.fertilizers))
            raise MaterialError(f"unknown fertilizer {brief(name)}; known: {known}") from None

    def fertilizer_of(self, scene: Any) -> Fertilizer:
        """The fertilizer of a scene: its inline one, or the library entry it names."""
        chosen = scene.fertilizer
        if isinstance(chosen, FertilizerSpec):
            return Fertilizer.from_spec(chosen.name or INLINE_NAME, chosen)
        return self.fertilizer(chosen)

    def with_entries(self, entries: Mapping[str, Mapping[str, Any]]) -> "MaterialLibrary":
        """This library with `entries` (complete fertilizer entries by name, as `user_entries` holds them)
        over it: what a chart records of a user's materials file, so it runs anywhere from its manifest."""
        made = {name: Fertilizer.from_spec(name, validate(FertilizerSpec, dict(entry), f"fertilizers.{name}"))
                for name, entry in entries.items()}
        return replace(self, fertilizers={**self.fertilizers, **made},
                       user_entries={**self.user_entries, **entries})

    def with_inline(self, scene: Any) -> "MaterialLibrary":
        """This library with `scene`'s inline fertilizer under its name (over a library entry of that
        name), for code that names fertilizers (charts, the variability model's copies); itself otherwise."""
        if not isinstance(scene.fertilizer, FertilizerSpec):
            return self
        inline = self.fertilizer_of(scene)
        return replace(self, fertilizers={**self.fertilizers, inline.name: inline})

    def fertilizer_value(self, name: str) -> Any:
        """What a scene's `fertilizer:` should hold to run `name`: the name of a shipped entry,
        or, for one a user's materials file added or changed, the merged entry inline (so
        the scene carries it to workers, envs and pages that know the shipped library only)."""
        self.fertilizer(name)  # unknown: the one-line error
        entry = self.user_entries.get(name)
        return name if entry is None else {**entry, "name": name}

    def check_surface(self, name: str, fertilizer: Optional[Fertilizer] = None) -> str:
        """`name` if the library knows the surface, or `fertilizer` gives values for it."""
        known = {**dict.fromkeys(self.surfaces), **dict.fromkeys(fertilizer.friction if fertilizer else ())}
        if name not in known:
            raise MaterialError(f"unknown surface material {brief(name)}; known: {', '.join(sorted(known))}")
        return name


def fertilizer_name(chosen: Any) -> str:
    """The name results print for a scene's `fertilizer` value (a name or an inline spec)."""
    return (chosen.name or INLINE_NAME) if isinstance(chosen, FertilizerSpec) else str(chosen)


class LibraryFile(StrictModel):
    """The layout of a materials file (the shipped library or a user's)."""

    sources: dict[str, str] = Field(default_factory=dict)
    surfaces: dict[str, dict[str, str]] = Field(default_factory=dict)
    fertilizers: dict[str, dict[str, Any]] = Field(default_factory=dict)


def _merged(base: dict, over: dict) -> dict:
    """`over` laid on `base` key by key (mappings merged, everything else replaced)."""
    out = dict(base)
    for key, value in over.items():
        out[key] = _merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def _library(raws: list[tuple[str, dict]]) -> MaterialLibrary:
    """The library of the files `raws` ((label, mapping)), later ones merged over earlier ones:
    a fertilizer already there is updated key by key, a new one must be complete."""
    sources: dict[str, str] = {}
    surfaces: dict[str, str] = {}
    entries: dict[str, dict] = {}
    origin: dict[str, str] = {}  # the file that last gave each fertilizer's keys
    touched: set[str] = set()  # the fertilizers the files after the first added or changed
    for number, (label, raw) in enumerate(raws):
        if not isinstance(raw, dict):
            raise ConfigError(label, "must hold a mapping with fertilizers: (and optionally surfaces:, sources:)")
        parsed = validate(LibraryFile, raw, label)
        sources.update(parsed.sources)
        for name, surface in parsed.surfaces.items():
            surfaces[name] = surface.get("description", "")
        for name, entry in parsed.fertilizers.items():
            if not isinstance(entry, dict):
                raise ConfigError(f"{label}.fertilizers.{name}", "must be a mapping of the fertilizer's keys")
            entries[name] = _merged(entries.get(name, {}), entry)
            origin[name] = label
            if number > 0:
                touched.add(name)
    fertilizers = {}
    for name, entry in entries.items():
        try:
            spec = validate(FertilizerSpec, entry, "")
        except ConfigError as exc:
            key = ".".join(part for part in ("fertilizers", name, exc.key) if part)
            raise ConfigError(key, f"{exc.message} (in {origin[name]})") from None
        _check_pair_surfaces(name, spec, surfaces, origin[name])
        fertilizers[name] = Fertilizer.from_spec(name, spec)
    user = {name: {k: v for k, v in entries[name].items() if k != "provenance"} for name in sorted(touched)}
    return MaterialLibrary(fertilizers=fertilizers, surfaces=surfaces, sources=sources, user_entries=user)


def _check_pair_surfaces(name: str, spec: FertilizerSpec, surfaces: Mapping[str, str], label: str) -> None:
    """Every surface of a fertilizer's pair tables is one the library lists or its friction
    table gives (a new surface is introduced by its friction); else a ConfigError naming it
    (a misspelt surface would otherwise be kept and never used)."""
    known = {**dict.fromkeys(surfaces), **dict.fromkeys(spec.friction)}
    for quantity in PAIR_QUANTITIES[1:]:
        for surface in getattr(spec, quantity) or {}:
            if surface not in known:
                raise ConfigError(f"fertilizers.{name}.{quantity}.{surface}",
                                  f"unknown surface (in {label}); known: {', '.join(sorted(known))}")


MATERIALS_ENV = "SPREADGYM_MATERIALS"
"""A user's materials file merged over the shipped library wherever no other is named: set by
`serve --materials` and `chart --materials` for their worker processes (which inherit it),
or by a user for every command."""


def load_library(path: Optional[Path] = None, extra: Optional[Path] = None) -> MaterialLibrary:
    """Read the material library (the shipped one by default), with a user's materials
    file `extra` merged over it; the shipped library with neither named takes
    SPREADGYM_MATERIALS's file, if set, as `extra`."""
    flag = "--materials"
    if path is None and extra is None and os.environ.get(MATERIALS_ENV):
        extra, flag = Path(os.environ[MATERIALS_ENV]), MATERIALS_ENV
    return _load_library(path, extra, flag)


@contextmanager
def user_materials(path: Optional[Path]) -> Iterator[None]:
    """SPREADGYM_MATERIALS set to `path` (resolved) while the block runs, for this process and
    the processes it starts; nothing changes for None."""
    if path is None:
        yield
        return
    saved = os.environ.get(MATERIALS_ENV)
    os.environ[MATERIALS_ENV] = str(Path(path).resolve())
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop(MATERIALS_ENV, None)
        else:
            os.environ[MATERIALS_ENV] = saved


@lru_cache(maxsize=8)
def _load_library(path: Optional[Path], extra: Optional[Path], flag: str) -> MaterialLibrary:
    raws = [("materials", read_yaml(path or config_dir() / "materials.yaml"))]
    if extra is not None:
        raws.append((f"{flag} {extra}", read_yaml(regular_file(Path(extra), flag))))
    return _library(raws)


def regular_file(path: Path, flag: str) -> Path:
    """`path` if it is a regular file (a pipe or a device would block or never end a read)."""
    if not path.exists():
        raise ConfigError(flag, f"{path}: file not found")
    if not path.is_file():
        raise ConfigError(flag, f"{path}: not a regular file (a folder, pipe or device)")
    return path
