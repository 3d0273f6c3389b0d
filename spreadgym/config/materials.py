"""The material library (configs/materials.yaml): fertilizers, surfaces, measured pairs.

All values are SI. Pair properties (friction, restitution, impact time) are looked up
per fertilizer-surface pair; a pair the paper did not measure raises MaterialError
naming the pair, so no scene runs on an invented number.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Mapping, Optional

from spreadgym.config.base import brief
from spreadgym.config.resources import config_dir, read_yaml
from spreadgym.errors import MaterialError

PAIR_QUANTITIES = ("friction", "restitution", "impact_time_s", "rolling_resistance")


@dataclass(frozen=True)
class SizeDistribution:
    """Granule diameter distribution: normal(d50, sd) truncated to [min, max], metres."""

    d50_m: float
    sd_m: float
    min_m: float
    max_m: float
    source: str


@dataclass(frozen=True)
class Fertilizer:
    """One granular material with its measured properties against each surface."""

    name: str
    description: str
    particle_density_kg_m3: float
    bulk_density_kg_m3: float
    repose_angle_deg: float
    test_conditions: Mapping[str, Optional[float]]
    friction: Mapping[str, Optional[float]]
    restitution: Mapping[str, Optional[float]]
    impact_time_s: Mapping[str, Optional[float]]
    rolling_resistance: Mapping[str, Optional[float]]
    paper_stiffness_n_per_m: Mapping[str, float]
    paper_damping_ns_per_m: Mapping[str, float]
    size: SizeDistribution

    def pair(self, quantity: str, surface: str) -> float:
        """Measured `quantity` (friction, restitution, impact_time_s) on `surface`."""
        table = getattr(self, quantity)
        if surface not in table:
            raise MaterialError(
                f"unknown surface {brief(surface)}; known surfaces: {', '.join(sorted(table))}"
            )
        value = table[surface]
        if value is None:
            raise MaterialError(
                f"{quantity} of the pair {self.name}/{surface} was not measured in the paper; "
                f"set it in the scene under contact: (or choose a measured pair)"
            )
        return float(value)


@dataclass(frozen=True)
class MaterialLibrary:
    fertilizers: Mapping[str, Fertilizer]
    surfaces: Mapping[str, str]

    def fertilizer(self, name: str) -> Fertilizer:
        try:
            return self.fertilizers[name]
        except KeyError:
            known = ", ".join(sorted(self.fertilizers))
            raise MaterialError(f"unknown fertilizer {brief(name)}; known: {known}") from None

    def check_surface(self, name: str) -> str:
        if name not in self.surfaces:
            known = ", ".join(sorted(self.surfaces))
            raise MaterialError(f"unknown surface material {brief(name)}; known: {known}")
        return name


def _fertilizer(name: str, raw: dict) -> Fertilizer:
    return Fertilizer(
        name=name,
        description=raw["description"],
        particle_density_kg_m3=float(raw["particle_density_kg_m3"]),
        bulk_density_kg_m3=float(raw["bulk_density_kg_m3"]),
        repose_angle_deg=float(raw["repose_angle_deg"]),
        test_conditions=dict(raw.get("test_conditions", {})),
        friction=dict(raw["friction"]),
        restitution=dict(raw["restitution"]),
        impact_time_s=dict(raw["impact_time_s"]),
        rolling_resistance=dict(raw.get("rolling_resistance") or {k: 0.0 for k in raw["friction"]}),
        paper_stiffness_n_per_m=dict(raw.get("paper_stiffness_n_per_m", {})),
        paper_damping_ns_per_m=dict(raw.get("paper_damping_ns_per_m", {})),
        size=SizeDistribution(**raw["size"]),
    )


@lru_cache(maxsize=4)
def load_library(path: Optional[Path] = None) -> MaterialLibrary:
    """Read the material library (the shipped one by default)."""
    raw = read_yaml(path or config_dir() / "materials.yaml")
    fertilizers = {name: _fertilizer(name, data) for name, data in raw["fertilizers"].items()}
    surfaces = {name: data["description"] for name, data in raw["surfaces"].items()}
    return MaterialLibrary(fertilizers=fertilizers, surfaces=surfaces)
