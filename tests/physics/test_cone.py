"""A dished disc (spinner.cone_deg): departures tilted up along the cone, against the
closed form of a frictionless granule sliding along a radial vane on a spinning cone."""

import math

import numpy as np
import pytest

from spreadgym.config.scene import load_scene
from spreadgym.errors import ConfigError
from spreadgym.physics.constants import GRAVITY_M_S2
from spreadgym.physics.departure import DEPARTED, Departure, tilted_by_cone
from spreadgym.spread.pipeline import run_scene


def rim_departure(radial, tangential, radius=0.3, vertical=0.0):
    angle = np.linspace(0.0, 2.0 * np.pi, len(radial), endpoint=False)
    r_hat = np.c_[np.cos(angle), np.sin(angle)]
    t_hat = np.c_[-r_hat[:, 1], r_hat[:, 0]]
    n = len(radial)
    return Departure(position_m=radius * r_hat, velocity_m_s=radial[:, None] * r_hat + tangential[:, None] * t_hat,
                     spin_rad_s=np.zeros(n), height_m=np.zeros(n), vertical_velocity_m_s=np.full(n, vertical),
                     time_s=np.ones(n), outcome=np.full(n, DEPARTED, dtype=np.int8), model="test", dt_s=0.0)


def test_the_radial_part_turns_up_by_the_cone_and_the_rest_is_kept():
    d = rim_departure(np.array([10.0, 20.0, 5.0]), np.array([30.0, 31.0, 32.0]), vertical=0.5)
    t = tilted_by_cone(d, math.radians(8.0))
    r_hat = d.position_m / 0.3
    radial = np.sum(t.velocity_m_s * r_hat, axis=1)
    tangential = t.velocity_m_s[:, 1] * r_hat[:, 0] - t.velocity_m_s[:, 0] * r_hat[:, 1]
    np.testing.assert_allclose(radial, [10.0 * math.cos(math.radians(8.0)), 20 * math.cos(math.radians(8.0)),
                                        5 * math.cos(math.radians(8.0))], rtol=1e-14)
    np.testing.assert_allclose(tangential, [30.0, 31.0, 32.0], rtol=1e-14)
    np.testing.assert_allclose(t.vertical_velocity_m_s, 0.5 + np.array([10.0, 20.0, 5.0]) * math.sin(math.radians(8.0)),
                               rtol=1e-14)
    assert tilted_by_cone(d, 0.0) is d


@pytest.mark.parametrize("rpm,cone_deg", [(500, 5.0), (500, 10.0), (1000, 10.0), (1000, 15.0)])
def test_along_the_surface_the_flat_disc_speed_matches_the_cone_closed_form(rpm, cone_deg):
    """Frictionless granule on a radial vane of a cone, from rest at plan radius r0:
    s'' = w^2 cos^2(a) s - g sin(a) along the surface, so with c = g sin a / (w cos a)^2 it
    leaves the rim at ds/dt = w cos a sqrt((R/cos a - c)^2 - (r0/cos a - c)^2). The flat
    disc gives w sqrt(R^2 - r0^2) radially; tilted, that is its speed along the surface."""
    w, a, radius, r0 = rpm * 2 * math.pi / 60, math.radians(cone_deg), 0.3, 0.1
    flat_radial = w * math.sqrt(radius**2 - r0**2)
    tilted = tilted_by_cone(rim_departure(np.array([flat_radial]), np.array([w * radius])), a)
    along = math.hypot(np.sum(tilted.velocity_m_s[0] * tilted.position_m[0] / radius), tilted.vertical_velocity_m_s[0])
    c = GRAVITY_M_S2 * math.sin(a) / (w * math.cos(a)) ** 2
    exact = w * math.cos(a) * math.sqrt((radius / math.cos(a) - c) ** 2 - (r0 / math.cos(a) - c) ** 2)
    assert along == pytest.approx(flat_radial, rel=1e-14)
    assert abs(along / exact - 1.0) < 2.0 * c / (radius - r0)  # only gravity along the slope is left out
    assert math.atan2(tilted.vertical_velocity_m_s[0], np.sum(tilted.velocity_m_s[0] * tilted.position_m[0] / radius)) \
        == pytest.approx(a, rel=1e-12)


def test_a_dished_disc_throws_further_and_a_flat_one_is_unchanged():
    flat = run_scene(load_scene("field", {"sim.granules": 512}), model="analytic")
    same = run_scene(load_scene("field", {"sim.granules": 512, "spinner.cone_deg": 0.0}), model="analytic")
    assert np.array_equal(flat.landing.position_m, same.landing.position_m)
    dished = run_scene(load_scene("field", {"sim.granules": 512, "spinner.cone_deg": 8.0}), model="analytic")
    reach = [np.percentile(np.hypot(*r.landing.position_m.T), 90) for r in (flat, dished)]
    assert reach[1] > reach[0] + 0.5


def test_a_cone_past_the_bound_is_named():
    with pytest.raises(ConfigError, match="spinner.cone_deg"):
        load_scene("paper", {"spinner.cone_deg": 30.0})
