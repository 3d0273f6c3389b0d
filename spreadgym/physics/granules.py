"""Sampling the granules of one run: sizes, masses, release points and spinner phases.

A real spreader feeds continuously, so a granule meets the spinner at a random phase.
Because the disc and its vanes are rotationally symmetric, a granule released when
the spinner stands at angle `phase` is simulated with the spinner at angle 0 and
the release point turned by `-phase`; its departure state is turned back by
`+phase`. Every random input (phase, diameter, the two feed offsets) is drawn as a
Latin hypercube: each is stratified into N equal-probability slices with one granule
per slice, the slices paired at random across inputs. That lowers the sampling noise
of the pattern without biasing it (measured in `make bench`, section cv-noise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri

from spreadgym.config.materials import Fertilizer
from spreadgym.config.scene import Scene


@dataclass(frozen=True)
class GranuleBatch:
    """Per-granule arrays (length N), SI units."""

    diameter_m: np.ndarray
    mass_kg: np.ndarray
    density_kg_m3: float
    release_xy_m: np.ndarray  # (N, 2) release point in the machine frame
    phase_rad: np.ndarray  # spinner angle when the granule is released

    @property
    def count(self) -> int:
        return int(self.diameter_m.shape[0])

    @property
    def radius_m(self) -> np.ndarray:
        return 0.5 * self.diameter_m

    def release_in_spinner_frame(self) -> np.ndarray:
        """Release points turned by -phase: the spinner then starts at angle 0 for all."""
        return rotate(self.release_xy_m, -self.phase_rad)


def rotate(xy: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """Rotate 2-D vectors (N, 2) by per-row angles (N,) about the origin."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([c * xy[:, 0] - s * xy[:, 1], s * xy[:, 0] + c * xy[:, 1]], axis=1)


def sample_granules(scene: Scene, fertilizer: Fertilizer, rng: np.random.Generator) -> GranuleBatch:
    """Draw `scene.sim.granules` granules.

    Diameter: normal(d50, sd) truncated to the fertilizer's [min, max] (scene values
    override d50 and sd; sd 0 gives one size). Mass: sphere of the particle density.
    """
    n = scene.sim.granules
    u_phase, u_size, u_x, u_y = (_stratified(rng, n) for _ in range(4))
    size = fertilizer.size
    d50 = scene.granule.diameter_m if scene.granule.diameter_m is not None else size.d50_m
    sd = scene.granule.diameter_sd_m if scene.granule.diameter_sd_m is not None else size.sd_m
    lo, hi = min(size.min_m, d50), max(size.max_m, d50)
    diameter = np.full(n, d50)
    if sd > 0:
        diameter = _truncated_normal(d50, sd, lo, hi, u_size)
    density = fertilizer.particle_density_kg_m3
    mass = density * math.pi / 6.0 * diameter**3

    feed = scene.feed
    base = np.array([feed.radius_m * math.cos(feed.angle_rad), feed.radius_m * math.sin(feed.angle_rad)])
    release = np.tile(base, (n, 1))
    if feed.spread_m > 0:
        release = release + feed.spread_m * np.column_stack([ndtri(u_x), ndtri(u_y)])
        release = _clip_inside(release, 0.95 * scene.vane_outer_radius_m)
    phase = 2.0 * math.pi * u_phase
    return GranuleBatch(diameter, mass, density, release, phase)


def _stratified(rng: np.random.Generator, n: int) -> np.ndarray:
    """n uniforms in (0, 1), one in each slice [k/n, (k+1)/n), in random order."""
    return (rng.permutation(n) + rng.random(n)) / n


def _truncated_normal(mean, sd, lo, hi, uniform) -> np.ndarray:
    """Inverse-CDF map of uniforms to a normal truncated to [lo, hi]."""
    a, b = ndtr((lo - mean) / sd), ndtr((hi - mean) / sd)
    return mean + sd * ndtri(a + (b - a) * uniform)


def _clip_inside(xy: np.ndarray, radius: float) -> np.ndarray:
    r = np.hypot(xy[:, 0], xy[:, 1])
    scale = np.minimum(1.0, radius / np.maximum(r, 1e-300))
    return xy * scale[:, None]
