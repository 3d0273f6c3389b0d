"""Geometry shared by every spinner model: vanes at spinner angle 0, crossings, frames.

Vane k has its inner end at radius r_in (its own, where vanes differ in length) on the
angle 2*pi*k/N. Its direction is the
radial unit vector there turned by pitch * sign(omega): a positive pitch leans the tip
in the direction of rotation. It runs along that direction until its centre line
reaches the outer radius.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from spreadgym.config.scene import Deflector, Scene
from spreadgym.physics.granules import rotate

ZONE_MARGIN_M = 0.01
"""Clearance (m) between the outermost plate and the edge of the deflector zone."""


def vane_segments(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Inner and outer end points (N, 2) of every vane's centre line, metres."""
    n = scene.vanes.count
    r_in, r_out = np.asarray(scene.vanes.inner_radii_m()), scene.vane_outer_radius_m
    sense = math.copysign(1.0, scene.spinner.omega_rad_s)
    theta = 2.0 * math.pi * np.arange(n) / n
    direction = theta + sense * np.asarray(scene.vanes.pitches_rad())
    inner = r_in[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    u = np.stack([np.cos(direction), np.sin(direction)], axis=1)
    # |inner + s u| = r_out  ->  s^2 + 2 s (inner . u) + r_in^2 - r_out^2 = 0
    b = np.sum(inner * u, axis=1)
    length = -b + np.sqrt(b * b + r_out * r_out - r_in * r_in)
    return inner, inner + length[:, None] * u


def machine_frame_tracks(points, end_points, start_angle) -> list[np.ndarray]:
    """Recorded paths (one row per step, NaN once finished) in the machine frame.

    The simulation frame is the machine frame turned by a constant angle per granule.
    """
    if not points:
        return []
    stacked = np.stack(points)  # (T, k, 2)
    tracks = []
    for k in range(stacked.shape[1]):
        path = np.vstack([stacked[:, k][~np.isnan(stacked[:, k, 0])], end_points[k]])
        tracks.append(rotate(path, np.full(path.shape[0], start_angle[k])))
    return tracks


def crossing_fraction(p0: np.ndarray, p1: np.ndarray, radius: float) -> np.ndarray:
    """Fraction f in [0, 1] of the step at which |p0 + f (p1 - p0)| = radius."""
    return np.clip(advance_to_circle(p0, p1 - p0, radius), 0.0, 1.0)


def point_segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points (..., 2) to the segments a-b (..., 2); everything broadcasts."""
    d = b - a
    length2 = np.sum(d * d, axis=-1)
    t = np.clip(np.sum((points - a) * d, axis=-1) / np.maximum(length2, 1e-300), 0.0, 1.0)
    return np.hypot(*(points - a - t[..., None] * d).T)


def zone_radius_m(plates: Sequence[Deflector], max_granule_radius_m: float) -> float:
    """Radius of the circle about the axis that holds every plate with clearance."""
    reach = 0.0
    for plate in plates:
        for x, y in plate.endpoints():
            reach = max(reach, math.hypot(x, y) + 0.5 * plate.thickness_m)
    return reach + max_granule_radius_m + ZONE_MARGIN_M


def advance_to_circle(position, velocity, radius_m):
    """Time (N,) for straight-line motion from inside to the circle |x| = radius."""
    a = np.sum(velocity * velocity, axis=1)
    b = 2.0 * np.sum(position * velocity, axis=1)
    c = np.sum(position * position, axis=1) - radius_m * radius_m
    disc = np.maximum(b * b - 4.0 * a * c, 0.0)
    return np.where(a > 0, (-b + np.sqrt(disc)) / np.maximum(2.0 * a, 1e-300), 0.0)
