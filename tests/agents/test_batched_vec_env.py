"""`train`'s batched vector env (agents/batched_vec_env.py) against SB3's own SubprocVecEnv:
the same observations, rewards, ends, infos and trained policy, bit for bit."""

from functools import partial

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

from spreadgym.agents.batched_vec_env import BatchedVecEnv, env_infos
from spreadgym.agents.run_config import default_config_path, read_config, validate_config
from spreadgym.agents.training_env import threads_shared, worker_env
from spreadgym.errors import ConfigError

DESIGN = "spreadgym/SpinnerDesign-v1"
TUNING = "spreadgym/SpreaderTuning-v1"


def assert_same(a, b, where="info", strict=False):
    """Equal values, arrays equal to the bit, dicts key for key; numpy scalars equal to
    Python numbers unless `strict`, which asks for the same types throughout."""
    if strict:
        assert type(a) is type(b), f"{where}: {type(a).__name__} != {type(b).__name__}"
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for key in a:
            assert_same(a[key], b[key], f"{where}.{key}", strict)
    elif strict and isinstance(a, (list, tuple)):
        assert len(a) == len(b), f"{where}: {a!r} != {b!r}"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]", strict)
    elif isinstance(a, (np.ndarray, list, tuple)):
        assert np.array_equal(np.asarray(a), np.asarray(b)), f"{where}: {a!r} != {b!r}"
        assert not strict or np.asarray(a).dtype == np.asarray(b).dtype, f"{where}: dtypes differ"
    elif isinstance(a, float):
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), f"{where}: {a!r} != {b!r}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def step_both(ours, theirs, steps: int, seed: int = 0, strict: bool = False):
    """Step both VecEnvs with the same random actions; compare everything SB3 reads (the
    rewards as `theirs` types them: SubprocVecEnv float64, DummyVecEnv float32)."""
    assert np.array_equal(ours.reset(), theirs.reset())
    assert ours._seeds == [None] * ours.num_envs and ours._options == [{}] * ours.num_envs  # used once
    for i, (a, b) in enumerate(zip(ours.reset_infos, theirs.reset_infos)):
        assert_same(b, a, f"reset_infos[{i}]", strict)
    rng = np.random.default_rng(seed)
    ends = cut = 0
    for _ in range(steps):
        actions = rng.uniform(-1, 1, (ours.num_envs, *ours.action_space.shape)).astype(np.float32)
        obs_a, rew_a, done_a, info_a = ours.step(actions)
        obs_b, rew_b, done_b, info_b = theirs.step(actions)
        assert np.array_equal(obs_a, obs_b) and obs_a.dtype == obs_b.dtype
        assert rew_a.dtype == np.float64 and rew_a.astype(rew_b.dtype).tobytes() == rew_b.tobytes()
        assert np.array_equal(done_a, done_b)
        for i, (a, b) in enumerate(zip(info_a, info_b)):
            b = {key: value for key, value in b.items() if key != "episode"}  # Monitor's (timed); no VecMonitor here
            assert_same(b, a, f"infos[{i}]", strict)
        for i, (a, b) in enumerate(zip(ours.reset_infos, theirs.reset_infos)):
            assert_same(b, a, f"reset_infos[{i}] after a step", strict)
        ends += int(done_a.sum())
        cut += sum(info["TimeLimit.truncated"] for info in info_a)
    return ends, cut


def test_the_design_tasks_step_as_in_subprocvecenv_workers():
    """Three envs in two worker processes against SubprocVecEnv's three: every step ends
    an episode, so every step checks terminal_observation and the reset in the same step."""
    kwargs = {"granules": 32}
    theirs = make_vec_env(partial(worker_env, DESIGN, None), n_envs=3, seed=5, env_kwargs=kwargs,
                          vec_env_cls=partial(threads_shared, SubprocVecEnv))  # as train builds them
    ours = BatchedVecEnv(gym.make_vec(DESIGN, num_envs=3, autoreset_mode="same_step", workers=2, **kwargs))
    ours.seed(5)
    try:
        assert step_both(ours, theirs, steps=3, strict=True) == (9, 0)  # each info as the env gave it
    finally:
        ours.close()
        theirs.close()


def test_a_vector_env_without_step_each_is_unstacked_alike():
    """The adapter's path for other gymnasium vector envs (stacked infos taken apart) on the
    design task, against the same vector env's own per-env records."""
    kwargs = {"granules": 32}
    ours = BatchedVecEnv(gym.make_vec(DESIGN, num_envs=3, autoreset_mode="same_step", **kwargs))
    plain = gym.make_vec(DESIGN, num_envs=3, autoreset_mode="same_step", **kwargs)
    theirs = BatchedVecEnv(gym.vector.VectorWrapper(plain))  # a wrapper hides step_each: stacked infos
    assert ours._each and not theirs._each
    for env in (ours, theirs):
        env.seed(4)
    try:
        assert step_both(ours, theirs, steps=2) == (6, 0)
    finally:
        ours.close()
        theirs.close()


def test_truncated_episodes_keep_their_last_observation_and_say_so():
    """SpreaderTuning's episodes end by the time limit (truncated, not terminated): the
    adapter over gymnasium's own sync vector env against DummyVecEnv of the same env."""
    kwargs = {"granules": 32, "max_steps": 2, "max_episode_steps": 2}
    theirs = make_vec_env(partial(worker_env, TUNING, None), n_envs=2, seed=3, env_kwargs=kwargs,
                          vec_env_cls=DummyVecEnv)
    ours = BatchedVecEnv(gym.make_vec(TUNING, num_envs=2, vectorization_mode="sync",
                                      vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP}, **kwargs))
    ours.seed(3)
    try:
        ends, cut = step_both(ours, theirs, steps=5)
        assert ends > cut > 0  # episodes ended both ways
    finally:
        ours.close()
        theirs.close()


def test_gymnasium_infos_go_back_to_one_dict_per_env():
    infos = {"a": np.array([1.0, 0.0]), "_a": np.array([True, False]),
             "nested": {"b": np.array([0, 7]), "_b": np.array([False, True])},
             "_nested": np.array([True, True])}
    assert env_infos(infos, 2) == [{"a": 1.0, "nested": {}}, {"nested": {"b": 7}}]


def test_what_the_adapter_cannot_do_is_said():
    vector = gym.make_vec(DESIGN, num_envs=2, autoreset_mode="next_step", granules=32)
    with pytest.raises(ValueError, match="same_step"):
        BatchedVecEnv(vector)
    vector.close()
    env = BatchedVecEnv(gym.make_vec(DESIGN, num_envs=2, autoreset_mode="same_step", granules=32))
    assert env.get_attr("render_mode") == [None, None] and env.env_is_wrapped(gym.Wrapper) == [False, False]
    with pytest.raises(AttributeError, match="'reset'.*vec_env: subproc"):
        env.env_method("reset")
    with pytest.raises(AttributeError, match="'x'.*vec_env: subproc"):
        env.set_attr("x", 1)
    assert env.get_attr("action_space")[0] == env.action_space  # one env's space, as SB3 reads it
    with pytest.raises(RuntimeError, match="without step_async"):
        env.step_wait()
    env.set_options([{"a": 1}, {}])
    with pytest.raises(ValueError, match="same options"):
        env.reset()
    env.set_options({"reset_mask": np.ones(2, dtype=bool)})
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset()
    env.close()


def test_train_records_episodes_with_vecmonitor():
    from spreadgym.agents.training_env import make_training_env

    cfg = validate_config("ppo", {**read_config(default_config_path("ppo")), "n_envs": 2, "workers": 1,
                                  "env_kwargs": {"granules": 32}}, "x")
    env = make_training_env(cfg, "errors")
    try:
        assert cfg.vec_env_kind == "batched"
        env.reset()
        _, rewards, _, infos = env.step(np.zeros((2, *env.action_space.shape), dtype=np.float32))
        assert [info["episode"]["r"] for info in infos] == pytest.approx(rewards.tolist(), rel=1e-6)
    finally:
        env.close()


@pytest.mark.parametrize("change, kind", [
    ({"n_envs": 3}, "batched"), ({"n_envs": 1}, "dummy"), ({"n_envs": 1, "vec_env": "batched"}, "batched"),
    ({"n_envs": 3, "vec_env": "subproc"}, "subproc"), ({"n_envs": 1, "vec_env": "subproc"}, "dummy"),
    ({"n_envs": 3, "env": TUNING}, "subproc"), ({"n_envs": 3, "vec_env": None}, "batched"),
    ({"n_envs": 1, "workers": 1}, "batched"), ({"n_envs": 2, "workers": 2}, "batched"),
    # one env a worker (2 threads): nothing to batch, SubprocVecEnv
    ({"n_envs": 2}, "subproc"),
    # what only one gym.make per env runs: auto leaves it to SubprocVecEnv
    ({"n_envs": 3, "env_kwargs": {"max_episode_steps": 3}}, "subproc"),
    ({"n_envs": 3, "env_kwargs": {"disable_env_checker": False}}, "subproc"),
    ({"n_envs": 3, "env_kwargs": {"render_mode": "human"}}, "subproc"),
    ({"n_envs": 3, "env_kwargs": {"render_mode": "rgb_array"}}, "batched"),
])
def test_auto_takes_the_batched_env_where_it_batches(monkeypatch, change, kind):
    monkeypatch.setenv("SPREADGYM_THREADS", "2")
    raw = read_config(default_config_path("ppo"))
    assert validate_config("ppo", {**raw, **change}, "x").vec_env_kind == kind


def test_auto_batches_above_the_thread_count(monkeypatch):
    raw = read_config(default_config_path("ppo"))
    for count, kind in ((8, "subproc"), (9, "batched")):
        monkeypatch.setenv("SPREADGYM_THREADS", "8")
        assert validate_config("ppo", {**raw, "n_envs": count}, "x").vec_env_kind == kind


@pytest.mark.parametrize("change, message", [
    ({"vec_env": "batched", "env": TUNING}, "vec_env: batched needs an env with a batched vector env"),
    ({"vec_env": "subproc", "workers": 2}, "workers: only the batched vector env has workers (vec_env: subproc)"),
    ({"n_envs": 64, "env": TUNING, "workers": 1}, "workers: only the batched vector env has workers (spreadgym:"),
    ({"n_envs": 2, "workers": 3}, "workers: at most n_envs (2), got 3"),
    ({"workers": 0}, "workers: Input should be greater than or equal to 1"),
    ({"vec_env": "ray"}, "vec_env: Input should be 'auto', 'batched' or 'subproc'"),
    ({"vec_env": "batched", "env_kwargs": {"max_episode_steps": 3}},
     "vec_env: batched cannot run this config (env_kwargs.max_episode_steps is a key of gym.make"),
    ({"n_envs": 2, "workers": 2, "env_kwargs": {"render_mode": "human"}},
     "workers: only the batched vector env has workers (env_kwargs.render_mode 'human': the vector env renders only"),
])
def test_bad_vec_env_keys_are_one_line_errors(change, message):
    raw = read_config(default_config_path("ppo"))
    with pytest.raises(ConfigError) as err:
        validate_config("ppo", {**raw, **change}, "x")
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


@pytest.mark.slow
@pytest.mark.parametrize("algo, normalize", [("ppo", False), ("ppo", True), ("sac", False)])
def test_training_on_the_batched_env_gives_subprocvecenvs_policy_to_the_bit(tmp_path, algo, normalize):
    """PPO (or SAC) for 48 steps of 3 envs: the policy's parameters (and VecNormalize's
    statistics) equal, whichever vector env stepped the envs."""
    import pickle

    from spreadgym.agents.run_config import algo_class
    from spreadgym.agents.training import train

    settings = ({"n_steps": 8, "batch_size": 8, "n_epochs": 2} if algo == "ppo" else
                {"learning_starts": 12, "batch_size": 8, "buffer_size": 100})
    params, stats = {}, {}
    for kind in ("subproc", "batched"):
        out = tmp_path / kind
        train(algo, out, overrides={"n_envs": 3, "vec_env": kind, "env_kwargs.granules": 32, "checkpoint_freq": 1000,
                                    "normalize": normalize, **settings}, timesteps=48, log=lambda message: None)
        params[kind] = algo_class(algo).load(out / "model.zip").policy.state_dict()
        if normalize:
            saved = pickle.loads((out / "vecnormalize.pkl").read_bytes())
            stats[kind] = (saved.obs_rms.mean, saved.obs_rms.var, saved.ret_rms.mean, saved.ret_rms.var)
    assert list(params["subproc"]) == list(params["batched"])
    for key, value in params["subproc"].items():
        assert np.array_equal(value.numpy(), params["batched"][key].numpy()), key
    for a, b in zip(stats.get("subproc", ()), stats.get("batched", ())):
        assert np.array_equal(a, b)


@pytest.mark.slow
@pytest.mark.parametrize("vec_env", ["batched", "subproc"])
def test_a_stop_signal_to_the_whole_process_group_still_saves_the_model(tmp_path, vec_env):
    """`timeout` and service managers send SIGTERM to the trainer's whole process group;
    the batched env's workers then stop with it (they leave only Ctrl-C to the trainer;
    SubprocVecEnv's ignore both), and the trainer saves the model as it was and exits 130."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    command = [sys.executable, "-m", "spreadgym.cli.main", "train", "--algo", "ppo", "--timesteps", "100000",
               "--set", "n_envs=4", "--set", f"vec_env={vec_env}", "--set", "env_kwargs.granules=32",
               "--set", "n_steps=8", "--set", "batch_size=8", "--out", str(out)]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not list((out / "tb").glob("*/*")) and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.2)  # the model exists and learn() has opened its log: steps are being taken
        time.sleep(2.0)
        os.killpg(process.pid, signal.SIGTERM)
        _, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == 130, err
    assert (out / "model.zip").is_file() and "Traceback" not in err, err


@pytest.mark.slow
def test_a_run_resumed_with_fewer_threads_than_its_workers_takes_what_there_is(tmp_path, monkeypatch):
    from spreadgym import threads
    from spreadgym.agents.training import train

    said = []
    settings = {"n_envs": 2, "workers": 2, "env_kwargs.granules": 32, "n_steps": 4, "batch_size": 4,
                "checkpoint_freq": 8}
    monkeypatch.setenv(threads.ENV_VAR, "1")
    with pytest.raises(ConfigError, match="^workers: 2 processes for the 1 threads"):  # a new run: its own error
        train("ppo", tmp_path / "new", overrides=settings, timesteps=8, log=said.append)
    monkeypatch.setenv(threads.ENV_VAR, "2")
    train("ppo", tmp_path / "run", overrides=settings, timesteps=8, log=said.append)
    monkeypatch.setenv(threads.ENV_VAR, "1")
    result = train("ppo", tmp_path / "run", timesteps=16, log=said.append)
    assert result.num_timesteps == 16 and result.resumed_from == 8
    assert any("workers 2 is more than the 1 threads" in line for line in said), said
    assert "workers: 2\n" in (tmp_path / "run" / "config.yaml").read_text(encoding="utf-8")  # the run's own count
