"""The spinner models and deflector methods by name, and which model a scene gets.

`SPINNER_MODELS` maps a model name to its runner and to the deflector method that
carries its departures past the plates; adding a model is one entry. A runner is named
"module:function" and imported only when that model runs (the compiled model loads
numba, which costs seconds; listing the models loads none of them). Every runner takes
(scene, granules, contacts) and returns a `Departure`; stepped runners also take
`progress` (called with the simulated time, s) and `track_count` (paths kept for plots).

`auto` takes the cheapest model that is exact enough. `compiled` integrates the full
model's contact laws granule by granule (numba), about 200 times faster than `pymunk`
and as fast as the closed forms. Measured against the converged full model on the
reference family and the edges of the environments' action ranges (docs/fidelity.md):
the CV at the target within 0.5 pp on every scene (within 0.3 pp on 22 of 24, rolling
resistance 0-0.6 among them), the effective swath equal on all 21 reference scenes, the
departure-azimuth histograms within a total variation of 0.007. So `auto` takes `compiled` for
every scene inside the envelope that measurement covers (`VALIDATED`), and the full
`pymunk` model outside it, saying why.

`analytic` (closed forms; exact for its own assumptions: no bounces on the disc, disc
drag to first order) departs from the full model by 1-9 pp in CV on that family, so it
runs only when asked for, as does `spring-damper` (the seed paper's contact model with
the measured contact time, never cheaper than pymunk).
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
    "rays": _deflect_by_rays,  # exact plan-view bounces, compiled: the pymunk stage's limit as its step shrinks
    "pymunk": _deflect_in_pymunk,  # plates stepped in pymunk
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
    batch_runner: Optional[str] = None  # "module:function" running many (scene, granules, contacts) in one call

    def run(self, scene: Scene, granules: GranuleBatch, contacts: Contacts,
            progress: Optional[Callable[[float], None]] = None, tracks: int = 0) -> Departure:
        """Departure states of `granules` (`tracks` paths kept by stepped models)."""
        module, function = self.runner.split(":")
        simulate = getattr(importlib.import_module(module), function)
        if not self.stepped:
            return simulate(scene, granules, contacts)
        return simulate(scene, granules, contacts, progress=progress, track_count=tracks)

    def run_batch(self, runs: list[tuple[Scene, GranuleBatch, Contacts]]) -> list[Departure]:
        """Departure states of each (scene, granules, contacts): one call of the batch
        runner when the model has one, else one run after the other; the same bits."""
        if self.batch_runner is None:
            return [self.run(*run) for run in runs]
        module, function = self.batch_runner.split(":")
        return getattr(importlib.import_module(module), function)(runs)

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
    SpinnerModel("compiled", "spreadgym.physics.compiled.model:simulate_compiled", "rays",
                 "the pymunk model's contact laws per granule, event-driven and compiled with numba; "
                 "plates by the same event-driven bounces",
                 batch_runner="spreadgym.physics.compiled.model:simulate_compiled_batch"),
)}

MODELS = ("auto", *SPINNER_MODELS)


# The envelope the compiled model was measured in against converged pymunk references
# (configs/references.yaml plus the edges of the environments' action ranges).
VALIDATED = {
    "rpm": (200.0, 1100.0),
    "pitch_deg": (-30.0, 30.0),
    "drop_height_m": (0.0, 0.08),
    "radius_m": (0.15, 0.30),
    "rolling_resistance": (0.0, 0.6),
}


def _rolling_resistance(scene: Scene, library=None) -> float:
    """The vane rolling resistance the scene runs with, from `library` (default the process's;
    0 where its pair is not known: the run itself then names the missing pair)."""
    from spreadgym.config.materials import load_library
    from spreadgym.errors import MaterialError

    if scene.contact.rolling_resistance is not None:
        return float(scene.contact.rolling_resistance)
    try:
        return (library or load_library()).fertilizer_of(scene).pair("rolling_resistance", scene.vane_material)
    except MaterialError:
        return 0.0


PLATE_CLEARANCE_M = 0.02
"""Plates closer than this (the largest granule diameter a scene allows) could hold a
granule against two at once; the compiled plate stage takes one bounce at a time and
was measured where plates stand apart (docs/fidelity.md)."""


def outside_validated(scene: Scene, library=None) -> list[str]:
    """What puts `scene` outside the envelope `compiled` was validated in (empty: inside)."""
    values = {"rpm": [scene.spinner.rpm], "pitch_deg": scene.vanes.per_vane("pitch_deg"),
              "drop_height_m": [scene.feed.drop_height_m], "radius_m": [scene.spinner.radius_m],
              "rolling_resistance": [_rolling_resistance(scene, library)]}
    out = []
    for key, (lo, hi) in VALIDATED.items():
        bad = [v for v in values[key] if not lo - 1e-9 <= v <= hi + 1e-9]
        if bad:
            out.append(f"{key} {bad[0]:g} outside [{lo:g}, {hi:g}]")
    return out + _plates_too_close(scene)


def _plates_too_close(scene: Scene) -> list[str]:
    """The pairs of plates whose capsules stand closer than PLATE_CLEARANCE_M."""
    plates = scene.deflectors
    if len(plates) < 2:
        return []
    from spreadgym.physics.compiled.plates import segment_distance  # numba: only for scenes with two plates

    out = []
    for i in range(len(plates)):
        for j in range(i + 1, len(plates)):
            (a, b), (c, d) = plates[i].endpoints(), plates[j].endpoints()
            gap = segment_distance(*a, *b, *c, *d) - 0.5 * (plates[i].thickness_m + plates[j].thickness_m)
            if gap < PLATE_CLEARANCE_M:
                out.append(f"deflectors {i} and {j} {gap * 1e3:.3g} mm apart (under {PLATE_CLEARANCE_M * 1e3:g} mm: "
                           "a granule may touch both at once)")
    return out


def choose_model(scene: Scene, requested: str = "auto", library=None) -> tuple[str, str]:
    """(model name, reason). `requested` other than auto is honoured as it is; `library` (default
    the process's) holds the scene's fertilizer, whose rolling resistance the envelope bounds."""
    if requested not in MODELS:
        raise ConfigError("model", f"unknown model {requested!r}; allowed: {', '.join(MODELS)}")
    if requested != "auto":
        return requested, "requested"
    outside = outside_validated(scene, library)
    if outside:
        return "pymunk", (f"auto: {'; '.join(outside)}, where the fast compiled model has not been checked "
                          "against the full model, so the full model runs")
    reason = ("auto: the compiled model (the full model's contact laws per granule) matches the "
              "converged full model within 0.5 pp of CV on all 24 reference scenes (within 0.3 pp on 22; "
              "twin-field 0.45 pp low; rolling resistance 0-0.6 included) and with the same effective "
              "swath on all 21 (docs/fidelity.md), ~200x cheaper")
    if scene.deflectors:
        reason += ("; its plates bounce granules event by event, the limit the full model's stepped plate stage "
                   "converges to (docs/fidelity.md)")
    return "compiled", reason
