"""What only a twin-disc machine has: a throw that meets the other disc.

A departed granule whose straight plan-view path from the edge of the plate zone passes
within the other disc's radius would meet that disc (its vanes stand above the disc
plane where the granule flies); what the other disc's vanes would do with it is not
modelled, so `intercepted` marks it and the run takes it out of the pattern, counts its
mass as intercepted (not landed) and says how much in a note. A search therefore gains
nothing from throwing onto the other disc, and the mass lost shows in every score that
counts the landed fraction. The discs themselves, mirrored or not, are
spreadgym.spread.discs.
"""

from __future__ import annotations

import numpy as np

from spreadgym.spread.discs import Disc, Throw


def intercepted(throws: list[Throw], parts: list[Disc], mirror: bool) -> np.ndarray:
    """(N,) bool over the granules of all discs in order (machine frame): departed granules
    whose plan-view path from launch passes within the other disc's radius (plus their
    own). With `mirror`, the second disc's throw is the first's mirrored and takes the
    first's marks, so the pair stays an exact mirror image."""
    if len(parts) < 2:
        return np.zeros(throws[0].granules.count, dtype=bool)
    marks = []
    for throw, other in zip(throws, parts[::-1]):
        if marks and mirror:
            marks.append(marks[0])
            continue
        launch = throw.launch
        marks.append(launch.departed & onto_disc_axis(launch.position_m, launch.velocity_m_s, throw.granules.radius_m,
                                                       np.asarray(other.centre_m), other.scene.spinner.radius_m))
    return np.concatenate(marks)


def onto_disc_axis(position_m: np.ndarray, velocity_m_s: np.ndarray, granule_radius_m: np.ndarray,
                   axis_m: np.ndarray, disc_radius_m: float) -> np.ndarray:
    """Whether granules launched at `position_m` with plan-view `velocity_m_s` pass within
    `disc_radius_m` plus their own radius of a disc axis at `axis_m` ((2,) or one per granule)."""
    return _ray_meets_circle(position_m, velocity_m_s, axis_m, disc_radius_m + granule_radius_m)


def interception_notes(throws: list[Throw], parts: list[Disc], lost_kg: list[float]) -> list[str]:
    """One note per disc that throws mass onto the other disc (`lost_kg` per disc)."""
    notes = []
    for i, (throw, other, lost) in enumerate(zip(throws, parts[::-1], lost_kg)):
        if len(parts) > 1 and lost > 0.0:
            share = 100.0 * lost / throw.granules.mass_kg.sum()
            notes.append(f"{share:.2g} % of the mass of disc {i + 1} flies onto the other disc (axis at x = "
                         f"{other.centre_m[0]:g} m): taken out of the pattern as intercepted, since what that "
                         f"disc's vanes would do with it is not modelled")
    return notes


def _ray_meets_circle(p: np.ndarray, v: np.ndarray, centre: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Whether the rays p + t v (t >= 0) pass within `radius` of `centre` ((2,) or (N, 2)), plan view."""
    centre = np.asarray(centre, dtype=float)
    rx, ry = centre[..., 0] - p[:, 0], centre[..., 1] - p[:, 1]
    vx, vy = v[:, 0], v[:, 1]
    t = np.maximum((rx * vx + ry * vy) / np.maximum(vx * vx + vy * vy, 1e-300), 0.0)
    nx, ny = rx - t * vx, ry - t * vy
    return nx * nx + ny * ny < radius * radius
