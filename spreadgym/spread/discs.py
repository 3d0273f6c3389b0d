"""A machine of discs: each disc thrown by the single-disc models in its own frame, one
pattern from all of them.

A scene holds one disc, or two (`Scene.twin`) whose axes stand at `Scene.disc_centres_m`
in the machine frame; plates are shared, in the machine frame. Each disc is simulated as
a single-disc scene in its own frame (its axis at the origin, the plates moved by minus
its centre), with every spinner model and deflector method as they are; the launch
states are moved back by the centre (`moved`) and every disc's granules fly and land as
one batch (`combined`), so the tray pattern is that of the machine. A one-disc scene is
simply the case of one disc (`discs`); spreadgym.spread.batch runs the discs of many
scenes as entries of one (design x disc x granule) index. What only a pair of discs has,
a throw that meets the other disc, is spreadgym.spread.twin.

The discs do not interact in flight: their plan-view paths may cross, but granules are
far apart (collisions between flying granules are not modelled on one disc either).

A second disc is by default the mirror image of the first across the centreline. The
models handle either sense of rotation, so any second disc can run as it is; when it is
exactly the mirror image of the first (plates included), its run is the first disc's run
mirrored (x -> -x), which halves the cost and is an unbiased sample of the same thing:
the granule inputs (uniform phase, isotropic feed spread, size) have mirror-symmetric
distributions. Both discs then draw the same granules, mirrored; each replicate still
pairs independent draws, so the CV's bias correction and standard error hold. Without
crosswind the flight is odd in x as well, so the mirrored granules' landings are the
first disc's mirrored, to the bit (`mirrored_landing`): the pair flies once.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from spreadgym.config.scene import Deflector, Scene, mirror_disc
from spreadgym.physics.departure import Departure
from spreadgym.physics.granules import GranuleBatch
from spreadgym.physics.selection import choose_model
from spreadgym.spread.flight import Landing

_MIRROR_TOL = 1e-9  # relative: YAML decimals such as 60.3 and 119.7 mirror to within rounding


@dataclass(frozen=True)
class Disc:
    """One disc as a single-disc scene in its own frame, and where its axis stands (m)."""

    scene: Scene
    centre_m: tuple[float, float]


@dataclass(frozen=True)
class Throw:
    """The granules of one or more discs and their states at the disc edge and at launch."""

    granules: GranuleBatch
    departure: Departure
    launch: Departure


def discs(scene: Scene) -> list[Disc]:
    """The discs of `scene`, each a single-disc scene in its own frame."""
    if scene.twin is None:
        return [Disc(scene, (0.0, 0.0))]
    parts = [(scene.spinner, scene.vanes, scene.feed), scene.second_disc()]
    return [Disc(_disc_scene(scene, *part, centre), centre) for part, centre in zip(parts, scene.disc_centres_m)]


def _disc_scene(scene: Scene, spinner, vanes, feed, centre: tuple[float, float]) -> Scene:
    """A single-disc scene about the disc's axis. Not re-validated: its parts are the
    validated parts of `scene` (a moved plate may stand beyond the machine-frame bound)."""
    cx, cy = centre
    plates = [p.model_copy(update={"x_m": p.x_m - cx, "y_m": p.y_m - cy}) for p in scene.deflectors]
    return scene.model_copy(update={"spinner": spinner, "vanes": vanes, "feed": feed, "deflectors": plates,
                                    "twin": None})


def mirror_scene(scene: Scene) -> Scene:
    """The mirror image (x -> -x) of a single-disc scene: disc, feed and plates."""
    spinner, vanes, feed = mirror_disc(scene.spinner, scene.vanes, scene.feed)
    return scene.model_copy(update={"spinner": spinner, "vanes": vanes, "feed": feed,
                                    "deflectors": [_mirror_plate(p) for p in scene.deflectors]})


def _mirror_plate(plate: Deflector) -> Deflector:
    turn = plate.angle_range_deg
    return plate.model_copy(update={"x_m": -plate.x_m, "angle_deg": 180.0 - plate.angle_deg,
                                    "angle_range_deg": None if turn is None else (180.0 - turn[1], 180.0 - turn[0])})


def is_mirror_image(a: Scene, b: Scene) -> bool:
    """Whether single-disc scene `b` is `a` mirrored (to rounding; plates in any order)."""
    m = mirror_scene(a)
    if not all(_close(_numbers(x), _numbers(y)) for x, y in
               ((m.spinner, b.spinner), (m.vanes, b.vanes), (m.feed, b.feed))):
        return False

    def in_order(plates):
        return sorted(plates, key=lambda p: (round(p.x_m, 6), round(p.y_m, 6)))

    return len(m.deflectors) == len(b.deflectors) and all(
        _close(_numbers(p), _numbers(q)) for p, q in zip(in_order(m.deflectors), in_order(b.deflectors)))


def _numbers(section) -> dict:
    """A section's values, its angle taken mod 360 deg."""
    values = section.model_dump()
    if "angle_deg" in values:
        values["angle_deg"] %= 360.0
    return values


def _close(x, y) -> bool:
    """Equal, numbers to within rounding."""
    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() == y.keys() and all(_close(x[k], y[k]) for k in x)
    if isinstance(x, (list, tuple)) and isinstance(y, (list, tuple)):
        return len(x) == len(y) and all(_close(u, v) for u, v in zip(x, y))
    numbers = (int, float)
    if isinstance(x, numbers) and isinstance(y, numbers) and not isinstance(x, bool) and not isinstance(y, bool):
        return math.isclose(x, y, rel_tol=_MIRROR_TOL, abs_tol=_MIRROR_TOL)
    return x == y


def choose_for_discs(parts: list[Disc], requested: str, library=None) -> tuple[str, str]:
    """One model for every disc: `auto` takes the full model if any disc needs it."""
    choices = [choose_model(d.scene, requested, library) for d in parts]
    return next((c for c in choices if c[0] != choices[0][0]), choices[0])


def mirrored(throw: Throw) -> Throw:
    """A throw mirrored about its disc's axis (x -> -x): positions, velocities, spins, phases.

    The mirror scene's vane k is the image of vane N - k when its spinner stands at
    pi - phase, so that is a mirrored granule's phase."""
    g = throw.granules
    granules = dataclasses.replace(g, release_xy_m=g.release_xy_m * [-1.0, 1.0], phase_rad=np.pi - g.phase_rad)
    return Throw(granules, _mirror_states(throw.departure), _mirror_states(throw.launch))


def _mirror_states(d: Departure) -> Departure:
    flip = np.array([-1.0, 1.0])
    return dataclasses.replace(d, position_m=d.position_m * flip, velocity_m_s=d.velocity_m_s * flip,
                               spin_rad_s=-d.spin_rad_s, tracks=[t * flip for t in d.tracks],
                               notes=["the first disc's run mirrored (x -> -x)"])


def mirrored_landing(first: Landing) -> Landing:
    """The landings of a disc pair from the first disc's (its frame): the first's, then
    their mirror images (x -> -x), the second disc's granules in the same order."""
    return Landing(np.vstack([first.position_m, first.position_m * [-1.0, 1.0]]),
                   np.concatenate([first.time_s, first.time_s]))


def moved(throw: Throw, centre_m: tuple[float, float]) -> Throw:
    """A throw moved from its disc's frame into the machine frame (disc axis at `centre_m`)."""
    if centre_m == (0.0, 0.0):
        return throw
    c = np.asarray(centre_m, dtype=float)
    granules = dataclasses.replace(throw.granules, release_xy_m=throw.granules.release_xy_m + c)
    return Throw(granules, _moved_states(throw.departure, c), _moved_states(throw.launch, c))


def _moved_states(d: Departure, c: np.ndarray) -> Departure:
    return dataclasses.replace(d, position_m=d.position_m + c, tracks=[t + c for t in d.tracks])


def combined(throws: list[Throw]) -> Throw:
    """One throw holding the granules of several, in order; replicate k of every disc
    is replicate k of the whole."""
    if len(throws) == 1:
        return throws[0]
    g = [t.granules for t in throws]
    granules = GranuleBatch(*(np.concatenate([getattr(b, f) for b in g]) for f in
                              ("diameter_m", "mass_kg")), g[0].density_kg_m3,
                            np.concatenate([b.release_xy_m for b in g]), np.concatenate([b.phase_rad for b in g]),
                            np.concatenate([b.replicate for b in g]))
    return Throw(granules, _joined([t.departure for t in throws]), _joined([t.launch for t in throws]))


def _joined(states: list[Departure]) -> Departure:
    arrays = {f: np.concatenate([getattr(s, f) for s in states]) for f in
              ("position_m", "velocity_m_s", "spin_rad_s", "height_m", "vertical_velocity_m_s", "time_s", "outcome")}
    notes = [f"disc {i + 1}: {n}" for i, s in enumerate(states) for n in s.notes]
    return Departure(**arrays, model=states[0].model, dt_s=max(s.dt_s for s in states), notes=notes,
                     tracks=[t for s in states for t in s.tracks])
