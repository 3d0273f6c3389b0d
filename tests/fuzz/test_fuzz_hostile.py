"""The hostile pass of issue 36, kept in the suite: file bombs and depth, huge sizes, chart
folder corruption, Ray environment variables and env call sequences. Every input either
gives a correct result or one line naming the file, key or flag, each within its own time
(and, where it could grow, memory) cap: never a hang, a traceback or an exhausted machine."""

import io
import json
import math
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import bounded, time_limit
from hypothesis import example, given, settings
from hypothesis import strategies as st

import spreadgym.envs  # noqa: F401  (registers the ids)
from spreadgym.cli.main import main
from spreadgym.config.resources import MAX_YAML_BYTES, MAX_YAML_DEPTH, MAX_YAML_NODES, read_yaml
from spreadgym.errors import ConfigError, SpreadgymError


def run_cli(argv: list[str], seconds: int = 10) -> tuple[int, str]:
    """(exit status, stderr) of one command line, within `seconds` and 1 GiB more memory."""
    out, err = io.StringIO(), io.StringIO()
    with bounded(seconds), redirect_stdout(out), redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as ended:  # argparse
            code = ended.code
    return code, err.getvalue()


def refused(argv: list[str], fragment: str, seconds: int = 10) -> None:
    code, err = run_cli(argv, seconds)
    lines = err.strip().splitlines()
    assert code == 2 and "Traceback" not in err, err[-2000:]
    assert fragment in lines[-1], lines[-1]


# -- file bombs and depth ---------------------------------------------------------------

def laughs(levels: int, fanout: int, key: str) -> str:
    """Nested aliases: `levels` anchors, each a list of `fanout` aliases of the one before."""
    lines = ["a0: &a0 [" + ", ".join(['"lol"'] * fanout) + "]"]
    for level in range(1, levels):
        lines.append(f"a{level}: &a{level} [" + ", ".join([f"*a{level - 1}"] * fanout) + "]")
    return "\n".join(lines) + f"\n{key}: *a{levels - 1}\n"


BOMBS = {
    "billion laughs as the name": (laughs(9, 9, "name"), "holds more than 10000 values (aliases counted as copies)"),
    "billion laughs as the description": (laughs(9, 9, "description"), "holds more than"),
    "100 000 [": ("[" * 100_000, f"nested deeper than {MAX_YAML_DEPTH} levels"),
    "5 000 nested {a: ": ("{a: " * 5000, f"nested deeper than {MAX_YAML_DEPTH} levels"),
    "aliases nesting deeper than the limit": (
        "\n".join([f"a0: &a0 {'[' * 40}1{']' * 40}"] + [f"a{i}: &a{i} {'[' * 40}*a{i - 1}{']' * 40}"
                                                         for i in range(1, 4)]) + "\n",
        "aliases nest deeper than"),
    "a recursive alias": ("a: &a [1, *a]\n", "recursive alias"),
    "a flat list of 499 000 values in 1 MB": ("name: [" + ",".join(["1"] * 499_000) + "]\n", "holds more than"),
    "90 000 keys": ("".join(f"k{i}: 1\n" for i in range(90_000)), "holds more than"),
    "a 2 MB description": ("name: x\ndescription: " + "x" * 2_000_000 + "\n", "larger than 1000000 bytes"),
    "600 000 plates": ("deflectors:\n" + "  - {x_m: 0.3, y_m: 0, angle_deg: 0, length_m: 0.1, material: mc}\n"
                       * 600_000, "larger than 1000000 bytes"),
}


@pytest.mark.parametrize("name", BOMBS)
def test_a_hostile_scene_file_is_one_line_naming_it(name, tmp_path):
    text, fragment = BOMBS[name]
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    refused(["simulate", "--scene", str(path)], fragment)
    _, err = run_cli(["simulate", "--scene", str(path)])
    assert str(path) in err and len(err) < 400


def test_an_endless_file_is_read_no_further_than_the_limit():
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero here")
    with bounded(10), pytest.raises(ConfigError, match=f"larger than {MAX_YAML_BYTES} bytes"):
        read_yaml(Path("/dev/zero"))


def test_a_deep_set_value_is_one_line():
    refused(["simulate", "--set", "name=" + "[" * 100_000], "nested deeper than")


@settings(max_examples=25)
@given(levels=st.integers(1, 12), fanout=st.integers(1, 12), key=st.sampled_from(["name", "description", "x"]))
def test_alias_chains_load_within_the_limit_or_are_refused(tmp_path_factory, levels, fanout, key):
    path = tmp_path_factory.mktemp("alias") / "scene.yaml"
    path.write_text(laughs(levels, fanout, key))
    expanded = sum(fanout ** k for k in range(1, levels + 1)) * 2 + levels * 2 + 3  # an upper bound
    with bounded(10):
        try:
            data = read_yaml(path)
        except ConfigError as error:
            assert error.key == str(path) and "\n" not in str(error)
            assert expanded > MAX_YAML_NODES  # only a document beyond the limit is refused
            return
    assert len(data) == levels + (key not in {f"a{i}" for i in range(levels)})


# -- huge sizes -------------------------------------------------------------------------

CHART = ["chart", "--scene", "paper", "--fertilizers", "pellet", "--widths", "3"]


@pytest.mark.parametrize("argv, fragment", [
    (["simulate", "--set", "sim.granules=1000000", "--set", "sim.angle_copies=256"],
     "sim.granules: 1000000 x sim.angle_copies 256 = 256000000 landing points per run; allowed: at most 4000000"),
    (["simulate", "--scene", "twin-field", "--set", "sim.granules=1000000"], "x 2 discs"),
    (["simulate", "--set", "pattern.target_swath_m=0.5"], "narrower than 2 trays"),
    (CHART + ["--budget", "1000000000000"], "--budget: 1000000000000 is out of range; allowed: in [1, 100000]"),
    (CHART[:-1] + ["0.5:100:1e-9"], "9.95e+10 widths; allowed: at most 2000"),
    (CHART[:-1] + ["0.1:100:0.00001"], "widths; allowed: at most 2000"),
    (CHART + ["--granules", "1000000"], "--granules: 1000000 x sim.angle_copies 32"),
])
def test_a_huge_request_is_refused_before_the_work(argv, fragment, tmp_path):
    out = tmp_path / "out"
    refused(argv + (["--out", str(out)] if argv[0] == "chart" else []), fragment)
    assert not out.exists()


def test_an_env_asking_for_more_than_memory_holds_is_refused():
    with bounded(10), pytest.raises(ConfigError, match="landing points per run"):
        gym.make("spreadgym/SpinnerDesign-v0", granules=1_000_000)


# -- chart folder corruption ------------------------------------------------------------

@pytest.fixture(scope="module")
def cell_record(tmp_path_factory):
    """A finished one-cell chart folder (closed-form search, two short verification runs)."""
    from spreadgym.agents.chart import make_spec, run_chart

    spec = make_spec("paper", "pellet", "3", budget=2, granules=64, search_model="analytic", verify_runs=2)[0]
    out = tmp_path_factory.mktemp("chart")
    run_chart(spec, out, engine="local", progress=False)
    record = json.loads((out / "cells" / f"{spec.cells[0].key}.json").read_text(encoding="utf-8"))
    return spec, record


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=4),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner,
                                                                                 max_size=3), max_leaves=8)
IDENTITY = {("row", "fertilizer"), ("row", "width_m"), ("row", "driving"), ("detail", "key")}


@given(part=st.sampled_from(["row", "detail"]), data=st.data(), value=JSON)
def test_a_damaged_cell_record_is_never_taken_for_its_cell(cell_record, part, data, value):
    from spreadgym.agents.chart.store import record_problem

    spec, record = cell_record
    damaged = json.loads(json.dumps(record))
    key = data.draw(st.sampled_from(sorted(damaged[part])))
    damaged[part][key] = value
    with time_limit(10):
        problem = record_problem(spec, spec.cells[0], damaged)
    if (part, key) in IDENTITY and value != record[part][key]:
        assert problem is not None
    if problem is None:  # an unchanged identity and values of the right kind: still a record of its cell
        assert damaged["row"]["width_m"] == 3.0 and damaged["detail"]["key"] == spec.cells[0].key


@given(content=st.binary(max_size=200) | JSON.map(lambda v: json.dumps(v).encode()))
def test_any_cell_file_loads_as_its_record_or_not_at_all(cell_record, tmp_path_factory, content):
    from spreadgym.agents.chart.store import ChartStore

    spec, _ = cell_record
    store = ChartStore(tmp_path_factory.mktemp("store"), spec)
    store.cell_path(spec.cells[0]).parent.mkdir(parents=True)
    store.cell_path(spec.cells[0]).write_bytes(content)
    with time_limit(10):
        record, problem = store.load(spec.cells[0])
    assert record is None and problem


# -- Ray environment variables ----------------------------------------------------------

@given(st.one_of(st.text(max_size=30), st.sampled_from(["auto", "local", "127.0.0.1:1", "ray://127.0.0.1:1",
                                                        "localhost:6379", ""])))
def test_ray_address_in_the_environment_is_never_joined(address):
    import ray

    from spreadgym.agents.chart import runner

    calls = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("RAY_ADDRESS", address.replace("\x00", ""))
        patch.setattr(ray, "is_initialized", lambda: False)
        patch.setattr(ray, "init", lambda **kwargs: calls.append(kwargs))
        with time_limit(10):
            assert runner.connect_ray(1, None)
    assert calls[0]["address"] == "local"


@given(port=st.integers(-10, 10**6))
def test_an_address_port_is_checked_before_ray_is_asked(port):
    from spreadgym.agents.chart.runner import check_address

    with time_limit(10):
        try:
            check_address(f"127.0.0.1:{port}")
        except SpreadgymError as error:
            message = str(error)
            assert "\n" not in message
            if not 1 <= port <= 65535:
                assert "out of range; allowed [1, 65535]" in message or "expected HOST:PORT" in message


# -- env call sequences -----------------------------------------------------------------

BAD_OPTIONS = [{"context": {"fertilizer": "nope"}}, {"context": {"wind_m_s": [math.nan, 0.0]}},
               {"context": {"target_swath_m": 1j}}, {"context": {"target_swath_m": 0.5}}, {"foo": 1}, "x"]
BAD_ACTIONS = [[0.1 + 1j, 0.0], "ab", [math.inf, 0.0], [[0.0, 0.0]], None]
OPS = st.lists(st.one_of(st.tuples(st.just("reset"), st.integers(0, 3)),
                         st.tuples(st.just("bad reset"), st.sampled_from(range(len(BAD_OPTIONS)))),
                         st.tuples(st.just("step"), st.floats(-2, 2)),
                         st.tuples(st.just("bad step"), st.sampled_from(range(len(BAD_ACTIONS))))),
               min_size=1, max_size=6)


@pytest.fixture(scope="module", params=["spreadgym/SpinnerDesign-v0", "spreadgym/SpreaderTuning-v0"])
def any_env(request):
    env = gym.make(request.param, granules=64, disable_env_checker=True)
    yield env
    env.close()


@settings(max_examples=15)
@given(ops=OPS)
@example(ops=[("reset", 0), ("bad reset", 0), ("step", 0.0)])  # the state a failed reset leaves
@example(ops=[("reset", 0), ("bad step", 0), ("step", 0.0)])  # a complex action
def test_env_call_sequences_stay_consistent(any_env, ops):
    """Refusals are ConfigError / ValueError / ResetNeeded of one line; a failed reset leaves
    an env that needs a reset; after a good one a good step runs (SpreaderTuning: until
    its episode ends)."""
    env = any_env
    size = env.action_space.shape[0]
    episodic = "Tuning" in env.spec.id
    with time_limit(60):
        with pytest.raises(ConfigError):
            env.reset(seed=0, options={"context": {"fertilizer": "nope"}})
        steps = False  # whether a good step must run now
        for op, arg in ops:
            try:
                if op == "reset":
                    env.reset(seed=arg)
                    steps = True
                elif op == "bad reset":
                    steps = False
                    env.reset(seed=0, options=BAD_OPTIONS[arg])
                    raise AssertionError(f"accepted {BAD_OPTIONS[arg]!r}")
                elif op == "step":
                    _, reward, terminated, truncated, _ = env.step(np.full(size, arg))
                    assert steps and math.isfinite(reward), "a step ran where a reset was needed"
                    steps = not (episodic and (terminated or truncated))
                else:
                    env.step(BAD_ACTIONS[arg] if arg != 0 else [0.1 + 1j] + [0.0] * (size - 1))
                    raise AssertionError(f"accepted {BAD_ACTIONS[arg]!r}")
            except gym.error.ResetNeeded:
                assert not steps or op == "bad step"
            except ValueError as error:  # ConfigError is one
                assert "\n" not in str(error) and op in ("bad reset", "bad step"), (op, error)
