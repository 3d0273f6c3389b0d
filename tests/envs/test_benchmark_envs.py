"""The v1 tasks of the benchmark (docs/benchmark.md): ids, held-out evaluation, the robust
variant, SpreaderTuning's start rule, the registry's conventions and the native vector env's
gymnasium 1.x API. Few granules throughout (fast); the speed figures are in `make bench`."""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import spreadgym  # noqa: F401  (registers the ids)
from spreadgym.envs.common.task import job_tray_width_m
from spreadgym.envs.registration import ENVS, ID_FORMS, LADDER, TASKS
from spreadgym.errors import ConfigError
from spreadgym.spread.variability import FACTORS, default_variability

SMALL = {"granules": 48}
DESIGN_RUNGS = [f"spreadgym/{name}" for name in LADDER]
TUNING = ["spreadgym/SpreaderTuning-v1", "spreadgym/SpreaderTuningHard-v1"]


# -- ids -----------------------------------------------------------------------------------------

def test_each_v1_task_has_one_namespaced_id():
    for name in TASKS:
        assert f"spreadgym/{name}" in gym.registry
        assert name not in gym.registry and f"spreadgym:{name}" not in gym.registry
    assert set(LADDER) < set(TASKS)
    for name in ("SpinnerDesign", "SpreaderTuning"):  # the contract's ids
        assert f"spreadgym/{name}-v1" in gym.registry


@pytest.mark.parametrize("form", ID_FORMS)
@pytest.mark.parametrize("name", list(ENVS))
def test_v0_ids_keep_working_with_a_deprecation_note(form, name):
    with pytest.warns(DeprecationWarning, match=f"{name.split('-')[0]}-v0 is deprecated"):
        env = gym.make(form.format(name), **SMALL)
    env.reset(seed=0)
    _, reward, *_ = env.step(np.zeros(env.action_space.shape))
    assert math.isfinite(reward)
    assert env.observation_space.shape[0] in (15, 77)  # v0's own observation, one-hot included


def test_the_module_prefix_form_makes_a_v1_env_in_a_process_that_has_not_imported_spreadgym():
    import subprocess
    import sys

    code = ("import gymnasium as gym; env = gym.make('spreadgym:spreadgym/SpinnerDesign-v1', granules=32); "
            "print(env.reset(seed=0)[0].shape)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "(8,)"


# -- held-out evaluation -------------------------------------------------------------------------

@pytest.mark.parametrize("env_id", DESIGN_RUNGS + TUNING)
def test_training_and_evaluation_contexts_are_disjoint(env_id):
    """Every evaluation job lies outside the training contexts, and 400 training draws never
    land on a held-out fertilizer or in a held-out band."""
    env = gym.make(env_id, **SMALL)
    task = env.unwrapped.task
    cfg = task.cfg
    jobs = task.evaluation_jobs
    assert len(jobs) >= 8
    held_out_ferts = set(cfg.evaluation.fertilizers) - set(cfg.context.fertilizers)
    assert held_out_ferts, "at least one fertilizer never seen in training"
    assert all(not task.is_training_context(job) for job in jobs)
    rng = np.random.default_rng(0)
    draws = [task.sample_context(rng) for _ in range(400)]
    assert all(task.is_training_context(c) for c in draws)
    assert not {c.fertilizer for c in draws} & held_out_ferts
    bands = cfg.context.held_out_swath_m
    assert not any(a <= c.target_swath_m <= b for c in draws for a, b in bands)
    assert not set(draws) & set(jobs)
    assert len({round(c.target_swath_m, 9) for c in draws}) > 300  # continuous widths, not a handful


def test_the_eval_split_draws_only_evaluation_jobs():
    env = gym.make("spreadgym/SpinnerDesign-v1", split="eval", **SMALL)
    jobs = {job.as_dict()["fertilizer"] + f"@{job.target_swath_m}" for job in env.unwrapped.task.evaluation_jobs}
    seen = set()
    for seed in range(60):
        _, info = env.reset(seed=seed)
        seen.add(info["context"]["fertilizer"] + f"@{info['context']['target_swath_m']}")
    assert seen == jobs


def test_an_evaluation_job_inside_the_training_contexts_is_refused():
    with pytest.raises(ConfigError, match="evaluation.*also a training context"):
        gym.make("spreadgym/SpinnerDesign-v1", **{"evaluation.target_swath_m": [2.5]}, **SMALL)
    with pytest.raises(ConfigError, match="held_out_swath_m"):
        gym.make("spreadgym/SpinnerDesign-v1", **{"context.swath_draw": "tray_grid"}, **SMALL)


def test_a_continuous_width_gets_trays_that_divide_it():
    env = gym.make("spreadgym/SpinnerDesign-v1", **SMALL)
    for seed in range(20):
        _, info = env.reset(seed=seed)
        width = info["context"]["target_swath_m"]
        scene = env.unwrapped._scene
        trays = width / scene.pattern.tray_width_m
        assert abs(trays - round(trays)) < 1e-9 and round(trays) == round(width / 0.5)
        assert scene.pattern.target_swath_m == width
    assert job_tray_width_m(2.9, 0.5) == pytest.approx(2.9 / 6)


def test_the_observation_is_what_a_fertilizer_is_and_every_entry_varies():
    """No one-hot: an unseen fertilizer is observed by its properties; over training draws
    every entry takes several values (v0 had 4 of 15 constant)."""
    env = gym.make("spreadgym/SpinnerDesign-v1", **SMALL)
    names = env.unwrapped.task.context_names
    assert not any("=" in name for name in names)
    obs = np.stack([env.reset(seed=s)[0] for s in range(80)])
    assert all(len(np.unique(obs[:, k])) >= 2 for k in range(obs.shape[1])), names
    held_out, _ = env.reset(seed=0, options={"context": {"fertilizer": "mixture-17-21-17"}})
    assert held_out.shape == obs.shape[1:] and np.all(np.abs(held_out) <= 1)


# -- the robust, hidden-parameter rung ------------------------------------------------------------

def test_the_robust_rung_hides_a_batch_drawn_from_the_variability_model():
    exact = gym.make("spreadgym/SpinnerDesign-v1", **SMALL)
    robust = gym.make("spreadgym/SpinnerDesignRobust-v1", **SMALL)
    half = default_variability()
    action = np.array([0.1, -0.2], dtype=np.float32)
    batches, differ = [], 0
    for seed in range(8):
        obs_e, _ = exact.reset(seed=seed)
        obs_r, _ = robust.reset(seed=seed)
        np.testing.assert_array_equal(obs_e, obs_r)  # the nominal properties only
        _, reward_e, *_ = exact.step(action)
        obs_r2, reward_r, _, _, info = robust.step(action)
        np.testing.assert_array_equal(obs_r2, obs_r)
        differ += reward_e != reward_r
        batch = info["batch"]
        for name in FACTORS:
            assert abs(batch[name] - 1.0) <= half[name] + 1e-12
        assert abs(batch["vane_pitch_deg"]) <= half["vane_pitch_deg"] + 1e-12
        batches.append(batch["disc_friction"])
    assert len(set(batches)) == len(batches) and differ == len(batches)
    again = gym.make("spreadgym/SpinnerDesignRobust-v1", **SMALL)  # same seed, same hidden batch, same bits
    again.reset(seed=7)
    assert again.step(action)[4]["batch"] == info["batch"]


def test_the_robust_rung_keeps_its_model_at_the_edges_of_the_action_box():
    """A hidden batch can put the top rpm 2 % and the pitch 1 deg past the action ranges, outside
    the envelope where `auto` picks the compiled model: the rung runs the compiled model
    throughout (with `auto` some episodes there would switch to pymunk)."""
    env = gym.make("spreadgym/SpinnerDesignRobust-v1", **SMALL)
    auto = gym.make("spreadgym/SpinnerDesignRobust-v1", model="auto", **SMALL)
    models, auto_models = set(), set()
    for seed in range(12):
        for made, found in ((env, models), (auto, auto_models)):
            made.reset(seed=seed)
            found.add(made.step(np.ones(2, dtype=np.float32))[4]["metrics"]["model"])
    assert models == {"compiled"} and "pymunk" in auto_models


def test_the_robust_rung_refuses_an_unknown_half_range():
    with pytest.raises(ConfigError, match="variability.*unknown key"):
        gym.make("spreadgym/SpinnerDesignRobust-v1", variability={"humidity": 0.1}, **SMALL)
    with pytest.raises(ConfigError, match="variability.disc_friction.*out of range"):
        gym.make("spreadgym/SpinnerDesignRobust-v1", variability={"disc_friction": 2.0}, **SMALL)


# -- SpreaderTuning's start rule and time limit -------------------------------------------------

@pytest.mark.parametrize("env_id", TUNING)
def test_no_evaluation_start_meets_the_goal(env_id):
    """Every held-out job, at the scoring seeds of two runs: the first tray test misses the goal
    (the start rule redraws starts that meet it, and counts each draw)."""
    from spreadgym.agents.evaluation import evaluation_set, make_env

    env = make_env(env_id, {"granules": 512})
    goal = env.unwrapped.config.goal_cv_percent
    redrawn = 0
    for ctx in evaluation_set(env=env):
        for episode in range(2):
            before = env.simulations
            _, info = env.reset(seed=ctx.score_seed(episode), options=ctx.options())
            assert not info["start_solved"] and info["metrics"]["cv_percent_at_target"] > goal
            assert env.simulations - before == info["tray_tests"]
            redrawn += info["tray_tests"] > 1
    assert redrawn > 0  # the rule had starts to redraw (v0 started solved in about half the episodes)


def test_the_start_rule_needs_random_starts():
    with pytest.raises(ConfigError, match="start: unsolved"):
        gym.make("spreadgym/SpreaderTuning-v1", initial_settings="middle", **SMALL)


def test_the_time_limit_follows_max_steps_or_says_what_to_pass():
    env = gym.make("spreadgym/SpreaderTuningHard-v1", **SMALL)
    assert env.spec.max_episode_steps == env.unwrapped.config.max_steps == 30
    with pytest.raises(ConfigError) as err:
        gym.make("spreadgym/SpreaderTuning-v1", max_steps=40, **SMALL)
    assert "max_steps=40, max_episode_steps=40" in str(err.value) and "\n" not in str(err.value)
    env = gym.make("spreadgym/SpreaderTuning-v1", max_steps=3, max_episode_steps=3, goal_cv_percent=0.001, **SMALL)
    env.reset(seed=0)
    for _ in range(3):
        *_, terminated, truncated, _ = env.step(np.zeros(2))
    assert truncated and not terminated


# -- the passive checker ---------------------------------------------------------------------------

def _failed_first_reset_then_step(env):
    with pytest.raises(ConfigError):
        env.reset(seed=1, options={"context": {"fertilizer": "nope"}})
    env.reset(seed=1)
    return env.step(np.zeros(env.action_space.shape))


def test_the_checker_is_on_and_survives_a_failed_first_reset():
    from gymnasium.utils import passive_env_checker

    from spreadgym.envs.spinner_design import SpinnerDesignEnv

    env = gym.make("spreadgym/SpinnerDesign-v1", **SMALL)
    assert "PassiveEnvChecker" in str(env) and env.spec.disable_env_checker is False
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the checker itself finds nothing to warn about
        assert math.isfinite(_failed_first_reset_then_step(env)[1])
    if hasattr(passive_env_checker, "env_data_reuse_passive_checker"):  # gymnasium >= 1.4: the upstream bug
        with pytest.raises(TypeError, match="NoneType"):
            _failed_first_reset_then_step(gym.wrappers.PassiveEnvChecker(SpinnerDesignEnv(**SMALL)))


# -- the native vector env ---------------------------------------------------------------------------

def test_vector_reset_takes_a_list_of_seeds():
    venv = gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=3, **SMALL)
    obs, info = venv.reset(seed=[11, 5, 2])
    for i, seed in enumerate([11, 5, 2]):
        single, single_info = gym.make("spreadgym/SpinnerDesign-v1", **SMALL).reset(seed=seed)
        np.testing.assert_array_equal(obs[i], single)
        assert info["context"]["target_swath_m"][i] == single_info["context"]["target_swath_m"]
    with pytest.raises(ValueError, match="2 seeds for num_envs=3"):
        venv.reset(seed=[1, 2])


@pytest.mark.parametrize("mode", ["disabled", "same_step", "next_step"])
def test_reset_mask_equals_resetting_those_sub_envs_singly(mode):
    n = 4
    venv = gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=n, autoreset_mode=mode, **SMALL)
    singles = [gym.make("spreadgym/SpinnerDesign-v1", **SMALL) for _ in range(n)]
    obs, _ = venv.reset(seed=100)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(env.reset(seed=100 + i)[0], obs[i])
    actions = np.random.default_rng(3).uniform(-1, 1, (n, 2)).astype(np.float32)
    _, rewards, *_ = venv.step(actions)
    single = [env.step(a) for env, a in zip(singles, actions)]
    assert list(rewards) == [s[1] for s in single]
    mask = np.array([True, False, True, False])
    kept = venv.step(actions)[0] if mode == "next_step" else None  # next_step: this step resets all four
    obs, info = venv.reset(seed=[7, 8, 9, 10], options={"reset_mask": mask})
    for i in np.flatnonzero(mask):
        np.testing.assert_array_equal(obs[i], singles[i].reset(seed=[7, 8, 9, 10][i])[0])
    assert list(info["_context"]) == list(mask)
    if kept is not None:
        np.testing.assert_array_equal(obs[~mask], kept[~mask])
    if mode == "disabled":  # the other two ended too: they step only after their own reset
        with pytest.raises(ValueError, match="autoreset is disabled"):
            venv.step(actions)
        venv.reset(seed=[7, 8, 9, 10], options={"reset_mask": ~mask})
        for i in np.flatnonzero(~mask):
            singles[i].reset(seed=[7, 8, 9, 10][i])
    _, rewards, *_ = venv.step(actions)
    for i in np.flatnonzero(mask) if mode != "disabled" else range(n):
        assert rewards[i] == singles[i].step(actions[i])[1]
    with pytest.raises(ValueError, match="reset_mask"):
        venv.reset(options={"reset_mask": np.zeros(n, dtype=bool)})


def test_disabled_autoreset_refuses_to_step_an_ended_sub_env():
    venv = gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=2, autoreset_mode="disabled", **SMALL)
    venv.reset(seed=0)
    venv.step(np.zeros((2, 2), dtype=np.float32))
    with pytest.raises(ValueError, match="autoreset is disabled"):
        venv.step(np.zeros((2, 2), dtype=np.float32))
    venv.reset(options={"reset_mask": np.array([True, True])})
    venv.step(np.zeros((2, 2), dtype=np.float32))


def test_the_vector_env_renders_one_frame_per_sub_env():
    venv = gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=2, render_mode="rgb_array",
                        **{**SMALL, "render.width_px": 96, "render.height_px": 96})
    venv.reset(seed=0)
    _, rewards, *_ = venv.step(np.zeros((2, 2), dtype=np.float32))
    frames = venv.render()
    assert len(frames) == 2 and all(f.shape == (96, 96, 3) and f.dtype == np.uint8 for f in frames)
    env = gym.make("spreadgym/SpinnerDesign-v1", **SMALL)  # rendering steps each sub-env itself: same bits
    env.reset(seed=1)
    assert env.step(np.zeros(2, dtype=np.float32))[1] == rewards[1]
    with pytest.raises(ConfigError, match="render_mode"):
        gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=2, render_mode="human", **SMALL)


def test_the_robust_rung_runs_its_hidden_batches_as_one_batch_with_the_single_envs_bits():
    """The vector env and the searches' `step_designs` put every episode's fertilizer copy in
    one library and run the designs together: the same rewards as one env at a time."""
    from spreadgym.envs.vector import step_designs

    venv = gym.make_vec("spreadgym/SpinnerDesignRobust-v1", num_envs=3, autoreset_mode="same_step", **SMALL)
    venv.reset(seed=20)
    actions = np.random.default_rng(1).uniform(-1, 1, (3, 2)).astype(np.float32)
    _, rewards, *_ = venv.step(actions)
    env = gym.make("spreadgym/SpinnerDesignRobust-v1", **SMALL)
    singles = _single_rewards(env, 20, actions)
    assert list(rewards) == singles
    batch = step_designs(env, [(20 + i, None) for i in range(3)], list(actions))
    assert [step[1] for step in batch] == singles


def test_a_step_beyond_the_landing_point_budget_runs_in_parts_with_the_single_envs_results(monkeypatch):
    from spreadgym.envs import vector

    per_run = 48 * 32  # granules x release-angle copies
    monkeypatch.setattr(vector, "MAX_GRANULE_COPIES", 3 * per_run)  # at most 3 sub-envs a part
    sizes = []
    venv = gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=7, autoreset_mode="same_step", **SMALL)
    task = venv.unwrapped.task
    original = type(task).run_batch
    monkeypatch.setattr(type(task), "run_batch", lambda self, scenes, library=None: (
        sizes.append(len(scenes)), original(self, scenes, library))[1])
    venv.reset(seed=40)
    venv.action_space.seed(2)
    actions = venv.action_space.sample()
    _, rewards, *_ = venv.step(actions)
    assert sizes == [3, 2, 2]  # shared out evenly over the fewest parts
    assert list(rewards) == _single_rewards(gym.make("spreadgym/SpinnerDesign-v1", **SMALL), 40, actions)


def _single_rewards(env, seed: int, actions) -> list:
    """The reward of each action on `env` reset with seed + i, as vector sub-env i is."""
    rewards = []
    for i, action in enumerate(actions):
        env.reset(seed=seed + i)
        rewards.append(env.step(action)[1])
    return rewards


def test_an_error_in_a_later_part_reaches_the_step_and_the_env_works_on(monkeypatch):
    from spreadgym.envs import vector

    monkeypatch.setattr(vector, "MAX_GRANULE_COPIES", 2 * 48 * 32)  # parts of 2 sub-envs
    venv = gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=5, autoreset_mode="same_step", **SMALL)
    task = venv.unwrapped.task
    original, calls = type(task).run_batch, []

    def failing_second(self, scenes, library=None):
        calls.append(len(scenes))
        if len(calls) == 2:
            raise RuntimeError("the second part failed")
        return original(self, scenes, library)

    monkeypatch.setattr(type(task), "run_batch", failing_second)
    venv.reset(seed=3)
    with pytest.raises(RuntimeError, match="the second part failed"):
        venv.step(venv.action_space.sample())
    assert "run" not in task.__dict__  # the task's own run again
    monkeypatch.setattr(type(task), "run_batch", original)
    venv.reset(seed=3)
    venv.step(venv.action_space.sample())  # the env works on


def test_num_envs_beyond_its_bound_is_a_one_line_error():
    from spreadgym.envs.vector import MAX_NUM_ENVS

    for bad in (MAX_NUM_ENVS + 1, 10**9, 0, 2.5, True):
        with pytest.raises(ConfigError) as err:
            gym.make_vec("spreadgym/SpinnerDesign-v1", num_envs=bad, **SMALL)  # refused before any sub-env exists
        assert str(err.value).startswith("num_envs:") and "\n" not in str(err.value)


# -- RecordVideo ------------------------------------------------------------------------------------

def test_record_video_works_or_names_what_it_needs(tmp_path):
    from gymnasium.wrappers import RecordVideo

    env = gym.make("spreadgym/SpinnerDesign-v1", render_mode="rgb_array",
                   **{**SMALL, "render.width_px": 96, "render.height_px": 96})
    try:
        import moviepy  # noqa: F401
    except ImportError:
        with pytest.raises(gym.error.DependencyNotInstalled, match="moviepy"):
            RecordVideo(env, str(tmp_path))
        return
    env = RecordVideo(env, str(tmp_path), episode_trigger=lambda k: True)
    for seed in range(2):
        env.reset(seed=seed)
        env.step(np.zeros(2, dtype=np.float32))
    env.close()
    assert len(list(tmp_path.glob("*.mp4"))) == 2

