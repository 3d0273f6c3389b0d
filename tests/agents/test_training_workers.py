"""An exception in a training env worker (SubprocVecEnv) reaches the user as one line."""

import pytest

from spreadgym.agents import training, training_env
from spreadgym.cli.main import main
from spreadgym.config.resources import config_dir
from spreadgym.errors import SpreadgymError


def test_a_recorded_input_error_becomes_a_one_line_spreadgym_error(tmp_path):
    training_env._record_failure(str(tmp_path), SpreadgymError("scene: no file\n named x.yaml"))
    failure = training_env.worker_failure(str(tmp_path))
    assert isinstance(failure, SpreadgymError)
    assert str(failure) == "a training env worker stopped: scene: no file named x.yaml"


def test_a_recorded_bug_stays_a_bug_and_silence_is_said(tmp_path):
    assert "without a message" in str(training_env.worker_failure(str(tmp_path)))
    training_env._record_failure(str(tmp_path), ZeroDivisionError("division by zero"))
    failure = training_env.worker_failure(str(tmp_path))
    assert isinstance(failure, RuntimeError) and "ZeroDivisionError: division by zero" in str(failure)


@pytest.mark.slow
@pytest.mark.parametrize("vec_env, said", [("subproc", "a training env worker stopped:"), ("batched", "scene")])
def test_a_worker_that_cannot_build_its_env_ends_train_with_its_message(tmp_path, monkeypatch, capsys, vec_env, said):
    """The parent's check passes; the scene file is gone before the two workers start
    (SubprocVecEnv's, or the batched vector env's, whose errors reach the parent as they are)."""
    scene = tmp_path / "gone.yaml"
    scene.write_text((config_dir() / "scenes" / "paper.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    original = training.check_env_kwargs

    def check_then_remove(env_id, env_kwargs):
        spaces = original(env_id, env_kwargs)
        scene.unlink()
        return spaces

    monkeypatch.setattr(training, "check_env_kwargs", check_then_remove)
    code = main(["train", "--algo", "ppo", "--timesteps", "64", "--set", "n_envs=2", "--set", "env_kwargs.granules=32",
                 "--set", f"env_kwargs.scene={scene}", "--set", f"vec_env={vec_env}", "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert said in err and "gone.yaml" in err
    assert "Traceback" not in err.splitlines()[-1]


def test_the_workers_share_the_threads_instead_of_each_taking_them_all(monkeypatch):
    """SubprocVecEnv workers share spreadgym's threads out, all of them (processes and threads
    do not multiply: two workers of two threads each stepped 8 % slower on two cores); each
    worker sets its share before it builds its env."""
    from stable_baselines3.common import env_util, vec_env

    from spreadgym import threads
    from spreadgym.agents.run_config import default_config_path, read_config, validate_config

    made = []
    monkeypatch.setattr(env_util, "make_vec_env", lambda factory, **kwargs: made.append(kwargs["vec_env_cls"]))
    monkeypatch.setattr(vec_env, "SubprocVecEnv", lambda env_fns, **kwargs: env_fns)  # no processes: its env_fns
    monkeypatch.setenv(threads.ENV_VAR, "5")
    cfg = validate_config("ppo", read_config(default_config_path("ppo")), "shipped")
    counted = []

    def counts_threads():
        counted.append(threads.thread_count())
        return len(counted)

    for n, shares in [(2, [3, 2]), (3, [2, 2, 1]), (8, [1] * 8)]:
        training_env.make_training_env(cfg.replace(n_envs=n, vec_env="subproc"), "errors")
        counted.clear()
        fns = made[-1]([counts_threads] * n)  # what make_vec_env does with its ranked env makers
        try:
            assert [fn() for fn in fns] == list(range(1, n + 1)) and counted == shares
        finally:
            threads.set_threads(None)  # each worker set its own process's count: here, this one's
    training_env.make_training_env(cfg.replace(n_envs=1, vec_env="subproc"), "errors")
    assert made[-1] is vec_env.DummyVecEnv  # one env: in this process, on its threads


def test_the_batched_env_takes_one_worker_per_thread_at_most_n_envs(monkeypatch):
    """The batched vector env's workers share spreadgym's threads among them (envs/shards.py):
    one worker per thread by default, never more than n_envs, or as many as `workers` says."""
    import gymnasium as gym

    from spreadgym import threads
    from spreadgym.agents.run_config import default_config_path, read_config, validate_config

    asked, original = [], gym.make_vec

    def make_vec(env_id, num_envs, **kwargs):
        asked.append((num_envs, kwargs["workers"]))
        return original(env_id, num_envs=num_envs, autoreset_mode="same_step", granules=32)

    monkeypatch.setattr(gym, "make_vec", make_vec)
    monkeypatch.setenv(threads.ENV_VAR, "5")
    cfg = validate_config("ppo", read_config(default_config_path("ppo")), "shipped")
    for change in ({"n_envs": 2, "vec_env": "batched"}, {"n_envs": 8}, {"n_envs": 8, "workers": 2}):
        training_env.make_training_env(cfg.replace(**change), "errors").close()
    assert asked == [(2, 2), (8, 5), (8, 2)]
