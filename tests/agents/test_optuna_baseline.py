"""The Optuna (TPE) baseline: budget, determinism, the same accounting and the same honest
re-scoring as random, grid and CMA-ES."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spreadgym.agents import baselines as bl
from spreadgym.agents import evaluation as ev
from spreadgym.cli.main import main

GRANULES = 100
TIMINGS = ("decide_s", "wall_s")  # wall-clock seconds: the only fields allowed to differ between runs


def sphere(x):
    return -float(np.sum((np.asarray(x) - 0.3) ** 2))


@pytest.mark.parametrize("budget", [1, 7, 13, 60])
def test_optuna_respects_the_budget_exactly(budget):
    calls = []

    def objective(x):
        calls.append(np.array(x))
        return sphere(x)

    result = bl.optuna_search(objective, 2, budget, seed=1)
    assert len(calls) == result.evaluations == len(result.history) == budget
    assert all(np.all(np.abs(x) <= 1.0) for x in calls)
    if budget >= 60:  # past the 10 random start-up trials TPE closes in on the optimum
        assert np.allclose(result.best_x, 0.3, atol=0.1)


def test_optuna_search_is_bit_for_bit_deterministic_and_quiet(capfd):
    import optuna

    verbosity = optuna.logging.get_verbosity()
    first = bl.optuna_search(sphere, 3, 30, seed=4)
    again = bl.optuna_search(sphere, 3, 30, seed=4)
    other = bl.optuna_search(sphere, 3, 30, seed=5)
    assert np.array_equal(np.array(first.points), np.array(again.points))
    assert first.history == again.history
    assert not np.array_equal(np.array(first.points), np.array(other.points))
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # no "Trial N finished" lines
    assert optuna.logging.get_verbosity() == verbosity  # the caller's setting is restored


def test_optuna_baseline_runs_and_beats_the_published_settings():
    env = ev.make_env(ev.DESIGN_ENV, {"granules": 600})
    ctx = ev.evaluation_set(["compound-10-16-10"], [5.0])[0]
    published = bl.run_baseline(env, ctx, "published")[0]
    before = env.simulations
    row = bl.run_baseline(env, ctx, "optuna", budget=16, seed=0)[0]
    assert env.simulations - before == row.simulations == 17  # 16 to search + 1 to score
    assert row.search_simulations == 16 and row.method == "optuna"
    assert row.reward > published.reward
    assert row.cv_percent < published.cv_percent


def test_same_seed_same_rows_bit_for_bit():
    ctx = ev.evaluation_set(["pellet"], [3.0])[0]
    runs = []
    for _ in range(2):  # a fresh env each time: nothing carried over between runs
        env = ev.make_env(ev.DESIGN_ENV, {"granules": GRANULES})
        rows = bl.run_baseline(env, ctx, "optuna", budget=20, seed=3, episodes=2)
        runs.append([{k: v for k, v in r.as_dict().items() if k not in TIMINGS} for r in rows])
    assert runs[0] == runs[1]
    env = ev.make_env(ev.DESIGN_ENV, {"granules": GRANULES})
    other = bl.run_baseline(env, ctx, "optuna", budget=20, seed=4)[0]
    assert other.action != runs[0][0]["action"]


@pytest.mark.parametrize("budget", [3, 6, 16, 40])
def test_accounting_equals_the_other_searches(budget, monkeypatch):
    """Optuna spends the budget as random search and CMA-ES do: the same share searching, the
    rest re-scoring, every simulation counted, the same row fields."""
    env = ev.make_env(ev.DESIGN_ENV, {"granules": GRANULES})
    ctx = ev.evaluation_set(["mixture-17-21-17"], [4.0])[0]
    searched = {}
    for method in ("random", "cmaes", "optuna"):
        search = bl.SEARCHES[method]

        def counted(*args, _search=search, _method=method, **kwargs):
            result = _search(*args, **kwargs)
            searched[_method] = result.evaluations
            return result

        monkeypatch.setitem(bl.SEARCHES, method, counted)
        before = env.simulations
        rows = bl.run_baseline(env, ctx, method, budget, seed=0)
        assert env.simulations - before == budget + 1, method  # search + re-scores, then 1 to score
        assert (rows[0].search_simulations, rows[0].scoring_simulations) == (budget, 1), method
        assert {"search_best_cv_percent", "search_best_cv_se_percent", "search_rescores"} <= set(rows[0].extra)
    assert searched["optuna"] == searched["random"] == searched["cmaes"] == bl.split_budget(budget)[0]



def test_compare_runs_optuna_beside_the_other_searches(capsys, tmp_path):
    budget = 6
    code = main(["compare", "--budget", str(budget), "--granules", str(GRANULES), "--fertilizers", "pellet",
                 "--swaths", "2.9", "--methods", "cmaes", "optuna", "--json", "--out", str(tmp_path)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    table = {row["key"]: row for row in json.loads(captured.out)["table"]}
    assert list(table) == ["cmaes", "optuna"]
    assert table["optuna"]["method"] == "Optuna TPE"
    for key in ("search_simulations", "simulations"):
        assert table["optuna"][key] == table["cmaes"][key]
    assert table["optuna"]["search_simulations"] == budget and table["optuna"]["simulations"] == budget + 1
    assert "Optuna TPE" in (tmp_path / "compare.md").read_text()
