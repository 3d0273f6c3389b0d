"""Regression tests of issue 15's environment findings: options, kwargs and actions go
through the same checks as scenes, and the gymnasium contracts hold."""

import gymnasium as gym
import numpy as np
import pytest

import spreadgym.envs  # noqa: F401  (registers the ids)
from spreadgym.errors import ConfigError

IDS = ("spreadgym/SpinnerDesign-v0", "spreadgym/SpreaderTuning-v0")


@pytest.fixture(scope="module", params=IDS)
def env(request):
    made = gym.make(request.param, granules=256, disable_env_checker=True)
    yield made
    made.close()


@pytest.mark.parametrize("options, key", [
    ({"context": {"wind_m_s": [float("nan"), 0.0]}}, "options.context.wind_m_s.0"),
    ({"context": {"wind_m_s": [1e6, 0.0]}}, "flight.wind_m_s.0"),
    ({"foo": 1}, "options.foo"),
    ({"context": {"target_swath_m": float("nan")}}, "options.context.target_swath_m"),
    ({"context": {"target_swath_m": float("inf")}}, "options.context.target_swath_m"),
    ([], "options"),
])
def test_reset_options_are_checked(env, options, key):
    with pytest.raises(ConfigError) as err:
        env.reset(seed=0, options=options)
    assert err.value.key == key


@pytest.mark.parametrize("action, fragment", [
    ("abc", "finite numbers"),
    (np.zeros((1, 2)), "shape (2,)"),
    ([np.nan, 0.0], "not finite"),
])
def test_bad_actions_are_refused_with_the_envs_message(env, action, fragment):
    env.reset(seed=0)
    size = env.action_space.shape[0]
    if isinstance(action, np.ndarray):
        action = np.zeros((1, size))
    elif isinstance(action, list):
        action = [np.nan] + [0.0] * (size - 1)
    with pytest.raises(ValueError, match=fragment.replace("(", r"\(").replace(")", r"\)").replace("2", str(size))):
        env.step(action)


@pytest.mark.parametrize("kwargs, key", [
    ({"granules": "200"}, "granules"),
    ({"granules": True}, "granules"),
    ({"scene_overrides": {"feed.angle_deg": float("nan")}}, "feed.angle_deg"),
])
def test_constructor_kwargs_follow_the_schema(kwargs, key):
    with pytest.raises(ConfigError) as err:
        gym.make(IDS[0], **kwargs)
    assert err.value.key == key


@pytest.mark.parametrize("kwargs, key, fragment", [
    ({"scene_overrides": {"flight.wind_m_s": [5, 5], "flight.forward_speed_m_s": 3}},
     "scene_overrides.flight.wind_m_s", "sets flight.wind_m_s itself from context.wind_x_m_s"),
    ({"scene_overrides": {"flight": {"forward_speed_m_s": 3}}}, "scene_overrides.flight",
     "context.forward_speed_m_s"),
    ({"scene_overrides": {"fertilizer": "pellet"}}, "scene_overrides.fertilizer", "context.fertilizers"),
    ({"scene_overrides": {"sim.granules": 100}}, "scene_overrides.sim.granules", "from granules"),
    ({"context.fertilizers": ["pellet", "pellet"]}, "context.fertilizers", "'pellet' is listed twice"),
    ({"context.spinner_materials": ["mc", "mc"]}, "context.spinner_materials", "'mc' is listed twice"),
    ({"context.target_swath_m": [0.5, 0.5]}, "context.target_swath_m", "of at least 2 trays"),
    ({"granules": 1_000_000}, "granules", "landing points per run"),
])
def test_what_the_env_would_ignore_or_cannot_hold_is_refused(kwargs, key, fragment):
    with pytest.raises(ConfigError) as err:
        gym.make(IDS[0], **kwargs)
    assert err.value.key == key and fragment in err.value.message


def test_an_override_the_context_leaves_alone_is_kept():
    env = gym.make(IDS[0], granules=64, scene_overrides={"flight": {"drag_coefficient": 0.5}},
                   disable_env_checker=True)
    env.reset(seed=0)
    assert env.unwrapped._scene.flight.drag_coefficient == 0.5


@pytest.mark.parametrize("action", [[0.1 + 1j, 0.0], np.array([1.0 + 0j, 0.0]), ["0.1", "0"]])
def test_complex_and_text_actions_are_refused(env, action):
    env.reset(seed=0)
    size = env.action_space.shape[0]
    action = list(action) + [0.0] * (size - len(action))
    with pytest.raises(ValueError, match="action must be"):
        env.step(action)


@pytest.mark.parametrize("env_id", IDS)
def test_a_failed_reset_leaves_an_env_that_needs_a_reset_and_then_works(env_id):
    env = gym.make(env_id, granules=64, disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="options.context.fertilizer"):
        env.reset(seed=1, options={"context": {"fertilizer": "nope"}})
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(env.action_space.shape))
    env.reset(seed=1)
    _, reward, _, _, _ = env.step(np.zeros(env.action_space.shape))
    assert np.isfinite(reward)


def test_spreader_tuning_refuses_a_step_after_the_episode_ended():
    env = gym.make(IDS[1], granules=256, goal_cv_percent=1e4, disable_env_checker=True)
    env.reset(seed=0)
    _, _, terminated, _, _ = env.step(np.zeros(env.action_space.shape))
    assert terminated  # any CV meets a goal of 1e4 %
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(env.action_space.shape))
    env.reset(seed=1)
    env.step(np.zeros(env.action_space.shape))  # a reset starts a new episode


def test_docs_list_the_accepted_range_of_every_key_as_the_schemas_say():
    from pathlib import Path

    from spreadgym.envs.config_doc import config_keys_markdown

    doc = Path(__file__).resolve().parents[2] / "docs" / "config-keys.md"
    assert doc.read_text(encoding="utf-8") == config_keys_markdown(), \
        "docs/config-keys.md is stale: python -m spreadgym.envs.config_doc > docs/config-keys.md"
    assert "| `flight.wind_m_s` |" in doc.read_text() and "each >= -20, <= 20" in doc.read_text()


@pytest.mark.parametrize("env_id", [*IDS, "spreadgym/SpinnerDesign-v1", "spreadgym/SpreaderTuning-v1"])
def test_a_first_reset_that_fails_leaves_a_default_made_env_usable(env_id):
    """The issue's sequence as a user meets it: `gym.make` with its defaults, a first reset
    refused, then a good reset and a step (gymnasium 1.4's passive checker broke it; v0 keeps
    it off, the v1 ids have it on with the case fixed, envs/conventions.py)."""
    env = gym.make(env_id, granules=64)
    with pytest.raises(ConfigError, match="options.context.fertilizer"):
        env.reset(seed=1, options={"context": {"fertilizer": "nope"}})
    env.reset(seed=1)
    _, reward, _, _, _ = env.step(np.zeros(env.action_space.shape))
    assert np.isfinite(reward)


def test_action_to_settings_checks_the_action_as_step_does(env):
    from spreadgym.envs import action_to_settings

    size = env.action_space.shape[0]
    with pytest.raises(ValueError, match="not finite"):
        action_to_settings(env, [np.nan] + [0.0] * (size - 1))
    with pytest.raises(ValueError, match=rf"shape \({size},\)"):
        action_to_settings(env, [0.0] * (size + 1))
    assert action_to_settings(env, [2.0] + [0.0] * (size - 1)) == action_to_settings(env, [1.0] + [0.0] * (size - 1))


VECTOR = "spreadgym/SpinnerDesign-v1"


@pytest.fixture(scope="module", params=[1, 2], ids=["one process", "two workers"])
def vector(request):
    made = gym.make_vec(VECTOR, num_envs=2, workers=request.param, granules=256)
    yield made
    made.close()


def test_a_bad_context_value_resets_no_sub_env_of_the_vector_env(vector):
    vector.reset(seed=0)
    before = vector.step(np.zeros((2, 2)))
    vector.reset(seed=0)
    for given in ({"fertilizer": "nope"}, {"target_swath_m": float("nan")}):
        with pytest.raises(ConfigError, match="options.context"):
            vector.reset(options={"context": given})
    after = vector.step(np.zeros((2, 2)))  # every sub-env as the seeded reset left it
    assert np.array_equal(before[0], after[0]) and np.array_equal(before[1], after[1])


@pytest.mark.parametrize("seeds", [[1.5, 2.0], ["1", "2"], [True, 1], [-1, 2]])
def test_the_vector_env_takes_as_seeds_what_a_single_env_takes(vector, seeds):
    with pytest.raises(ValueError, match=r"seed\[0\] must be a non-negative int or None"):
        vector.reset(seed=seeds)


def test_the_vector_env_refuses_options_that_are_no_mapping(vector):
    with pytest.raises(ConfigError, match="options: expected a mapping, got str"):
        vector.reset(options="context")


def test_a_closed_vector_env_refuses_to_step_or_reset():
    for workers in (1, 2):
        made = gym.make_vec(VECTOR, num_envs=2, workers=workers, granules=256)
        made.reset(seed=0)
        made.close()
        with pytest.raises(gym.error.ClosedEnvironmentError):
            made.step(np.zeros((2, 2)))
        with pytest.raises(gym.error.ClosedEnvironmentError):
            made.reset(seed=0)


def test_step_designs_refuses_an_unseeded_job():
    from spreadgym.envs.vector import step_designs

    made = gym.make(VECTOR, granules=256)
    with pytest.raises(ValueError, match="needs a seed for every job"):
        step_designs(made, [(None, None), (3, None)], [np.zeros(2)] * 2)
    made.close()
