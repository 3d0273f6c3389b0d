"""The native vector env's `workers` (envs/shards.py): blocks of sub-envs in worker
processes give, bit for bit, what one process gives; bad counts, worker errors and a
killed worker each end in one line. Each env with workers starts fresh interpreters
(~1.5 s here), so there are few of them."""

import math
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time

import gymnasium as gym
import numpy as np
import pytest

import spreadgym  # noqa: F401  (registers the ids)
from spreadgym import threads
from spreadgym.envs import shards
from spreadgym.errors import ConfigError

ID = "spreadgym/SpinnerDesign-v1"
SMALL = {"granules": 48}


@pytest.fixture(autouse=True)
def _two_threads(monkeypatch):
    """Two threads whatever the machine: two workers of one thread each (inherited by the workers)."""
    monkeypatch.setenv(threads.ENV_VAR, "2")


def _same(a, b, path="") -> None:
    """a and b equal to the bit: arrays by dtype, shape and bytes, objects element by element."""
    if isinstance(a, dict):
        assert list(a) == list(b), path  # the same keys in the same order
        for key in a:
            _same(a[key], b[key], f"{path}/{key}")
    elif isinstance(a, (tuple, list)):
        assert type(a) is type(b) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, path
        if a.dtype == object:
            for i, (x, y) in enumerate(zip(a.ravel(), b.ravel())):
                _same(x, y, f"{path}[{i}]")
        else:
            assert a.tobytes() == b.tobytes(), path
    elif isinstance(a, float):
        assert type(b) is float and (a == b or math.isnan(a) and math.isnan(b)), (path, a, b)
    else:
        assert type(a) is type(b) and a == b, (path, a, b)


def _rollout(mode: str, workers: int) -> list:
    """reset, three steps and a masked reset of 5 sub-envs (blocks of 3 and 2 with two workers)."""
    venv = gym.make_vec(ID, num_envs=5, autoreset_mode=mode, workers=workers, **SMALL)
    try:
        rng = np.random.default_rng(4)
        out = [venv.reset(seed=30)]
        for _ in range(3):
            out.append(venv.step(rng.uniform(-1, 1, (5, 2)).astype(np.float32)))
            if mode == "disabled":  # every episode ends after one step: reset them all, the last two first
                out.append(venv.reset(seed=[None, None, None, 7, 8],
                                      options={"reset_mask": np.array([False, False, False, True, True])}))
                out.append(venv.reset(seed=[1, 2, 3, None, None],
                                      options={"reset_mask": np.array([True, True, True, False, False])}))
        out.append(venv.reset(seed=[None, 50, None, None, 51],
                              options={"reset_mask": np.array([False, True, False, False, True])}))
        return out
    finally:
        venv.close()


@pytest.mark.parametrize("mode", ["same_step", "next_step", "disabled"])
def test_workers_give_one_process_bits(mode):
    _same(_rollout(mode, 1), _rollout(mode, 2))


def test_frames_come_back_one_per_sub_env_in_order():
    frames = []
    for workers in (1, 2):
        venv = gym.make_vec(ID, num_envs=2, render_mode="rgb_array", workers=workers,
                            **{**SMALL, "render.width_px": 64, "render.height_px": 64})
        try:
            venv.reset(seed=0)
            venv.step(np.array([[0.5, -0.5], [-0.5, 0.5]], dtype=np.float32))
            frames.append(venv.render())
        finally:
            venv.close()
    _same(frames[0], frames[1])


@pytest.mark.parametrize("bad", [0, -1, 6, 2.0, True, "2", None])
def test_a_bad_worker_count_is_a_one_line_error_before_any_process_starts(bad):
    with pytest.raises(ConfigError) as err:
        gym.make_vec(ID, num_envs=5, workers=bad, **SMALL)
    assert str(err.value).startswith("workers:") and "\n" not in str(err.value)
    assert not multiprocessing.active_children()


def test_a_single_env_given_workers_says_where_they_belong():
    with pytest.raises(ConfigError, match=r"^workers: unknown key; .*gym\.make_vec\(id, num_envs=N, workers=P\)\)$"):
        gym.make(ID, workers=2, **SMALL)
    with pytest.raises(ConfigError) as err:  # SpreaderTuning has no vector env of its own: no hint
        gym.make("spreadgym/SpreaderTuning-v1", workers=2, **SMALL)
    assert "make_vec" not in str(err.value)


def test_workers_beyond_the_threads_are_refused(monkeypatch):
    monkeypatch.setenv(threads.ENV_VAR, "1")
    with pytest.raises(ConfigError, match=r"workers: 2 processes for the 1 threads .* allowed: 1 to 1"):
        gym.make_vec(ID, num_envs=4, workers=2, **SMALL)


def test_a_bad_action_or_option_changes_nothing_and_the_env_steps_on_as_one_process():
    """The parent checks actions and reset options before any worker runs, so after the
    error every block is where it was, and the next step (no reset between) has one
    process's bits."""
    nan = np.array([[0.0, 0.0], [0.0, 0.0], [np.nan, 0.0]], dtype=np.float32)  # the bad row in the second block
    errors, after = [], []
    for workers in (1, 2):
        venv = gym.make_vec(ID, num_envs=3, autoreset_mode="same_step", workers=workers, **SMALL)
        try:
            venv.reset(seed=0)
            with pytest.raises(Exception) as err:
                venv.step(nan)
            errors.append(err.value)
            with pytest.raises(ConfigError, match="options.bogus"):
                venv.reset(options={"bogus": 1})
            after.append(venv.step(np.full((3, 2), 0.25, dtype=np.float32)))
            after.append(venv.reset())
        finally:
            venv.close()
    assert type(errors[1]) is type(errors[0]) and str(errors[1]) == str(errors[0])
    assert "\n" not in str(errors[1])
    _same(after[:2], after[2:])


def test_an_error_inside_a_worker_keeps_its_type_message_and_traceback(monkeypatch):
    venv = gym.make_vec(ID, num_envs=2, autoreset_mode="same_step", workers=2, **SMALL)
    try:
        venv.reset(seed=0)
        # the parent refuses a bad context before any worker resets; without its check the
        # workers meet the error where they draw the context, and send it back
        monkeypatch.setattr(venv.task, "check_context", lambda given: None)
        with pytest.raises(ConfigError) as err:
            venv.reset(seed=0, options={"context": {"target_swath_m": "wide"}})
        assert str(err.value) == "options.context.target_swath_m: expected a number, got 'wide'"  # the env's own
        assert any("in a vector env worker process" in note for note in getattr(err.value, "__notes__", []))
        _steps_on(venv)
    finally:
        venv.close()


def test_ctrl_c_leaves_the_workers_running_and_the_pipes_in_step():
    """A terminal's Ctrl-C reaches every process of the group: the workers ignore it and
    finish their call; a call the parent abandoned leaves its answers, which the next call
    drops, so each call gets its own answers (one process's bits)."""
    one = gym.make_vec(ID, num_envs=2, autoreset_mode="same_step", **SMALL)
    two = gym.make_vec(ID, num_envs=2, autoreset_mode="same_step", workers=2, **SMALL)
    try:
        shards_ = two.unwrapped._shards
        for process in shards_._processes:
            os.kill(process.pid, signal.SIGINT)
        actions = np.array([[0.3, -0.2], [-0.6, 0.1]], dtype=np.float32)
        for venv in (one, two):
            venv.reset(seed=9)
        pipe = shards_._pipes[1]
        real = type(pipe).recv_bytes
        calls = []

        def interrupted_once(self):
            if self is pipe and not calls:
                calls.append(1)
                raise KeyboardInterrupt
            return real(self)

        type(pipe).recv_bytes = interrupted_once
        try:
            with pytest.raises(KeyboardInterrupt):
                two.step(actions)  # abandoned after worker 0's answer: worker 1's stays in its pipe
        finally:
            type(pipe).recv_bytes = real
        one.step(actions)  # what the workers did: both blocks stepped (and reset, same_step)
        _same(one.step(actions), two.step(actions))
        _same(one.reset(seed=3), two.reset(seed=3))
    finally:
        one.close()
        two.close()


@pytest.fixture
def _python_ctrl_c():
    """Python's own SIGINT handler (pytest may start with SIGINT ignored, as a background job does)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


@pytest.mark.parametrize("when", ["send", "receive"])
def test_a_ctrl_c_while_a_message_goes_through_is_held_until_it_is_accounted_for(_python_ctrl_c, when):
    """Ctrl-C arriving just as worker 0's message is sent (or its answer read): the
    KeyboardInterrupt comes once every message is out and marked owed (or once that answer
    is read and no longer owed), so the next calls drop what is left and get their own
    answers (one process's bits). Without the hold, worker 1's message would not go out and
    worker 0's answer would be read as the next call's (or worker 0 would stay owed an
    answer already read, and the next call would wait for it forever)."""
    one = gym.make_vec(ID, num_envs=2, autoreset_mode="same_step", **SMALL)
    two = gym.make_vec(ID, num_envs=2, autoreset_mode="same_step", workers=2, **SMALL)
    try:
        actions = np.array([[0.3, -0.2], [-0.6, 0.1]], dtype=np.float32)
        for venv in (one, two):
            venv.reset(seed=9)
        shards_ = two.unwrapped._shards
        pipe = shards_._pipes[0]
        name = "send_bytes" if when == "send" else "recv_bytes"
        real = getattr(type(pipe), name)
        hit = []

        def then_ctrl_c(self, *args):
            done = real(self, *args)
            if self is pipe and not hit:
                hit.append(1)
                os.kill(os.getpid(), signal.SIGINT)  # handled between two bytecodes of this process
            return done

        setattr(type(pipe), name, then_ctrl_c)
        try:
            with pytest.raises(KeyboardInterrupt):
                two.step(actions)
        finally:
            setattr(type(pipe), name, real)
        assert hit and signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert shards_._owed == ({0, 1} if when == "send" else {1})
        one.step(actions)  # what the workers did: both blocks stepped
        _same(one.step(actions), two.step(actions))
        _same(one.reset(seed=3), two.reset(seed=3))
    finally:
        one.close()
        two.close()


def test_the_workers_run_where_this_process_chose(monkeypatch):
    """A spawned worker reads the environment, not this process's `set_device`: it is given the device."""
    from spreadgym import device

    monkeypatch.setenv("SPREADGYM_DEVICE", "cuda")
    device.set_device("cpu")  # this process's choice wins over the variable (the conftest fixture resets it)
    venv = gym.make_vec(ID, num_envs=2, workers=2, **SMALL)
    try:
        _steps_on(venv)
    finally:
        venv.close()


def _steps_on(venv) -> None:
    """`venv` (two sub-envs) resets and steps to finite rewards."""
    venv.reset(seed=0)
    _, rewards, *_ = venv.step(np.zeros((2, 2), dtype=np.float32))
    assert np.all(np.isfinite(rewards))


def test_a_killed_worker_is_a_one_line_error_and_close_returns():
    venv = gym.make_vec(ID, num_envs=2, autoreset_mode="same_step", workers=2, **SMALL)
    try:
        venv.reset(seed=0)
        victim = venv.unwrapped._shards._processes[1]
        os.kill(victim.pid, signal.SIGKILL)
        victim.join(10)
        with pytest.raises(RuntimeError, match="vector env worker 1 stopped without an answer") as err:
            venv.step(np.zeros((2, 2), dtype=np.float32))
        assert "\n" not in str(err.value)
    finally:
        venv.close()
    assert not multiprocessing.active_children()


def test_a_script_without_the_main_guard_is_told_what_it_needs(tmp_path):
    """Spawned workers re-run the parent's script: without the guard each refuses to start
    another process and dies, and the parent says why instead of a bare broken pipe."""
    script = tmp_path / "no_guard.py"
    script.write_text("import gymnasium as gym, spreadgym\n"
                      f"gym.make_vec({ID!r}, num_envs=2, workers=2, granules=32).close()\n", encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("RuntimeError: vector env worker 0 stopped while starting (exit code 1; its error is on "
                           "stderr)") and 'needs `if __name__ == "__main__":` around it' in last


def test_blocks_are_contiguous_and_the_thread_shares_add_up(monkeypatch):
    assert shards.blocks(5, 2) == [(0, 3), (3, 5)]
    assert shards.blocks(64, 3) == [(0, 22), (22, 43), (43, 64)]
    for count, workers in [(2, 2), (16, 3), (16, 16), (7, 4)]:
        monkeypatch.setenv(threads.ENV_VAR, str(count))
        shares = threads.shares(workers)
        assert sum(shares) == count and max(shares) - min(shares) <= 1 and min(shares) >= 1


class _Probe:
    """A stand-in for a worker's vector env: what the worker loop sets up and hands back
    (it lives in the spawned worker; `closed` is a file it writes when closed)."""

    def __init__(self, num_envs: int, closed: str = "", fail: bool = False, slow_s: float = 0.0,
                 close_s: float = 0.0):
        if fail:
            raise ConfigError("granules", "expected >= 1, got 0")
        time.sleep(slow_s)  # a slow build, as numba's first compile makes one
        self.num_envs, self.closed, self.close_s = num_envs, closed, close_s

    def setup(self):
        from spreadgym import device

        ignores_ctrl_c = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
        return self.num_envs, threads.thread_count(), device.current(), ignores_ctrl_c

    def fails(self):
        raise ValueError("no such design")

    def unpicklable(self):
        return lambda: None

    def unloadable(self):
        return _Unloadable()

    def close(self):
        time.sleep(self.close_s)  # a close that hangs
        if self.closed:
            with open(self.closed, "w", encoding="utf-8") as handle:
                handle.write("closed")


class _Unloadable:
    """Pickles, but does not unpickle (as an object of a class the parent lacks would not)."""

    def __reduce__(self):
        return int, ("not a number",)


def _worker(probe_kwargs: dict):
    """A worker process running the loop on a _Probe block of 3 sub-envs, 5 threads, on the CPU."""
    ours, theirs = shards._START.Pipe()
    process = shards._START.Process(target=shards._serve, args=(theirs, _Probe, 3, 5, "cpu", probe_kwargs), daemon=True)
    process.start()
    theirs.close()
    return ours, process


def test_the_worker_loop_sets_up_its_process_hands_back_errors_and_closes(tmp_path):
    closed = tmp_path / "closed"
    ours, process = _worker({"closed": str(closed)})
    try:
        assert ours.recv() == ("ok", None)
        ours.send(("setup", ()))
        assert ours.recv() == ("ok", (3, 5, "cpu", True))  # its block, threads, device, and Ctrl-C left alone
        ours.send(("fails", ()))
        kind, error = ours.recv()
        assert kind == "error" and isinstance(error, ValueError) and str(error) == "no such design"
        assert "in a vector env worker process" in error.__notes__[0]
        ours.send(("unpicklable", ()))
        kind, error = ours.recv()
        assert kind == "error" and isinstance(error, RuntimeError) and "does not pickle" in str(error)
        ours.send(("close", ()))
        process.join(30)
        assert process.exitcode == 0 and closed.read_text(encoding="utf-8") == "closed"
    finally:
        process.kill()
    ours, process = _worker({"fail": True})
    kind, error = ours.recv()
    process.join(30)
    assert kind == "error" and isinstance(error, ConfigError) and str(error) == "granules: expected >= 1, got 0"
    assert "in a vector env worker process" in error.__notes__[0]  # a ConfigError keeps its notes across processes


def test_an_answer_that_does_not_unpickle_is_that_workers_error_and_the_pipes_stay_in_step(tmp_path):
    workers = shards.Shards(_Probe, 2, 2, "cpu", {"closed": str(tmp_path / "closed")})
    try:
        with pytest.raises(RuntimeError, match="vector env worker 0's answer does not unpickle here: ValueError"):
            workers.call("unloadable", [(), None])
        assert workers.call("setup", [(), ()]) == [(1, 1, "cpu", True)] * 2  # each its own answer, no hang
    finally:
        workers.close()


def test_close_after_an_abandoned_call_does_not_wait_for_its_answers():
    """A second Ctrl-C abandons a call whose answers (here two frames of about a megabyte)
    are larger than a pipe holds: the workers block sending them, so close() closes their
    pipes rather than waiting _CLOSE_WAIT_S (10 s) for each."""

    from spreadgym.envs import shards

    venv = gym.make_vec(ID, num_envs=2, autoreset_mode="same_step", render_mode="rgb_array", workers=2, **SMALL)
    venv.reset(seed=1)
    venv.step(np.array([[0.3, -0.2], [-0.6, 0.1]], dtype=np.float32))
    frames = venv.render()
    assert min(frame.nbytes for frame in frames) > 500_000
    shards_ = venv.unwrapped._shards
    pipe = shards_._pipes[0]
    real = type(pipe).recv_bytes

    def interrupted(self):
        if self is pipe:
            raise KeyboardInterrupt
        return real(self)

    type(pipe).recv_bytes = interrupted
    try:
        with pytest.raises(KeyboardInterrupt):
            venv.render()  # abandoned: both workers owe their frames
    finally:
        type(pipe).recv_bytes = real
    processes = list(shards_._processes)
    start = time.monotonic()
    venv.close()
    assert time.monotonic() - start < shards._CLOSE_WAIT_S / 2
    assert not any(process.is_alive() for process in processes)


def test_a_ctrl_c_while_the_workers_start_ends_them_promptly(_python_ctrl_c):
    """A Ctrl-C while the workers still build their sub-envs (each here takes 60 s, as a
    first compile can take a minute) raises at once, and the workers are ended within
    _OWED_WAIT_S, not after _CLOSE_WAIT_S each (30 s for three)."""
    alarm = threading.Timer(2.0, os.kill, (os.getpid(), signal.SIGINT))
    started = time.monotonic()
    alarm.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            shards.Shards(_Probe, 3, 3, "cpu", {"slow_s": 60.0})
    finally:
        alarm.cancel()
        alarm.join()  # no SIGINT left to arrive after the test
    assert time.monotonic() - started < 2.0 + shards._OWED_WAIT_S + 4.0
    assert not [p for p in multiprocessing.active_children() if p.name.startswith("spreadgym-vector-worker")]



def test_close_waits_once_for_all_the_workers_not_for_each(monkeypatch):
    """Three workers whose close hangs are terminated after one _CLOSE_WAIT_S in all (here
    2 s), not one each (6 s)."""
    monkeypatch.setattr(shards, "_CLOSE_WAIT_S", 2.0)
    workers = shards.Shards(_Probe, 3, 3, "cpu", {"close_s": 60.0})
    processes = list(workers._processes)
    started = time.monotonic()
    workers.close()
    assert time.monotonic() - started < 2.0 + 2.5
    assert not any(process.is_alive() for process in processes)
