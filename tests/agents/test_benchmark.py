"""The benchmark's protocol (agents/benchmark.py) and evaluating anything: rliable's aggregates
against hand-computed ones, normalisation, the resumable runner at tiny budgets, `evaluate`
and `compare` on a plain stable-baselines3 model file and on a callable."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spreadgym.agents import benchmark as bm
from spreadgym.agents.evaluation import make_env
from spreadgym.cli.main import main
from spreadgym.errors import SpreadgymError

GRANULES = 48


def run_cli(capsys, argv):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# -- aggregates ---------------------------------------------------------------------------------

def test_rliable_iqm_equals_the_hand_computed_one_on_a_small_table():
    """3 runs x 4 jobs holding 1..12: the interquartile mean is the mean of the middle six
    values, 4..9, = 6.5; the mean 6.5 too; a stratified bootstrap interval brackets both."""
    scores = {"a": np.arange(1.0, 13.0).reshape(3, 4),
              "b": np.array([[0.0, 0.0, 0.0, 10.0], [0.0, 1.0, 2.0, 3.0], [4.0, 5.0, 6.0, 100.0]])}
    found = bm.aggregate(scores, reps=500)
    point, low, high = found["a"]["iqm"]
    assert point == pytest.approx(6.5) and low <= 6.5 <= high and low < high
    assert found["a"]["mean"][0] == pytest.approx(6.5)
    # b sorted: 0 0 0 0 1 2 3 4 5 6 10 100; the middle six 0 1 2 3 4 5 -> 2.5; the mean is pulled by 100
    assert found["b"]["iqm"][0] == pytest.approx(2.5)
    assert found["b"]["mean"][0] == pytest.approx(131 / 12)
    again = bm.aggregate(scores, reps=500)
    assert again == found  # seeded
    alone = bm.aggregate({"a": scores["a"]}, reps=500)
    assert alone["a"] == found["a"]  # a method's interval does not depend on the others beside it
    assert bm.aggregate({"b": scores["b"], "a": scores["a"]}, reps=500)["a"] == found["a"]


def test_probability_of_improvement_equals_the_hand_counted_share():
    """Two jobs; on the first every run of x beats every run of y (1), on the second x's runs
    (1, 0) meet y's (1, 1, -1) in 6 pairs: 2 wins, 2 ties (half each), 2 losses (1/2): the mean is 3/4."""
    x = np.array([[2.0, 1.0], [3.0, 0.0]])
    y = np.array([[0.0, 1.0], [1.0, 1.0], [1.5, -1.0]])
    point, low, high = bm.probability_of_improvement(x, y, reps=300)
    assert point == pytest.approx(3 / 4) and low <= point <= high and low < high


def test_normalised_scores_are_0_at_the_random_action_and_1_at_the_best_setting():
    assert bm.normalise(-0.4, -0.4, -0.05) == 0.0
    assert bm.normalise(-0.05, -0.4, -0.05) == pytest.approx(1.0)
    assert bm.normalise(-0.225, -0.4, -0.05) == pytest.approx(0.5)
    with pytest.raises(SpreadgymError, match="not above the random action's"):  # no span: no score, no NaN
        bm.normalise(-0.1, -0.1, -0.1)


def test_performance_profiles_count_the_share_above_tau():
    scores = {"a": np.array([[0.1, 0.5, 0.9, 1.1]])}
    found, intervals = bm.profiles(scores, taus=np.array([0.0, 0.5, 1.0]), reps=50)
    assert list(found["a"]) == [1.0, 0.5, 0.25]  # shares strictly above tau


# -- the runner at tiny budgets -------------------------------------------------------------------

@pytest.fixture()
def tiny(monkeypatch):
    monkeypatch.setattr(bm, "SEARCH_BUDGET", 6)
    monkeypatch.setattr(bm, "REFERENCE_BUDGET", 8)
    monkeypatch.setattr(bm, "REFERENCE_EPISODES", 2)
    monkeypatch.setattr(bm, "RANDOM_ACTIONS", 3)
    monkeypatch.setattr(bm, "BOOTSTRAP_REPS", 200)
    monkeypatch.setattr(bm, "rung_env", lambda rung: make_env(rung.env_id, {"granules": GRANULES}))
    rung = bm.Rung("design", "spreadgym/SpinnerDesign-v1", 2, ("random-action", "centre", "cmaes"))
    monkeypatch.setitem(bm.RUNGS, "design", rung)
    return rung


def test_the_runner_scores_every_run_on_its_own_samples_and_resumes(tiny, tmp_path):
    jobs = bm.evaluation_set(env=bm.rung_env(tiny))[:2]
    env = bm.rung_env(tiny)
    bm.reference(tmp_path, tiny, env, jobs)
    for method in tiny.methods:
        for seed in range(tiny.seeds):
            bm.score_run(tmp_path, tiny, method, seed, env, jobs)
    reference = bm.read_json(tmp_path / "design" / "reference.json")
    assert list(reference["jobs"]) == [job.label for job in jobs]
    first = bm.read_json(bm.score_path(tmp_path, tiny, "centre", 0))
    second = bm.read_json(bm.score_path(tmp_path, tiny, "centre", 1))
    assert [r["episode"] for r in first["rows"]] == [0, 1, 0, 1]
    assert [r["episode"] for r in second["rows"]] == [2, 3, 2, 3]
    assert first["rows"][0]["sim_seed"] != second["rows"][0]["sim_seed"]  # each run its own granule samples
    assert first["rows"][0]["action"] == second["rows"][0]["action"] == [0.0, 0.0]
    searched = bm.read_json(bm.score_path(tmp_path, tiny, "cmaes", 1))
    assert all(r["search_simulations"] == 6 for r in searched["rows"])
    stamp = bm.score_path(tmp_path, tiny, "cmaes", 1).stat().st_mtime_ns
    assert bm.score_run(tmp_path, tiny, "cmaes", 1, env, jobs) == searched  # resumed: read, not rerun
    assert bm.score_path(tmp_path, tiny, "cmaes", 1).stat().st_mtime_ns == stamp
    rows, matrices = bm.rung_table(tmp_path, tiny)
    assert [r["key"] for r in rows] == list(tiny.methods)
    assert all(m.shape == (2, 2) and np.all(np.isfinite(m)) for m in matrices.values())
    for row in rows:
        assert row["iqm_low"] <= row["iqm"] <= row["iqm_high"] and row["runs"] == 2
    assert not list(tmp_path.rglob("*.part"))  # nothing half-written


def test_a_policy_stopped_before_its_end_is_neither_scored_nor_taken_as_trained(tiny, tmp_path):
    folder = bm.policy_dir(tmp_path, "design", "ppo", 0)
    folder.mkdir(parents=True)
    (folder / "model.zip").write_bytes(b"a stopped run writes its model too")
    (folder / "config.yaml").write_text("algo: ppo\ntrained: {num_timesteps: 1, stopped: time limit}\n")
    assert bm.trained_record(folder) is None
    with pytest.raises(SpreadgymError, match="no policy trained to its end"):
        bm.score_run(tmp_path, tiny, "ppo", 0)
    (folder / "config.yaml").write_text("algo: ppo\ntrained: {num_timesteps: 4096, stopped: done}\n")
    assert bm.trained_record(folder) == {"num_timesteps": 4096, "stopped": "done"}


def test_an_incomplete_rung_has_no_table(tiny, tmp_path):
    assert bm.rung_table(tmp_path, tiny) is None


# -- evaluate anything -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def plain_model(tmp_path_factory):
    """A stable-baselines3 PPO saved with `model.save`, no spreadgym run around it."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    env = gym.make("spreadgym/SpinnerDesign-v1", granules=GRANULES)
    path = tmp_path_factory.mktemp("plain") / "my_ppo.zip"
    PPO("MlpPolicy", env, n_steps=16, batch_size=16, seed=0, device="cpu").save(path)
    return path


@pytest.fixture()
def callable_file(tmp_path):
    path = tmp_path / "rule.py"
    path.write_text("import numpy as np\n\ndef policy(obs):\n    return np.array([0.2, obs[-1]], dtype=np.float32)\n")
    return path


def test_evaluate_a_plain_sb3_model_file(plain_model, capsys, tmp_path):
    code, out, err = run_cli(capsys, ["evaluate", "--model", str(plain_model), "--env", "spreadgym/SpinnerDesign-v1",
                                      "--granules", str(GRANULES), "--fertilizers", "mixture-17-21-17", "--json",
                                      "--no-plots", "--out", str(tmp_path)])
    assert code == 0, err
    data = json.loads(out)
    assert data["kind"] == "sb3" and data["env"] == "spreadgym:spreadgym/SpinnerDesign-v1"
    assert [row["context"]["target_swath_m"] for row in data["rows"]] == [2.9, 3.1, 4.9, 5.1]
    assert all(row["context"]["fertilizer"] == "mixture-17-21-17" for row in data["rows"])


def test_evaluate_a_callable(callable_file, capsys, tmp_path):
    code, out, err = run_cli(capsys, ["evaluate", "--model", f"{callable_file}:policy", "--granules", str(GRANULES),
                                      "--swaths", "4.9", "--json", "--no-plots", "--out", str(tmp_path)])
    assert code == 0, err
    data = json.loads(out)
    assert data["kind"] == "callable" and len(data["rows"]) == 3  # the three fertilizers at 4.9 m
    for row in data["rows"]:
        target = row["context"]["target_swath_m"]
        assert row["action"][0] == pytest.approx(0.2, abs=1e-7)
        assert row["action"][1] == pytest.approx((target - 2.0) / 2.0 - 1.0, abs=1e-6)  # the observed target


def test_evaluate_refuses_what_it_cannot_run(plain_model, capsys, tmp_path):
    for model, needle in ((f"{tmp_path}/none.py:policy", "cannot import"), ("json:nothing_here", "no callable"),
                          (str(plain_model), "does not fit")):
        env = ["--env", "spreadgym/SpinnerDesignPitch-v1"] if model == str(plain_model) else []
        code, _, err = run_cli(capsys, ["evaluate", "--model", model, *env, "--granules", str(GRANULES)])
        assert code == 2 and needle in err and "Traceback" not in err, err


@pytest.mark.filterwarnings("error::UserWarning")  # a legend of long labels once collapsed the chart's axes
def test_compare_groups_labelled_runs_and_normalises_with_references(plain_model, callable_file, capsys,
                                                                     tmp_path, monkeypatch):
    """Two runs under one label, a callable and two baselines with two seeds each, on two
    jobs; with (made-up) references for those jobs the table gains rliable's normalised IQM."""
    from spreadgym.agents.evaluation import evaluation_set

    jobs = evaluation_set(["pellet"], [2.9, 5.1], env=make_env("spreadgym/SpinnerDesign-v1", {"granules": GRANULES}))
    references = {"jobs": {job.label: {"random_reward": -0.6, "best_reward": -0.05} for job in jobs}}
    monkeypatch.setattr(bm, "shipped_references", lambda env_id: references)
    code, out, err = run_cli(capsys, [
        "compare", "--model", f"net={plain_model}", "--model", f"net={plain_model}",
        "--model", f"{callable_file}:policy", "--methods", "centre", "random-action", "--seeds", "2",
        "--granules", str(GRANULES), "--fertilizers", "pellet", "--swaths", "2.9", "5.1", "--json",
        "--out", str(tmp_path)])
    assert code == 0, err
    data = json.loads(out)
    table = {row["key"]: row for row in data["table"]}
    assert list(table) == ["net", f"{callable_file}:policy", "centre", "random-action"]
    assert table["net"]["runs"] == 2 and table["centre"]["runs"] == 2 and table[f"{callable_file}:policy"]["runs"] == 1
    for row in table.values():
        assert row["iqm_low"] <= row["iqm"] <= row["iqm_high"]
    centre = [r for r in data["rows"] if r["method"] == "centre"]
    assert sorted({r["episode"] for r in centre}) == [0, 1]  # run k scores on episode k (one per run)
    assert "normalised IQM" in (tmp_path / "compare.md").read_text()
    assert (tmp_path / "profiles.png").is_file()


def test_legend_labels_drop_a_policy_files_folders_stay_short_and_stay_apart():
    from spreadgym.agents.commands.compare import legend_labels

    assert legend_labels({"a": "runs/a/rule.py:policy", "b": "centre action"}) == {
        "a": "rule.py:policy", "b": "centre action"}
    long = legend_labels({"a": "x" * 50})["a"]
    assert len(long) == 32 and long.endswith("\u2026")
    # two policy files of one name: their ends tell them apart
    apart = legend_labels({"p": "runs/ppo/policy.py:act", "s": "runs/sac/policy.py:act"})
    assert apart == {"p": "runs/ppo/policy.py:act", "s": "runs/sac/policy.py:act"}
    deep = {m: "/a" * 30 + f"/{m}/policy.py:act" for m in ("ppo", "sac")}
    assert legend_labels(deep) == {m: "\u2026" + t[-31:] for m, t in deep.items()}  # "...a/a/ppo/policy.py:act"


@pytest.mark.filterwarnings("error::UserWarning")
def test_the_cv_chart_keeps_its_axes_with_many_long_labels(tmp_path):
    """Seven methods named by 60-character paths: the legend goes beside the axes, which
    keep their size (constrained layout once collapsed them, with a warning)."""
    from types import SimpleNamespace

    from spreadgym.agents.commands.compare import cv_bars

    order = [f"m{i}" for i in range(7)]
    titles = {m: "/".join(["folder"] * 8) + f"/policy_{m}.py:act" for m in order}
    rows = {m: [SimpleNamespace(context={"fertilizer": "pellet", "target_swath_m": w}, cv_percent=10.0 + i)
                for w in (12.0, 24.0)] for i, m in enumerate(order)}
    assert cv_bars(tmp_path / "cv.png", rows, order, titles).is_file()


def test_compare_without_references_says_so(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(bm, "shipped_references", lambda env_id: None)
    code, out, err = run_cli(capsys, ["compare", "--methods", "centre", "--granules", str(GRANULES),
                                      "--fertilizers", "pellet", "--swaths", "2.9", "--out", str(tmp_path)])
    assert code == 0, err
    assert "no normalised scores" in out and not (tmp_path / "profiles.png").exists()


@pytest.mark.parametrize("argv, message", [
    (["--model", "cmaes={callable}:policy"], "'cmaes' names a baseline method"),
    (["--model", "{broken}:policy"], "cannot import"),
])
def test_a_label_naming_a_baseline_and_a_broken_callable_are_one_line(callable_file, capsys, tmp_path, argv,
                                                                      message):
    broken = tmp_path / "broken.py"
    broken.write_text("def policy(obs:\n    return obs\n")  # a SyntaxError in the user's own file
    argv = [a.format(callable=callable_file, broken=broken) for a in argv]
    code, _, err = run_cli(capsys, ["compare", *argv, "--out", str(tmp_path / "out")])
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
