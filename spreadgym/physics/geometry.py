"""Vane geometry at spinner angle 0, shared by every spinner model.

Vane k has its inner end at radius r_in on the angle 2*pi*k/N. Its direction is the
radial unit vector there turned by pitch * sign(omega): a positive pitch leans the tip
in the direction of rotation. It runs along that direction until its centre line
reaches the outer radius.
"""

from __future__ import annotations

import math

import numpy as np

from spreadgym.scene import Scene


def vane_segments(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Inner and outer end points (N, 2) of every vane's centre line, metres."""
    n = scene.vanes.count
    r_in, r_out = scene.vanes.inner_radius_m, scene.vane_outer_radius_m
    sense = math.copysign(1.0, scene.spinner.omega_rad_s)
    theta = 2.0 * math.pi * np.arange(n) / n
    direction = theta + sense * np.asarray(scene.vanes.pitches_rad())
    inner = r_in * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    u = np.stack([np.cos(direction), np.sin(direction)], axis=1)
    # |inner + s u| = r_out  ->  s^2 + 2 s (inner . u) + r_in^2 - r_out^2 = 0
    b = np.sum(inner * u, axis=1)
    length = -b + np.sqrt(b * b + r_out * r_out - r_in * r_in)
    return inner, inner + length[:, None] * u
