"""The core settings space: unit box <-> SI values <-> scene overrides."""

import math

import numpy as np
import pytest

from spreadgym.config.scene import load_scene
from spreadgym.config.settings import SettingsSpace
from spreadgym.errors import ConfigError

PLATES = {"deflectors.0.angle_range_deg": [50.0, 100.0], "deflectors.1.angle_range_deg": [80.0, 130.0]}


def test_ends_and_middle_map_to_the_range_in_si_and_in_the_named_units():
    space = SettingsSpace(load_scene("paper"), rpm=(200.0, 1100.0), pitch_deg=(-30.0, 30.0))
    assert space.names == ["rpm", "pitch_deg"]
    assert space.low == pytest.approx([200 * 2 * math.pi / 60, -math.pi / 6])
    assert space.values([-1, -1]) == pytest.approx({"rpm": 200.0, "pitch_deg": -30.0})
    assert space.values([0, 0]) == pytest.approx({"rpm": 650.0, "pitch_deg": 0.0})
    assert space.values([5, 1]) == pytest.approx({"rpm": 1100.0, "pitch_deg": 30.0})  # clipped


def test_unit_si_round_trip_and_the_scene_own_settings():
    scene = load_scene("paper-deflectors", PLATES)
    space = SettingsSpace(scene, pitch_per_vane=True, feed_radius_m=(0.02, 0.1), feed_angle_deg=(60.0, 150.0))
    assert space.names == ["rpm", "vane_0_pitch_deg", "vane_1_pitch_deg", "vane_2_pitch_deg", "vane_3_pitch_deg",
                           "deflector_0_angle_deg", "deflector_1_angle_deg", "feed_radius_m", "feed_angle_deg"]
    u = np.random.default_rng(1).uniform(-1, 1, space.size)
    assert space.unit(space.si(u)) == pytest.approx(u, abs=1e-12)
    own = space.apply(scene, space.scene_unit(scene))  # the scene's settings survive the trip
    assert own.spinner.rpm == pytest.approx(500.0)
    assert own.vanes.pitch_deg == pytest.approx([0.0] * 4)
    assert [p.angle_deg for p in own.deflectors] == pytest.approx([60.0, 120.0])
    assert (own.feed.radius_m, own.feed.angle_deg) == pytest.approx((0.043, 105.0))


def test_overrides_put_every_setting_into_the_scene():
    scene = load_scene("paper-deflectors", PLATES)
    space = SettingsSpace(scene, pitch_per_vane=True)
    u = np.array([1.0, -1.0, -0.5, 0.5, 1.0, -1.0, 1.0])
    moved = space.apply(scene, u)
    assert moved.spinner.rpm == pytest.approx(1100.0)
    assert moved.vanes.pitch_deg == pytest.approx([-30.0, -15.0, 15.0, 30.0])
    assert [p.angle_deg for p in moved.deflectors] == pytest.approx([50.0, 130.0])
    assert moved.spinner.omega_rad_s == pytest.approx(space.si(u)[0])


def test_a_list_of_pitches_in_the_scene_gives_one_axis_per_vane():
    space = SettingsSpace(load_scene("paper", {"vanes.pitch_deg": [0.0, 5.0, 0.0, 5.0]}))
    assert space.names[1:] == [f"vane_{k}_pitch_deg" for k in range(4)]
    assert SettingsSpace(load_scene("paper")).names == ["rpm", "pitch_deg"]


def test_same_map_as_the_envs_settings_map():
    from spreadgym.envs.common.actions import SettingsMap
    from spreadgym.envs.common.config import SettingsConfig

    scene = load_scene("paper-deflectors", PLATES)
    envs_map = SettingsMap(scene, SettingsConfig())
    space = SettingsSpace(scene)
    for u in np.random.default_rng(2).uniform(-1, 1, (5, space.size)):
        assert envs_map.scene_overrides(envs_map.to_settings(u)) == pytest.approx(space.overrides(u))


@pytest.mark.parametrize("kwargs, key", [
    ({"rpm": (200.0, 7000.0)}, "settings.rpm"),  # a rim speed over 100 m/s on a 0.15 m disc
    ({"rpm": (0.0, 500.0)}, "settings.rpm"),
    ({"pitch_deg": (10.0, -10.0)}, "settings.pitch_deg"),
    ({"pitch_deg": (-70.0, 0.0)}, "settings.pitch_deg"),
    ({"feed_radius_m": (0.0, 0.2)}, "settings.feed_radius_m"),  # outside the 0.15 m disc
])
def test_ranges_out_of_bounds_name_the_key(kwargs, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        SettingsSpace(load_scene("paper"), **kwargs)


def test_a_plate_range_that_reaches_the_disc_is_refused():
    scene = load_scene("paper-deflectors", {"deflectors.0.angle_range_deg": [20.0, 100.0]})
    with pytest.raises(ConfigError, match=r"deflectors\.0\.angle_range_deg: at 20 deg"):
        SettingsSpace(scene)
