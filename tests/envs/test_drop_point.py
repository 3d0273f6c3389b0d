"""The drop point as a setting: where a scene gives feed ranges, actions, searches and the
settings helpers move the feed radius and angle within them."""

import gymnasium as gym
import numpy as np
import pytest

import spreadgym.envs  # noqa: F401  (registers the ids)
from spreadgym.config.scene import load_scene
from spreadgym.config.settings import SettingsSpace
from spreadgym.envs import action_to_settings, setting_ranges, settings_to_action
from spreadgym.errors import ConfigError

RANGES = {"feed.radius_range_m": [0.03, 0.09], "feed.angle_range_deg": [60.0, 150.0]}
SMALL = {"model": "compiled", "granules": 64}


@pytest.mark.parametrize("env_id", ["spreadgym/SpinnerDesign-v0", "spreadgym/SpreaderTuning-v0"])
def test_a_scene_with_feed_ranges_adds_two_action_entries_that_reach_the_scene(env_id):
    env = gym.make(env_id, scene_overrides=RANGES, **SMALL)
    assert env.action_space.shape == (4,)
    ranges = setting_ranges(env)
    assert list(ranges)[2:] == ["feed.radius_m", "feed.angle_deg"]
    assert ranges["feed.radius_m"] == (0.03, 0.09) and ranges["feed.angle_deg"] == (60.0, 150.0)
    settings = action_to_settings(env, np.array([0.0, 0.0, 1.0, -1.0]))
    assert settings["feed_radius_m"] == 0.09 and settings["feed_angle_deg"] == 60.0
    np.testing.assert_allclose(settings_to_action(env, settings), [0.0, 0.0, 1.0, -1.0], atol=1e-7)
    task = env.unwrapped.task
    scene = task.settings_scene(task.base_scene, task.settings_map.to_settings(np.array([0.0, 0.0, 1.0, -1.0])), 0)
    assert scene.feed.radius_m == 0.09 and scene.feed.angle_deg == 60.0
    off = gym.make(env_id, scene_overrides=RANGES, settings={"feed": False}, **SMALL)
    assert off.action_space.shape == (2,)


def test_the_drop_point_changes_where_the_fertilizer_goes():
    env = gym.make("spreadgym/SpinnerDesign-v0", scene_overrides=RANGES, **SMALL)
    env.reset(seed=3)
    near = env.step(np.array([0.0, 0.0, 0.0, -1.0], dtype=np.float32))[4]
    env.reset(seed=3)
    far = env.step(np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32))[4]
    assert near["settings"]["feed_angle_deg"] == 60.0 and far["settings"]["feed_angle_deg"] == 150.0
    # same granules, the release turned by 90 deg about the axis: the pattern moves
    assert near["metrics"]["cv_percent_at_target"] != far["metrics"]["cv_percent_at_target"]


def test_settings_space_takes_the_scenes_ranges_and_explicit_ones_replace_them():
    scene = load_scene("paper", RANGES)
    assert SettingsSpace(scene).names == ["rpm", "pitch_deg", "feed_radius_m", "feed_angle_deg"]
    assert SettingsSpace(scene, feed=False).names == ["rpm", "pitch_deg"]
    space = SettingsSpace(scene, feed_radius_m=(0.04, 0.05))
    assert space.values(np.ones(space.size))["feed_radius_m"] == 0.05


@pytest.mark.parametrize("overrides,message", [
    ({"feed.radius_range_m": [0.09, 0.03]}, "feed.radius_range_m: \\[0.09, 0.03\\] is reversed"),
    ({"feed.radius_range_m": [0.03, 0.2]}, "feed.radius_range_m: \\[0.03, 0.2\\] m must lie within \\[0, 0.15\\)"),
    ({"feed.angle_range_deg": [0.0, 400.0]}, "feed.angle_range_deg"),
])
def test_bad_feed_ranges_are_named(overrides, message):
    with pytest.raises(ConfigError, match=message):
        load_scene("paper", overrides)


@pytest.mark.parametrize("env_id", ["spreadgym/SpinnerDesign-v0", "spreadgym/SpreaderTuning-v0"])
def test_both_envs_run_twin_field_with_its_drop_point_actions(env_id):
    kwargs = {"scene": "twin-field", "granules": 64, "context.target_swath_m": [18.0, 36.0]}
    runs = []
    for _ in range(2):
        env = gym.make(env_id, **kwargs)
        assert env.action_space.shape == (4,) and list(setting_ranges(env))[2:] == ["feed.radius_m", "feed.angle_deg"]
        _, info = env.reset(seed=5)
        assert 18.0 <= info["context"]["target_swath_m"] <= 36.0
        runs.append(env.step(np.array([0.5, 0.0, 0.2, -0.4], dtype=np.float32)))
    info = runs[0][4]
    assert info["metrics"]["model"] == "compiled" and 0.06 <= info["settings"]["feed_radius_m"] <= 0.16
    assert runs[0][1] == runs[1][1] and np.array_equal(runs[0][0], runs[1][0])  # same seed, same bits
