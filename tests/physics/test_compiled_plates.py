"""The compiled plate stage (event-driven bounces) against the full model's stepped plate
stage (pymunk), which converges to it as its step shrinks: same departures, granule by
granule, on several plate settings; and the stage's near-plate test against brute force."""

import numpy as np
import pytest

from spreadgym.config.materials import load_library
from spreadgym.config.scene import Deflector, load_scene
from spreadgym.physics.compiled.plates import near_plates
from spreadgym.physics.geometry import ZONE_MARGIN_M
from spreadgym.physics.selection import DEFLECTOR_METHODS, SPINNER_MODELS
from spreadgym.physics.stepped import pymunk_deflectors
from spreadgym.spread.pipeline import plan_scene

SETTINGS = {
    "default": {},
    "plates 50/130 deg": {"deflectors.0.angle_deg": 50.0, "deflectors.1.angle_deg": 130.0},
    "plates 100/80 deg": {"deflectors.0.angle_deg": 100.0, "deflectors.1.angle_deg": 80.0},
    "locked": {"granule.rotation": "locked"},
    "900 rpm, pellet": {"spinner.rpm": 900.0, "fertilizer": "pellet"},
}


def exit_angle_errors(a, b, gone):
    """|difference| (deg) of the exit directions of two deflector results."""
    ha = np.arctan2(a.velocity_m_s[gone, 1], a.velocity_m_s[gone, 0])
    hb = np.arctan2(b.velocity_m_s[gone, 1], b.velocity_m_s[gone, 0])
    return np.degrees(np.abs(np.angle(np.exp(1j * (ha - hb)))))


@pytest.mark.parametrize("setting", list(SETTINGS))
def test_the_pymunk_plate_stage_converges_to_the_compiled_one(setting, monkeypatch):
    """The stepped stage finds a contact up to a step's travel inside the plate; halving the
    step halves that. At the shipped step (1/8 of the reach per step) and at a quarter of it
    the exit directions of the same departed granules approach the compiled stage's in
    proportion (measured: the mean error falls 4-15 fold for the 4-fold finer step, to
    0.005-0.044 deg, 99 % of granules within 1.6 deg, exit speeds within 0.0012 m/s on
    average): mean at the finer step at most 0.4 of the shipped step's and below 0.06 deg,
    99 % within 2 deg, the mean exit speed error below 0.002 m/s (of 10-25 m/s)."""
    scene = load_scene("paper-deflectors", {"sim.granules": 512, "sim.seed": 21, **SETTINGS[setting]})
    plan = plan_scene(scene, "compiled", load_library())
    disc, granules, contacts = plan.spinner_runs()[0]
    departure = SPINNER_MODELS["compiled"].run(disc, granules, contacts)
    exact = DEFLECTOR_METHODS["rays"](departure, disc, contacts, granules)
    gone = departure.departed
    errors = {}
    for fraction in (pymunk_deflectors.STEP_FRACTION, pymunk_deflectors.STEP_FRACTION / 4):
        monkeypatch.setattr(pymunk_deflectors, "STEP_FRACTION", fraction)
        stepped = DEFLECTOR_METHODS["pymunk"](departure, disc, contacts, granules)
        errors[fraction] = exit_angle_errors(exact, stepped, gone)
        speed_error = np.abs(np.hypot(*exact.velocity_m_s[gone].T) - np.hypot(*stepped.velocity_m_s[gone].T))
    coarse, fine = errors.values()
    assert coarse.mean() > 0  # the stepped stage did step granules onto plates here
    assert fine.mean() <= 0.4 * coarse.mean()
    assert fine.mean() < 0.06
    assert np.quantile(fine, 0.99) < 2.0
    assert speed_error.mean() < 0.002


def test_the_near_test_never_misses_a_path_that_comes_within_reach():
    """Turned paths against a brute-force distance: the box prefilter and squared distances
    agree with sampling the path finely (a margin of the sampling's own error aside)."""
    rng = np.random.default_rng(5)
    n = 4000
    start = rng.uniform(-0.2, 0.2, (n, 2))
    end = start + rng.normal(0.0, 0.25, (n, 2))
    radius = rng.uniform(0.001, 0.003, n)
    plates = [Deflector(x_m=0.21, y_m=-0.12, angle_deg=60.0, length_m=0.2, material="steel"),
              Deflector(x_m=-0.2, y_m=0.1, angle_deg=-20.0, length_m=0.15, thickness_m=0.01, material="steel")]
    angle = rng.uniform(-np.pi, np.pi, n)
    granule = rng.integers(0, n, n)
    near = near_plates(start, end, radius, plates, turn=(np.cos(angle), np.sin(angle)), granule=granule)
    c, s = np.cos(angle), np.sin(angle)
    p0, p1 = start[granule], end[granule]
    p0 = np.column_stack([c * p0[:, 0] - s * p0[:, 1], s * p0[:, 0] + c * p0[:, 1]])
    p1 = np.column_stack([c * p1[:, 0] - s * p1[:, 1], s * p1[:, 0] + c * p1[:, 1]])
    along = np.linspace(0.0, 1.0, 2001)
    path = p0[:, None] + along[None, :, None] * (p1 - p0)[:, None]  # (n, 2001, 2) points on every path
    gap = np.full(n, np.inf)
    for plate in plates:
        a, b = (np.asarray(e) for e in plate.endpoints())
        t = np.clip(((path - a) @ (b - a)) / ((b - a) @ (b - a)), 0.0, 1.0)
        d = np.hypot(*(path - a - t[..., None] * (b - a)).transpose(2, 0, 1)).min(axis=1)
        gap = np.minimum(gap, d - (radius[granule] + 0.5 * plate.thickness_m + ZONE_MARGIN_M))
    step = 0.5 * np.hypot(*(p1 - p0).T) / 2000  # the sampling's own error, per path
    assert np.all(near[gap < -step]) and not np.any(near[gap > step])
    assert 0.05 < near.mean() < 0.95
