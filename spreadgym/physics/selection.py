"""The spinner models and deflector methods by name, and which model a scene gets.

`SPINNER_MODELS` maps a model name to its runner and to the deflector method that
carries its departures past the plates; adding a model is one entry. A runner is named
"module:function" and imported only when that model runs (the compiled model loads
numba, which costs seconds; listing the models loads none of them). Every runner takes
(scene, granules, contacts) and returns a `Departure`; stepped runners also take
`progress` (called with the simulated time, s) and `track_count` (paths kept for plots).

`auto` takes the cheapest model that is exact enough. `analytic` is exact (closed
forms, checked to 1e-9 against numerical solves) for a granule that starts on the
disc, including the bouncing catch by the vanes. It has no bounces on the disc after a
drop. Measured against pymunk on the paper spinner at drop 0 (400 granules,
200-1100 rpm, pitch -15..0 deg): departure speed within 0.09 % and direction within
0.09 deg at the measured vane restitution 0.43. So `auto` takes analytic when the feed
does not drop onto the disc, and the full pymunk model otherwise. `spring-damper` (the
paper's contact model, with the measured contact time) is never cheaper and agrees
with pymunk within 0.3 % on departure speed, so it is used only when asked for.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable, Optional

from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError
from spreadgym.physics.analytic.deflector_rays import deflect
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import Departure
from spreadgym.physics.granules import GranuleBatch
from spreadgym.physics.stepped.pymunk_deflectors import deflect_pymunk


def _deflect_by_rays(departure: Departure, scene: Scene, contacts: Contacts, granules: GranuleBatch) -> Departure:
    return deflect(departure, scene.deflectors, contacts.deflectors, granules.radius_m, scene.granule.rotation)


def _deflect_in_pymunk(departure: Departure, scene: Scene, contacts: Contacts, granules: GranuleBatch) -> Departure:
    return deflect_pymunk(departure, scene.deflectors, contacts.deflectors, granules.radius_m, granules.mass_kg,
                          scene.granule.rotation)


DEFLECTOR_METHODS: dict[str, Callable[[Departure, Scene, Contacts, GranuleBatch], Departure]] = {
    "rays": _deflect_by_rays,  # exact plan-view reflections (closed form)
    "pymunk": _deflect_in_pymunk,  # plates stepped in pymunk, with the spinner model's contact laws
}
"""Deflector method name -> function(departure, scene, contacts, granules) giving the launch state."""


@dataclass(frozen=True)
class SpinnerModel:
    """One spinner model: how to run it and what it serves."""

    name: str
    runner: str  # "module:function"
    deflector: str  # key of DEFLECTOR_METHODS
    serves: str  # what it is exact or meant for
    stepped: bool = True  # the runner takes progress= and track_count=

    def run(self, scene: Scene, granules: GranuleBatch, contacts: Contacts,
            progress: Optional[Callable[[float], None]] = None, tracks: int = 0) -> Departure:
        """Departure states of `granules` (`tracks` paths kept by stepped models)."""
        module, function = self.runner.split(":")
        simulate = getattr(importlib.import_module(module), function)
        if not self.stepped:
            return simulate(scene, granules, contacts)
        return simulate(scene, granules, contacts, progress=progress, track_count=tracks)

    def deflect(self, departure: Departure, scene: Scene, contacts: Contacts, granules: GranuleBatch) -> Departure:
        """States at the edge of the deflector zone, by this model's deflector method."""
        return DEFLECTOR_METHODS[self.deflector](departure, scene, contacts, granules)


SPINNER_MODELS: dict[str, SpinnerModel] = {m.name: m for m in (
    SpinnerModel("analytic", "spreadgym.physics.analytic.spinner:simulate_analytic", "rays",
                 "closed forms; exact without disc bounces (feed not dropping onto the disc)", stepped=False),
    SpinnerModel("pymunk", "spreadgym.physics.stepped.pymunk_spinner:simulate_pymunk", "pymunk",
                 "the full model: drop, disc bounces and drag, impulse contacts with the vanes"),
    SpinnerModel("spring-damper", "spreadgym.physics.stepped.spring_damper:simulate_spring_damper", "pymunk",
                 "the seed paper's spring-dashpot vane contact with the measured contact time"),
    SpinnerModel("compiled", "spreadgym.physics.compiled:simulate_compiled", "pymunk",
                 "the pymunk model's contact laws per granule, event-driven and compiled with numba"),
)}

MODELS = ("auto", *SPINNER_MODELS)


def choose_model(scene: Scene, requested: str = "auto") -> tuple[str, str]:
    """(model name, reason). `requested` other than auto is honoured as it is."""
    if requested not in MODELS:
        raise ConfigError("model", f"unknown model {requested!r}; allowed: {', '.join(MODELS)}")
    if requested != "auto":
        return requested, "requested"
    if scene.feed.drop_height_m > 0:
        return "pymunk", (f"auto: the feed drops {scene.feed.drop_height_m:g} m, and bounces on the disc "
                          "need the full model")
    return "analytic", "auto: the feed does not drop onto the disc, so the closed form is exact (no disc bounces)"
