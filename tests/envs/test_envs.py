"""The Gymnasium environments: API checkers, determinism, actions, rewards, config, rendering.

Runs use a few granules (fast). The spinner model is the envs' configured default
when the physics layer offers it, otherwise the full pymunk model.
"""

import copy
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from gymnasium.utils.env_checker import data_equivalence
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import spreadgym  # noqa: F401  (registers the envs)
from spreadgym.config.scene import load_scene
from spreadgym.envs.common import reward as rewards
from spreadgym.envs.common.config import DESIGN, TUNING, load_env_config
from spreadgym.envs.spreader_tuning import bout_features, rebin, single_pass_features
from spreadgym.errors import ConfigError
from spreadgym.physics.selection import choose_model
from spreadgym.spread.metrics import RunMetrics
from spreadgym.spread.pattern import Trays

DESIGN_ID = "spreadgym/SpinnerDesign-v0"
TUNING_ID = "spreadgym/SpreaderTuning-v0"
IDS = [DESIGN_ID, TUNING_ID]
V1_IDS = ["spreadgym/SpinnerDesign-v1", "spreadgym/SpreaderTuning-v1", "spreadgym/SpinnerDesignRobust-v1",
          "spreadgym/SpinnerDesignTwin-v1"]


def _model() -> str:
    """The model the default config runs on (what `auto` resolves to on its scene)."""
    config = load_env_config(DESIGN)
    return choose_model(load_scene(config.scene), config.model)[0]


MODEL = _model()
SMALL = {"model": MODEL, "granules": 48}


def make(env_id, **kwargs):
    return gym.make(env_id, **{**SMALL, **kwargs})


def same(a, b) -> bool:
    return data_equivalence(a, b, exact=True)


# -- API checkers ------------------------------------------------------------------


def _errors_but_v0_deprecation() -> None:
    warnings.simplefilter("error")
    warnings.filterwarnings("ignore", message=".*-v0 is deprecated", category=DeprecationWarning)


@pytest.mark.parametrize("env_id", IDS + V1_IDS)
def test_gymnasium_checker_without_warnings(env_id):
    env = make(env_id)
    with warnings.catch_warnings():
        _errors_but_v0_deprecation()
        gym_check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", IDS + V1_IDS)
def test_sb3_checker_without_warnings(env_id):
    env = make(env_id)
    with warnings.catch_warnings():
        _errors_but_v0_deprecation()
        sb3_check_env(env.unwrapped, warn=True)
    env.close()


@pytest.mark.parametrize("env_id", IDS + V1_IDS)
def test_spaces_and_types(env_id):
    env = make(env_id)
    space = env.action_space
    assert isinstance(space, gym.spaces.Box) and space.dtype == np.float32
    assert np.all(space.low == -1.0) and np.all(space.high == 1.0)
    obs, info = env.reset(seed=3)
    assert obs.dtype == np.float32 and obs in env.observation_space
    obs, reward, terminated, truncated, info = env.step(space.sample())
    assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
    assert obs.dtype == np.float32 and obs in env.observation_space
    assert {"metrics", "settings", "context", "reward_terms", "sim_seed"} <= set(info)
    assert "cv_percent_at_target" in info["metrics"] and "trays" in info["metrics"]


# -- determinism -------------------------------------------------------------------


@pytest.mark.parametrize("env_id", IDS + V1_IDS)
def test_same_seed_same_trajectory_bit_for_bit(env_id):
    actions = np.random.default_rng(0).uniform(-1, 1, size=(3, make(env_id).action_space.shape[0]))
    runs = []
    for _ in range(2):
        env = make(env_id)
        record = [env.reset(seed=42)]
        for a in actions:
            record.append(env.step(a.astype(np.float32)))
            if record[-1][2] or record[-1][3]:
                record.append(env.reset())
        runs.append(record)
    assert len(runs[0]) == len(runs[1])
    for first, second in zip(*runs):
        assert same(first, second)
    # a different seed gives a different job or sample
    env = make(env_id)
    env.reset(seed=43)
    other = env.step(actions[0].astype(np.float32))
    assert not same(other[4]["metrics"], runs[0][1][4]["metrics"]) or not same(other[0], runs[0][1][0])


def test_design_step_after_end_reuses_the_job_and_sample():
    env = make(DESIGN_ID)
    env.reset(seed=5)
    a = np.array([0.2, -0.4], dtype=np.float32)
    first = env.step(a)
    again = env.step(a)
    assert same(first, again)


# -- actions -----------------------------------------------------------------------


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_is_refused(env_id, bad):
    env = make(env_id)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    action[0] = bad
    with pytest.raises(ValueError, match="not finite"):
        env.step(action)


@pytest.mark.parametrize("env_id", IDS)
def test_out_of_range_action_is_clipped(env_id):
    n = make(env_id).action_space.shape[0]
    big = np.array([5.0] + [-7.0] * (n - 1), dtype=np.float32)
    edge = np.array([1.0] + [-1.0] * (n - 1), dtype=np.float32)
    outs = []
    for action in (big, edge):
        env = make(env_id)
        env.reset(seed=11)
        outs.append(env.step(action))
    assert same(outs[0], outs[1])
    settings = outs[0][4]["settings"]
    cfg = load_env_config(DESIGN if env_id == DESIGN_ID else TUNING)
    if env_id == DESIGN_ID:
        assert settings["rpm"] == cfg.settings.rpm[1]
        assert settings["pitch_deg"] == [cfg.settings.pitch_deg[0]]


def test_action_maps_linearly_onto_the_ranges():
    env = make(DESIGN_ID, settings={"rpm": [300, 900], "pitch_deg": [-20, 10]})
    env.reset(seed=0)
    info = env.step(np.array([0.0, 1.0], dtype=np.float32))[4]
    assert info["settings"]["rpm"] == pytest.approx(600.0)
    assert info["settings"]["pitch_deg"] == [pytest.approx(10.0)]
    assert info["metrics"]["departure"]["speed_mean_m_s"] > 0


def test_per_vane_pitch_and_adjustable_deflector_add_action_entries():
    plate = {"x_m": 0.0, "y_m": -0.25, "angle_deg": 0.0, "length_m": 0.12, "material": "steel",
             "angle_range_deg": [-30.0, 30.0]}
    env = make(DESIGN_ID, settings={"pitch_per_vane": True}, scene_overrides={"deflectors": [plate]})
    assert env.action_space.shape == (1 + 4 + 1,)
    env.reset(seed=1)
    action = np.array([0.0, -1, -0.5, 0.5, 1, 1.0], dtype=np.float32)
    info = env.step(action)[4]
    assert info["settings"]["pitch_deg"] == pytest.approx([-30.0, -15.0, 15.0, 30.0])
    assert info["settings"]["deflector_angle_deg"] == pytest.approx([30.0])
    off = make(DESIGN_ID, settings={"deflectors": False}, scene_overrides={"deflectors": [plate]})
    assert off.action_space.shape == (2,)


def test_deflector_range_reaching_into_the_disc_is_refused():
    plate = {"x_m": 0.0, "y_m": -0.19, "angle_deg": 0.0, "length_m": 0.1, "material": "steel",
             "angle_range_deg": [0.0, 90.0]}
    with pytest.raises(ConfigError, match="deflectors.0.angle_range_deg"):
        make(DESIGN_ID, scene_overrides={"deflectors": [plate]})


# -- rewards -----------------------------------------------------------------------


def test_design_reward_within_declared_bounds_over_random_actions():
    env = make(DESIGN_ID)
    lo, hi = env.unwrapped.reward_bounds
    assert (lo, hi) == (-2.5, 0.0)
    env.action_space.seed(0)
    env.reset(seed=0)
    for _ in range(6):
        _, reward, terminated, _, info = env.step(env.action_space.sample())
        assert math.isfinite(reward) and lo <= reward <= hi
        assert reward == pytest.approx(-info["reward_terms"]["penalty"])
        env.reset()


def test_tuning_reward_within_declared_bounds_over_random_actions():
    env = make(TUNING_ID, max_steps=3)
    lo, hi = env.unwrapped.reward_bounds
    assert (lo, hi) == pytest.approx((-2.55, 0.95))
    env.action_space.seed(1)
    env.reset(seed=1)
    for _ in range(6):
        _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        assert math.isfinite(reward) and lo <= reward <= hi
        if terminated or truncated:
            env.reset()


def _metrics(cv, effective, released, landed, target=4.0):
    """Run metrics with only what the reward reads: the rest is empty or zero."""
    return RunMetrics(
        model="analytic", model_reason="", dt_s=None, granules=0, angle_copies=1, angle_copies_reason="",
        outcomes={}, departure={},
        target_swath_m=target, driving="racetrack", tray_width_m=0.5, cv_threshold_percent=15.0,
        cv_percent_at_target=cv, cv_standard_error_percent=None, cv_raw_percent=cv, cv_ci_percent=None,
        effective_swath_m=effective, curve_bout_width_m=np.zeros(0), curve_cv_percent=np.zeros(0),
        trays=Trays(np.zeros(1), np.array([landed]), 0.5), released_kg=released, retained_kg=released - landed,
    )


@pytest.mark.parametrize(
    "metrics",
    [
        _metrics(None, 0.0, 1.0, 0.0),  # nothing landed (everything retained)
        _metrics(None, 0.0, 0.0, 0.0),  # nothing released
        _metrics(float("nan"), float("nan"), 1.0, 0.5),
        _metrics(1e9, 1e3, 1.0, 1.0),
    ],
)
def test_reward_is_finite_and_bounded_in_degenerate_cases(metrics):
    design_cfg = load_env_config(DESIGN).reward
    tuning_cfg = load_env_config(TUNING).reward
    s = rewards.score(metrics, design_cfg)
    r = rewards.design_reward(s)
    lo, hi = rewards.design_reward_bounds(design_cfg)
    assert math.isfinite(r) and lo <= r <= hi
    for reached in (False, True):
        t = rewards.tuning_reward(rewards.score(metrics, tuning_cfg), tuning_cfg, reached)
        tlo, thi = rewards.tuning_reward_bounds(tuning_cfg)
        assert math.isfinite(t) and tlo <= t <= thi


def test_nothing_landed_scores_worst():
    cfg = load_env_config(DESIGN).reward
    s = rewards.score(_metrics(None, 0.0, 1.0, 0.0), cfg)
    assert s.cv_percent == cfg.cv_worst_percent
    assert rewards.design_reward(s) == rewards.design_reward_bounds(cfg)[0]
    perfect = rewards.score(_metrics(0.0, 4.0, 1.0, 1.0), cfg)
    assert rewards.design_reward(perfect) == 0.0


def test_reward_weights_come_from_config():
    env = make(DESIGN_ID, reward={"cv_weight": 2.0, "swath_weight": 0.0, "retained_weight": 0.0})
    assert env.unwrapped.reward_bounds == (-2.0, 0.0)
    env.reset(seed=2)
    _, reward, _, _, info = env.step(np.zeros(2, dtype=np.float32))
    cv = info["metrics"]["cv_percent_at_target"]
    assert reward == pytest.approx(-2.0 * min(cv, 100.0) / 100.0)


# -- tuning episode ------------------------------------------------------------------


def test_tuning_terminates_at_goal_and_truncates_at_the_step_limit():
    easy = make(TUNING_ID, goal_cv_percent=1e4)
    easy.reset(seed=0)
    _, reward, terminated, truncated, info = easy.step(np.zeros(2, dtype=np.float32))
    assert terminated and not truncated
    assert reward == pytest.approx(-info["reward_terms"]["penalty"] - 0.05 + 1.0)

    hard = make(TUNING_ID, goal_cv_percent=1e-9, max_steps=2)
    hard.reset(seed=0)
    assert hard.step(np.zeros(2, dtype=np.float32))[2:4] == (False, False)
    assert hard.step(np.zeros(2, dtype=np.float32))[2:4] == (False, True)


def test_tuning_action_changes_the_settings_by_max_change():
    env = make(TUNING_ID, initial_settings="middle", max_change=0.5)
    obs, info = env.reset(seed=0)
    assert info["settings"]["rpm"] == pytest.approx(650.0)
    _, _, _, _, info = env.step(np.array([1.0, -1.0], dtype=np.float32))
    assert info["settings"]["rpm"] == pytest.approx(650.0 + 0.25 * 900.0)
    assert info["settings"]["pitch_deg"] == [pytest.approx(-15.0)]
    _, info = make(TUNING_ID, initial_settings="scene").reset(seed=0)
    assert info["settings"] == {"rpm": 500.0, "pitch_deg": [0.0], "deflector_angle_deg": []}  # the paper scene
    names = env.unwrapped.observation_names
    assert len(names) == env.observation_space.shape[0]
    assert "setting:rpm" in names and "single_pass[0]" in names and "bout[15]" in names


def test_pattern_features():
    w = 0.5
    centres = np.arange(-6, 7) * w
    mass = np.exp(-0.5 * (centres / 1.2) ** 2)
    trays = Trays(centres, mass, w)
    edges = np.append(centres - w / 2, centres[-1] + w / 2)
    assert rebin(edges, mass, np.linspace(-1.0, 1.0, 5)).sum() == pytest.approx(mass.sum())
    single = single_pass_features(trays, 10.0, 40)
    assert single.shape == (40,) and single.max() == pytest.approx(1.0) and single.min() >= 0
    bout = bout_features(trays, 3.0, "racetrack", 16)
    assert bout.shape == (16,) and np.all((0 <= bout) & (bout <= 1))
    assert bout.mean() == pytest.approx(0.5, abs=0.05)
    empty = Trays(centres, np.zeros_like(mass), w)
    assert not single_pass_features(empty, 10.0, 40).any() and not bout_features(empty, 3.0, "racetrack", 16).any()


# -- context -------------------------------------------------------------------------


def test_context_draws_on_the_tray_grid_within_the_ranges():
    env = make(DESIGN_ID, context={"target_swath_m": [2.2, 4.9], "forward_speed_m_s": [1.0, 3.0],
                                   "wind_x_m_s": [-2.0, 2.0], "spinner_materials": ["mc", "steel", "pvc"]})
    seen = set()
    for seed in range(12):
        obs, info = env.reset(seed=seed)
        c = info["context"]
        assert c["target_swath_m"] / 0.5 == pytest.approx(round(c["target_swath_m"] / 0.5))
        assert 2.5 <= c["target_swath_m"] <= 4.5
        assert 1.0 <= c["forward_speed_m_s"] <= 3.0 and -2.0 <= c["wind_m_s"][0] <= 2.0
        assert obs in env.observation_space
        seen.add((c["fertilizer"], c["spinner_material"]))
    assert len(seen) > 2


def test_mixture_gets_the_fallback_restitution_only_where_the_library_lacks_it():
    env = make(DESIGN_ID, fallback_restitution={"disc": 0.3, "vane": 0.35})
    _, info = env.reset(seed=0, options={"context": {"fertilizer": "mixture-17-21-17"}})
    assert info["context"]["fallback_restitution"] == {"contact.disc_restitution": 0.3,
                                                      "contact.vane_restitution": 0.35}
    _, _, _, _, step_info = env.step(np.zeros(2, dtype=np.float32))
    assert step_info["metrics"]["mass"]["released_kg"] > 0
    _, info = env.reset(seed=0, options={"context": {"fertilizer": "compound-10-16-10"}})
    assert info["context"]["fallback_restitution"] == {}


def test_a_kept_job_scene_is_the_one_built_afresh_and_the_env_still_pickles():
    """The task keeps each job's scene; what it hands out equals a fresh build, a caller
    changing the info's fallbacks changes nothing kept, and the env pickles (spawned
    workers and Ray send envs that way)."""
    import pickle

    env = make(DESIGN_ID, granules=64)
    _, info = env.reset(seed=0, options={"context": {"fertilizer": "mixture-17-21-17"}})
    task = env.unwrapped.task
    context = next(iter(task._jobs))
    assert task.context_scene(context) == task._build_job(context)[0]
    info["context"]["fallback_restitution"].clear()
    assert task.context_info(context)["fallback_restitution"]
    again = pickle.loads(pickle.dumps(env.unwrapped))
    assert again.task.context_scene(context) == task.context_scene(context)


def test_reset_options_fix_the_job():
    env = make(DESIGN_ID)
    _, info = env.reset(seed=0, options={"context": {"target_swath_m": 5.5, "fertilizer": "pellet"}})
    assert info["context"]["target_swath_m"] == 5.5 and info["context"]["fertilizer"] == "pellet"
    with pytest.raises(ConfigError, match="options.context.colour"):
        env.reset(options={"context": {"colour": "red"}})
    with pytest.raises(ConfigError, match="target_swath_m"):
        env.reset(options={"context": {"target_swath_m": 5.2}})


# -- config --------------------------------------------------------------------------


def test_yaml_defaults_are_the_documented_ones():
    for name in (DESIGN, TUNING):
        cfg = load_env_config(name)
        assert cfg.model == "auto" and cfg.scene == "paper" and cfg.granules is None  # the scene's own count
        assert cfg.settings.rpm == (200.0, 1100.0) and cfg.settings.pitch_deg == (-30.0, 30.0)
        assert cfg.context.fertilizers == ["mixture-17-21-17", "compound-10-16-10", "pellet"]
        assert cfg.fallback_restitution.disc == cfg.fallback_restitution.vane == 0.43


def test_the_default_granule_count_is_the_scenes_own():
    for scene, granules in (("paper", 2048), ("paper-deflectors", 2048), ("field", 2048)):
        env = gym.make("spreadgym:SpinnerDesign-v0", scene=scene)
        assert env.unwrapped.task.base_scene.sim.granules == granules


def test_kwargs_override_the_config():
    env = gym.make("spreadgym:SpinnerDesign-v0", granules=100, model=MODEL,
                   reward={"cv_weight": 3.0}, **{"context.target_swath_m": [3.0, 3.0]})
    cfg = env.unwrapped.config
    assert cfg.granules == 100 and cfg.reward.cv_weight == 3.0 and cfg.reward.swath_weight == 0.5
    _, info = env.reset(seed=0)
    assert info["context"]["target_swath_m"] == 3.0
    info = env.step(np.zeros(2, dtype=np.float32))[4]
    assert info["metrics"]["granules"] == 100 and info["metrics"]["model"] == MODEL


def test_scene_overrides_reach_the_scene():
    env = make(DESIGN_ID, scene_overrides={"spinner.height_m": 1.2}, **{"scene_overrides.feed.angle_deg": 90.0})
    scene = env.unwrapped.task.base_scene
    assert scene.spinner.height_m == 1.2 and scene.feed.angle_deg == 90.0


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"granulez": 100}, "granulez"),
        ({"reward": {"cv_wieght": 1.0}}, "reward.cv_wieght"),
        ({"context.windx": [0, 1]}, "context.windx"),
        ({"context.wind_x_m_s": [-25.0, 25.0]}, "context.wind_x_m_s"),  # the scene's bound (20), not a later failure
        ({"granules": 0}, "granules"),
        ({"settings": {"rpm": [900, 300]}}, "settings.rpm"),
        ({"context": {"fertilizers": ["sand"]}}, "context.fertilizers"),
        ({"context": {"target_swath_m": [2.1, 2.4]}}, "context.target_swath_m"),
        ({"model": "magic"}, "model"),
        ({"scene_overrides": {"spinner.rpmm": 3}}, "spinner.rpmm"),
    ],
)
def test_bad_kwargs_are_errors_naming_the_key(kwargs, key):
    with pytest.raises(ConfigError) as err:
        gym.make(DESIGN_ID, **{**SMALL, **kwargs})
    assert err.value.key == key and key in str(err.value)


def test_unknown_kwarg_on_the_tuning_env():
    with pytest.raises(ConfigError, match="max_stepz"):
        gym.make(TUNING_ID, max_stepz=3)


# -- rendering -----------------------------------------------------------------------


@pytest.mark.parametrize("env_id", IDS)
def test_rgb_array_frames(env_id):
    env = make(env_id, render_mode="rgb_array", render={"width_px": 480, "height_px": 400})
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (400, 480, 3) and frame.dtype == np.uint8
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.shape == (400, 480, 3) and frame.dtype == np.uint8
    assert frame.min() < 128 < frame.max()  # something is drawn
    env.close()


def test_info_is_not_shared_between_calls():
    env = make(DESIGN_ID)
    _, info_a = env.reset(seed=0)
    info_b = copy.deepcopy(info_a)
    info_a["context"]["fertilizer"] = "changed"
    _, info_c = env.reset(seed=0)
    assert same(info_b, info_c)


# -- docs ----------------------------------------------------------------------------


def test_the_docs_example_runs():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "environments.md").read_text(encoding="utf-8")
    example = text.split("```python\n", 1)[1].split("```", 1)[0]
    assert len(example.strip().splitlines()) == 5
    scope: dict = {}
    exec(compile(example, "docs/environments.md", "exec"), scope)
    assert isinstance(scope["reward"], float) and scope["terminated"] is True
