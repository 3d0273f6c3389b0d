"""Contact parameters of a scene: library pair values, unless the scene overrides them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from spreadgym.config.materials import Fertilizer, MaterialLibrary
from spreadgym.config.scene import Scene
from spreadgym.errors import MaterialError


@dataclass(frozen=True)
class PlateContact:
    friction: float
    restitution: float


@dataclass(frozen=True)
class Contacts:
    """Coefficients of every surface a granule can touch in this scene."""

    disc_friction: float
    disc_restitution: float
    vane_friction: float
    vane_restitution: float
    vane_contact_time_s: Optional[float]  # only the spring-damper model needs it
    vane_rolling_resistance: float  # mu_r: torque mu_r r N against the spin relative to the vane
    deflectors: tuple[PlateContact, ...]


def _pick(override: Optional[float], fertilizer: Fertilizer, quantity: str, surface: str) -> float:
    return float(override) if override is not None else fertilizer.pair(quantity, surface)


def resolve_contacts(scene: Scene, library: MaterialLibrary) -> Contacts:
    """Look every pair up; a pair the paper did not measure is an error naming it."""
    fertilizer = library.fertilizer_of(scene)

    def surface(name: str) -> str:
        return library.check_surface(name, fertilizer)

    disc, vane = surface(scene.spinner.material), surface(scene.vane_material)
    c = scene.contact
    try:
        contact_time = _pick(c.vane_contact_time_s, fertilizer, "impact_time_s", vane)
    except MaterialError:
        contact_time = None
    plates = tuple(
        PlateContact(
            friction=_pick(p.friction, fertilizer, "friction", surface(p.material)),
            restitution=_pick(p.restitution, fertilizer, "restitution", p.material),
        )
        for p in scene.deflectors
    )
    return Contacts(
        disc_friction=_pick(c.disc_friction, fertilizer, "friction", disc),
        disc_restitution=_pick(c.disc_restitution, fertilizer, "restitution", disc),
        vane_friction=_pick(c.vane_friction, fertilizer, "friction", vane),
        vane_restitution=_pick(c.vane_restitution, fertilizer, "restitution", vane),
        vane_contact_time_s=contact_time,
        vane_rolling_resistance=_pick(c.rolling_resistance, fertilizer, "rolling_resistance", vane),
        deflectors=plates,
    )


def runnable(scene: Scene, library: MaterialLibrary) -> Contacts:
    """The scene's contacts if its fertilizer can run on it (its density and size known and
    every pair the scene needs measured or set), else a MaterialError naming what is missing."""
    library.fertilizer_of(scene).granule_properties()
    return resolve_contacts(scene, library)
