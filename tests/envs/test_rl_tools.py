"""spreadgym where RL users work: ids in fresh processes, registry conventions, the native
vector env, the settings <-> action helpers, rl_zoo3 and RLlib (the last two only when installed)."""

import os
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
import yaml

import spreadgym  # noqa: F401  (registers the envs)
from spreadgym.envs import action_to_settings, setting_ranges, settings_to_action
from spreadgym.envs.common.config import DESIGN, TUNING, load_env_config
from spreadgym.envs.vector import SpinnerDesignVectorEnv
from spreadgym.envs.zoo import hyperparams_path
from spreadgym.errors import ConfigError

SMALL = {"granules": 32}
NAMES = ["SpinnerDesign-v0", "SpreaderTuning-v0"]


def run_python(code: str, cwd=None, timeout=240, log_dir=None) -> subprocess.CompletedProcess:
    """`python *code`; `log_dir`: where SB3 writes the logs of a trainer that sets none (rl-zoo
    without --tensorboard-log), instead of a new folder in the user's temp folder per run."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    if log_dir is not None:
        env["SB3_LOGDIR"] = str(log_dir)
    return subprocess.run([sys.executable, *code], capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env)


# -- ids in fresh processes ---------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_colon_id_works_in_a_fresh_process(name):
    code = (f"import gymnasium as gym; env = gym.make('spreadgym:{name}', granules=32); "
            "obs, _ = env.reset(seed=0); print(env.observation_space.contains(obs))")
    out = run_python(["-c", code])
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "True"


def test_namespaced_id_needs_the_import_in_a_fresh_process():
    """What docs/rl-tools.md says: gymnasium 1.x loads no plugins, so `spreadgym/...` is
    unknown in a process that has not imported spreadgym, and known once it has."""
    bare = run_python(["-c", "import gymnasium as gym; gym.make('spreadgym/SpinnerDesign-v0')"])
    assert bare.returncode != 0 and "NamespaceNotFound" in bare.stderr
    code = "import gymnasium as gym, spreadgym; gym.make('spreadgym/SpinnerDesign-v0', granules=32)"
    imported = run_python(["-c", code])
    assert imported.returncode == 0, imported.stderr


def test_subproc_vec_env_with_the_namespaced_id(tmp_path):
    """SB3's make_vec_env + SubprocVecEnv (forkserver) with `spreadgym/...`: the workers
    re-import the main script, whose `import spreadgym` registers the ids there (both
    ids at once, so one env shows it; each pair of fresh workers costs ~25 s here)."""
    script = tmp_path / "train_script.py"
    script.write_text(textwrap.dedent("""
        import numpy as np
        import spreadgym  # noqa: F401
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.vec_env import SubprocVecEnv

        if __name__ == "__main__":
            envs = make_vec_env("spreadgym/SpreaderTuning-v0", n_envs=2, seed=0, vec_env_cls=SubprocVecEnv,
                                env_kwargs={"granules": 32})
            obs = envs.reset()
            obs, rewards, dones, infos = envs.step(np.zeros((2,) + envs.action_space.shape))
            assert obs.shape[0] == 2 and np.all(np.isfinite(rewards))
            envs.close()
            print("ok")
    """))
    out = run_python([str(script)], cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("ok")


# -- registry conventions -------------------------------------------------------------------
def test_spreader_tuning_time_limit_is_in_the_spec_and_agrees_with_the_env():
    max_steps = load_env_config(TUNING).max_steps
    for form in ("spreadgym/{}", "spreadgym:{}", "{}"):
        assert gym.spec(form.format("SpreaderTuning-v0")).max_episode_steps == max_steps
    env = gym.make("spreadgym/SpreaderTuning-v0", granules=16)
    assert isinstance(env, gym.wrappers.TimeLimit) and env.get_wrapper_attr("_max_episode_steps") == max_steps
    assert env.unwrapped.config.max_steps == max_steps  # the env's own truncation, at the same step
    assert gym.spec("spreadgym/SpinnerDesign-v0").max_episode_steps is None  # ends itself after one step


def test_colon_id_is_in_the_registry_for_tools_that_check_it():
    assert "spreadgym:SpinnerDesign-v0" in gym.registry and "spreadgym:SpreaderTuning-v0" in gym.registry


# -- native vector env ------------------------------------------------------------------------
def _actions(seed, n, size):
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n, size)).astype(np.float32)


def _pick(infos: dict, i: int) -> dict:
    """Sub-env i's info out of a vector env's dict of arrays (only the keys it set)."""
    return {k: (_pick(v, i) if isinstance(v, dict) else v[i]) for k, v in infos.items()
            if not k.startswith("_") and infos[f"_{k}"][i]}


def _assert_same(a, b):
    """Equal bit for bit (floats by value, NaN at the same places)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            _assert_same(a[key], b[key])
    elif isinstance(a, (list, tuple, np.ndarray)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        assert np.asarray(a).dtype == np.asarray(b).dtype or np.asarray(a).dtype == object
    else:
        assert a == b or (a != a and b != b), (a, b)


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
def test_vector_env_equals_single_envs_step_by_step(mode):
    n, steps, seed = 3, 4, 11
    venv = gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=n, autoreset_mode=mode, **SMALL)
    assert isinstance(venv, SpinnerDesignVectorEnv)
    singles = [gym.make("spreadgym/SpinnerDesign-v0", **SMALL) for _ in range(n)]
    obs, infos = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        o, info = env.reset(seed=seed + i)
        np.testing.assert_array_equal(obs[i], o, strict=True)
        _assert_same(_pick(infos, i), info)
    pending = [False] * n  # next_step mode: this sub-env resets in this call
    for step in range(steps):
        actions = _actions(step, n, venv.single_action_space.shape[0])
        obs, rewards, terminated, truncated, infos = venv.step(actions)
        for i, env in enumerate(singles):
            if pending[i]:
                o, info = env.reset()
                r, te, tr = 0.0, False, False
            else:
                o, r, te, tr, info = env.step(actions[i])
                if mode == "same_step" and (te or tr):
                    final = _pick(infos, i)
                    np.testing.assert_array_equal(final.pop("final_obs"), o, strict=True)
                    _assert_same(final.pop("final_info"), info)
                    o, info = env.reset()
            np.testing.assert_array_equal(obs[i], o, strict=True)
            assert rewards[i] == r and terminated[i] == te and truncated[i] == tr
            mine = _pick(infos, i)
            mine.pop("final_obs", None), mine.pop("final_info", None)
            _assert_same(mine, info)
            pending[i] = mode == "next_step" and (te or tr)
    venv.close()


def test_vector_env_refuses_bad_arguments():
    with pytest.raises(ConfigError, match="autoreset_mode"):
        SpinnerDesignVectorEnv(num_envs=2, autoreset_mode="sometimes", **SMALL)
    with pytest.raises(ConfigError, match="num_envs"):
        SpinnerDesignVectorEnv(num_envs=0, **SMALL)
    venv = SpinnerDesignVectorEnv(num_envs=2, **SMALL)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="2 rows"):
        venv.step(np.zeros((3, venv.single_action_space.shape[0])))


# -- settings <-> actions ----------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_settings_round_trip_through_the_action(name):
    env = gym.make(f"spreadgym/{name}", **SMALL)
    ranges = setting_ranges(env)
    cfg = load_env_config(DESIGN if name.startswith("Spinner") else TUNING)
    assert list(ranges)[:2] == ["rpm", "pitch_deg"] and ranges["rpm"] == tuple(cfg.settings.rpm)
    lows = [lo for lo, _ in ranges.values()]
    highs = [hi for _, hi in ranges.values()]
    np.testing.assert_allclose(settings_to_action(env, action_to_settings(env, -np.ones(len(ranges)))), -1.0)
    np.testing.assert_allclose(settings_to_action(env, action_to_settings(env, np.ones(len(ranges)))), 1.0)
    middle = {"rpm": 0.5 * (lows[0] + highs[0]), "pitch_deg": 0.5 * (lows[1] + highs[1]),
              "deflector_angle_deg": [0.5 * (lo + hi) for lo, hi in zip(lows[2:], highs[2:])]}
    np.testing.assert_allclose(settings_to_action(env, middle), 0.0, atol=1e-7)
    # the settings an env step reports map back onto the action that produced them
    env.reset(seed=0)
    action = np.array([0.25, -0.5] + [0.75] * (len(ranges) - 2), dtype=np.float32)
    if name.startswith("Spinner"):
        *_, info = env.step(action)
        np.testing.assert_allclose(settings_to_action(env, info["settings"]), action, atol=1e-6)


def test_settings_to_action_names_a_bad_value():
    env = gym.make("spreadgym/SpinnerDesign-v0", **SMALL)
    lo, hi = setting_ranges(env)["rpm"]
    angles = [0.0] * (len(setting_ranges(env)) - 2)
    with pytest.raises(ConfigError, match=r"settings\.rpm.*outside"):
        settings_to_action(env, {"rpm": hi + 1, "pitch_deg": 0.0, "deflector_angle_deg": angles})
    with pytest.raises(ConfigError, match="settings.speed"):
        settings_to_action(env, {"rpm": lo, "pitch_deg": 0.0, "speed": 1})


# -- rl_zoo3 (only when installed: the `zoo` extra) -------------------------------------------------
@pytest.mark.parametrize("algo", ["ppo", "sac", "tqc"])
def test_zoo_hyperparameter_files_have_both_envs(algo):
    data = yaml.safe_load(hyperparams_path(algo).read_text())
    keys = [form.format(name) for name in NAMES for form in ("spreadgym:{}", "spreadgym/{}")]
    keys += ["spreadgym/SpinnerDesign-v1", "spreadgym/SpreaderTuning-v1"]  # v1: its one namespaced id
    for key in keys:
        entry = data[key]
        assert {"n_timesteps", "policy"} <= set(entry)
        assert not {"env", "seed", "checkpoint_freq", "max_minutes"} & set(entry)  # zoo's own arguments


def test_zoo_path_command():
    out = run_python(["-m", "spreadgym.envs.zoo", "path", "sac"])
    assert out.returncode == 0 and out.stdout.strip() == str(hyperparams_path("sac"))
    bad = run_python(["-m", "spreadgym.envs.zoo", "path", "dqn"])
    assert bad.returncode == 2 and "shipped: ppo, sac, tqc" in bad.stderr


@pytest.mark.parametrize("algo", ["ppo", "tqc"])
def test_zoo_reads_the_shipped_file_and_trains(algo, tmp_path):
    pytest.importorskip("rl_zoo3")
    if algo == "tqc":
        pytest.importorskip("sb3_contrib")
    import argparse

    from rl_zoo3.exp_manager import ExperimentManager

    manager = ExperimentManager(argparse.Namespace(), algo, "spreadgym:SpinnerDesign-v0", str(tmp_path),
                                config=str(hyperparams_path(algo)))
    hyperparams, _ = manager.read_hyperparameters()
    assert hyperparams["n_timesteps"] > 0
    args = ["-m", "rl_zoo3.train", "--algo", algo, "--env", "spreadgym:SpinnerDesign-v0", "--gym-packages",
            "spreadgym", "-conf", str(hyperparams_path(algo)), "--num-threads", "1", "-f", str(tmp_path),
            "--env-kwargs", "granules:32", "--vec-env", "subproc"]
    # PPO: one rollout (2 envs x 32 steps); TQC: a few gradient steps after 4 random ones
    args += ["-n", "64"] if algo == "ppo" else ["-n", "8", "--hyperparams", "learning_starts:4"]
    out = run_python(args, timeout=300, log_dir=tmp_path / "sb3")
    assert out.returncode == 0, out.stderr[-2000:]
    assert (tmp_path / algo / "SpinnerDesign-v0_1" / "SpinnerDesign-v0.zip").is_file()


def test_zoo_trains_a_v1_task_in_subprocesses_and_evaluate_scores_its_model(tmp_path):
    """The v1 id through `python -m spreadgym.envs.zoo train` (which imports spreadgym, so the
    forkserver workers of --vec-env subproc know the id); `spreadgym evaluate` then reads
    the env id and kwargs from zoo's args.yml."""
    pytest.importorskip("rl_zoo3")
    env_id = "spreadgym/SpinnerDesign-v1"
    args = ["-m", "spreadgym.envs.zoo", "train", "--algo", "ppo", "--env", env_id, "-conf",
            str(hyperparams_path("ppo")), "--num-threads", "1", "-f", str(tmp_path), "--env-kwargs", "granules:32",
            "--vec-env", "subproc", "-n", "64"]
    out = run_python(args, timeout=300, log_dir=tmp_path / "sb3")
    assert out.returncode == 0, out.stderr[-2000:]
    models = [p for p in (tmp_path / "ppo").glob("*/*.zip") if p.name != "best_model.zip"]
    assert len(models) == 1
    out = run_python(["-m", "spreadgym.cli.main", "evaluate", "--model", str(models[0]), "--granules", "32",
                      "--fertilizers", "pellet", "--json", "--no-plots", "--out", str(tmp_path / "eval")])
    assert out.returncode == 0, out.stderr[-2000:]
    data = yaml.safe_load(out.stdout)
    assert data["kind"] == "zoo" and data["env"] == "spreadgym:spreadgym/SpinnerDesign-v1"
    assert data["env_kwargs"] == {"granules": 32} and len(data["rows"]) == 4  # pellet at the four held-out widths


# -- RLlib (only when installed: the `rllib` extra, in its own venv) -----------------------------------
def test_rllib_trains_one_iteration_with_the_namespaced_id():
    pytest.importorskip("ray.rllib")
    code = textwrap.dedent("""
        import spreadgym.envs
        from ray.rllib.algorithms.ppo import PPOConfig
        spreadgym.envs.register_rllib()
        config = (PPOConfig().environment("spreadgym/SpinnerDesign-v1", env_config={"granules": 32})
                  .env_runners(num_env_runners=1, sample_timeout_s=600)  # a loaded CI machine: no empty sample
                  .training(train_batch_size=16, minibatch_size=8, num_epochs=1))
        algo = config.build_algo()
        result = algo.train()
        print("return", result["env_runners"]["episode_return_mean"])
        algo.stop()
    """)
    out = run_python(["-c", code], timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    value = float(out.stdout.strip().splitlines()[-1].split()[1])
    low, high = gym.make("spreadgym/SpinnerDesign-v0", **SMALL).unwrapped.reward_bounds
    assert low <= value <= high
