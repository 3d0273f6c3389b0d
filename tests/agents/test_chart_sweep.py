"""The row sweep (agents/chart/sweep.py): the dynamic programme against a hand-made tie set
with a known steadiest path and against brute force, a row without ties keeping its best,
and a chart whose sweep moves a cell verifying the moved cell as a fresh verification
would, deterministically and on resume."""

import itertools
import json

import numpy as np
import pytest

from spreadgym.agents.chart import make_spec, run_chart
from spreadgym.agents.chart.quality import chart_quality
from spreadgym.agents.chart.search import verified_record
from spreadgym.agents.chart.store import record_problem
from spreadgym.agents.chart.sweep import (
    Point,
    points_of,
    repair,
    row_points,
    row_turns,
    speed_steps,
    steadiest,
    step,
    swept_record,
    turning,
)

FERTILIZER = "compound-10-16-10"


def point(rpm, pitch, excess=0.0):
    """A point whose unit settings are its dial values scaled into the box."""
    return Point(((rpm - 650.0) / 450.0, pitch / 30.0), {"rpm": float(rpm), "pitch_deg": float(pitch)}, excess)


def movement(row, picks):
    return sum(step(row[k - 1][picks[k - 1]], row[k][picks[k]]) for k in range(1, len(row)))


def brute_force(row, preference="lowest-rpm"):
    """The lexicographic minimum (reversals, disc speeds in RPM_STEP steps with the lowest-rpm preference,
    movement, excess, indices) over every path."""
    def key(path):
        speed = sum(speed_steps(row[k][i].values, preference) for k, i in enumerate(path))
        return (row_turns(row, path), speed, movement(row, path), sum(row[k][i].excess for k, i in enumerate(path)),
                path)

    return list(min(itertools.product(*[range(len(cell)) for cell in row]), key=key))


def nearest_neighbour_chain(row):
    """The greedy chain of the search: the best first, then the tied point nearest the previous pick."""
    picks = [0]
    for cell in row[1:]:
        picks.append(min(range(len(cell)), key=lambda i: step(row[len(picks) - 1][picks[-1]], cell[i])))
    return picks


def test_the_sweep_undoes_a_turn_the_greedy_chain_takes():
    # 3 m: one point. 3.5 m: the best at 820 rpm, a tied point at 700. 4 m: only 700 rpm, 4.5 m: only 800.
    # The chain takes 3.5 m's point nearest 3 m (820), then must fall to 700 and climb to 800: a turn at
    # 4 m of 100 rpm (14 %) that the chain cannot undo. Through the tied 700 rpm the row falls and climbs
    # once, with no turn (a flat step is no turn).
    row = [[point(800, 10)],
           [point(820, 10), point(700, 10, 0.3)],
           [point(700, 10)],
           [point(800, 10)]]
    greedy = nearest_neighbour_chain(row)
    assert greedy == [0, 0, 0, 0] and row_turns(row, greedy) == 1
    picks = steadiest(row)
    assert picks == [0, 1, 0, 0] and row_turns(row, picks) == 0
    rows = [{"fertilizer": "f", "width_m": 3 + k / 2, "cv_percent": 1.0, "cv_p90_percent": 1.0, **row[k][i].values}
            for k, i in enumerate(picks)]
    assert chart_quality({"rows": rows})["rpm_reversals"] == 0  # what the sweep minimises is what quality counts
    greedy_rows = [{**r, **row[k][i].values} for k, (r, i) in enumerate(zip(rows, greedy))]
    assert chart_quality({"rows": greedy_rows})["rpm_reversals"] == 1


def test_pitch_turns_count_in_degrees_and_small_turns_do_not_count():
    # a 2-degree wiggle is under the target's 3 degrees: the sweep keeps the best (least movement says so too)
    row = [[point(800, 10)], [point(800, 12), point(800, 10, 0.5)], [point(800, 10)]]
    assert row_turns(row, [0, 0, 0]) == 0
    assert steadiest(row) == [0, 1, 0]  # the flat path moves less: tied points go to the steadier row
    # a 4-degree turn counts; the tied 5-degree point removes it
    row = [[point(800, 10)], [point(800, 14), point(800, 5, 0.5)], [point(800, 0)]]
    assert row_turns(row, [0, 0, 0]) == 1 and steadiest(row) == [0, 1, 0]
    # rpm: 5 % of the turning width's rpm (1000 -> 1040 -> 1000 is 3.8 %: not a reversal; 1000 -> 1060 is)
    assert row_turns([[point(1000, 0)], [point(1040, 0)], [point(1000, 0)]], [0, 0, 0]) == 0
    assert row_turns([[point(1000, 0)], [point(1060, 0)], [point(1000, 0)]], [0, 0, 0]) == 1


def test_a_row_without_ties_keeps_its_best_and_a_lone_cell_its_best():
    row = [[point(600, 5)], [point(1000, -10)], [point(500, 20)], [point(1100, 0)]]  # zigzag, no choice
    assert steadiest(row) == [0, 0, 0, 0]
    assert steadiest([[point(900, 3, 0.4), point(500, 0, 0.0), point(700, 1, 0.2)]]) == [1]
    with pytest.raises(ValueError):
        steadiest([[point(800, 0)], []])


@pytest.mark.parametrize("preference", ["lowest-rpm", "nearest"])
@pytest.mark.parametrize("seed", range(12))
def test_the_dynamic_programme_finds_the_brute_force_optimum(seed, preference):
    rng = np.random.default_rng(seed)
    # rpm on a 20 rpm grid, so that disc speeds tie often and the later terms decide too
    row = [[point(20 * rng.integers(20, 56), rng.uniform(-20, 20), 0.0 if i == 0 else rng.uniform(0, 1))
            for i in range(rng.integers(1, 4))] for _ in range(rng.integers(2, 7))]
    picks = steadiest(row, preference)
    assert picks == brute_force(row, preference)
    assert steadiest(row, preference) == picks  # the same tie sets, the same picks


SMALL = dict(budget=24, granules=64, search_model="analytic", verify_runs=2,
             variability={"draws": 4, "verify_draws": 4})
OLD_RULE = dict(steady_tolerance_pp=0.0, tie_preference="nearest")  # the rule before issue 45 (two SE, nearest)


@pytest.fixture(scope="module")
def chart(tmp_path_factory):
    """Two widths whose sweep moves the 3 m cell off its search pick (seed 1, the rule before issue 45: the 3 m
    cell ties 3 points, the 3.5 m cell 1; the tied point nearest the 3.5 m settings makes the row's step
    smaller)."""
    out = tmp_path_factory.mktemp("chart")
    spec = make_spec("paper", FERTILIZER, "3,3.5", seed=1, **SMALL, **OLD_RULE)[0]
    return spec, out, run_chart(spec, out, engine="local", progress=False)


def _records(out, spec):
    return {c.key: json.loads((out / "cells" / f"{c.key}.json").read_text(encoding="utf-8")) for c in spec.cells}


def _figures(record):
    return {k: record["row"][k] for k in ("rpm", "pitch_deg", "cv_percent", "cv_standard_error_percent",
                                          "cv_p90_percent", "cv_p90_standard_error_percent", "effective_swath_m")}


def test_every_cell_records_its_tie_set_and_what_the_sweep_did(chart):
    spec, out, result = chart
    records = _records(out, spec)
    for c, cell in zip(spec.cells, result.payload["cells"]):
        record = records[c.key]
        tie, block = cell["tie_set"], cell["sweep"]
        assert record["detail"]["sweep"] == block and record_problem(spec, c, record) is None
        assert cell["search_unit_settings"] == tie["points"][tie["search_pick"]]["unit_settings"]
        assert cell["unit_settings"] == tie["points"][block["pick"]]["unit_settings"]
        assert block["moved"] == (block["pick"] != tie["search_pick"])
        assert len(tie["points"]) == cell["ties"] >= 1
        best = tie["points"][tie["best"]]["score_percent"]
        assert all(p["score_percent"] <= best + 2.0 * tie["best_standard_error_percent"] + 1e-12 for p in tie["points"])
    moved = [cell["sweep"]["moved"] for cell in result.payload["cells"]]
    assert moved == [True, False]


def test_a_moved_cell_is_verified_at_its_pick_and_the_sweep_is_idempotent(chart):
    """The moved cell's row is a fresh verification of its pick on the cell's own seeds; the search pick's
    verified figures are kept beside it; sweeping again (a resumed chart) changes nothing."""
    from spreadgym.agents.chart.runner import sweep_rows
    from spreadgym.agents.chart.store import ChartStore

    spec, out, result = chart
    records = _records(out, spec)
    cell = spec.cells[0]
    moved = records[cell.key]
    tie, block = moved["detail"]["tie_set"], moved["detail"]["sweep"]
    pick, search_pick = tie["points"][block["pick"]], tie["points"][tie["search_pick"]]
    fresh = verified_record(spec, cell, np.asarray(pick["unit_settings"]), 0.0, None, 0, {}, 0.0)
    assert _figures(moved) == _figures(fresh)
    assert moved["row"]["cv_search_percent"] == pick["cv_search_percent"]
    before = verified_record(spec, cell, np.asarray(search_pick["unit_settings"]), 0.0, None, 0, {}, 0.0)
    kept = block["search_pick_verified"]
    assert {k: kept[k] for k in ("cv_percent", "cv_p90_percent", "effective_swath_m")} == \
        {k: before["row"][k] for k in ("cv_percent", "cv_p90_percent", "effective_swath_m")}
    assert kept["cv_search_percent"] == search_pick["cv_search_percent"]
    # the search's candidates, then two verifications (the search pick's and the pick's)
    assert moved["row"]["simulations"] == moved["detail"]["search_evaluations"] * 4 + 2 * spec.verify_simulations
    again = json.loads(json.dumps(records))
    sweep_rows(spec, ChartStore(out, spec), records)
    assert json.loads(json.dumps(records)) == again
    wrong = json.loads(json.dumps(moved))
    wrong["detail"]["sweep"]["pick"] = tie["search_pick"]
    assert record_problem(spec, cell, wrong) == "its settings are not its pick's"
    # moved again (another sweep of other tie sets): still the search's, the search pick's and this pick's runs
    (third,) = set(range(len(tie["points"]))) - {block["pick"], tie["search_pick"]}
    again = swept_record(spec, cell, moved, third, 0, 0)
    assert again["detail"]["unit_settings"] == tie["points"][third]["unit_settings"]
    assert again["row"]["simulations"] == moved["row"]["simulations"]
    assert again["detail"]["sweep"]["search_pick_verified"] == kept and record_problem(spec, cell, again) is None


def test_the_chain_follows_the_search_picks_not_the_swept_ones(chart, tmp_path):
    """The 3.5 m cell recomputed after the 3 m cell was swept starts from the 3 m cell's search pick (not
    from where the sweep moved it): the same chart as the fresh run."""
    import shutil

    spec, out, result = chart
    folder = tmp_path / "r"
    shutil.copytree(out, folder)
    (folder / "cells" / f"{spec.cells[1].key}.json").unlink()
    again = run_chart(spec, folder, engine="local", progress=False)
    assert again.computed == [spec.cells[1].key]

    def without_wall(rows):
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]

    assert without_wall(again.payload["rows"]) == without_wall(result.payload["rows"])
    assert [c["sweep"] for c in again.payload["cells"]] == [c["sweep"] for c in result.payload["cells"]]


def test_the_sweep_effect_reads_the_chart_before_the_sweep_back(chart):
    from spreadgym.agents.chart.quality import search_pick_rows, sweep_effect

    spec, out, result = chart
    payload = result.payload
    before = search_pick_rows(payload)
    moved_cell, kept_cell = payload["cells"]
    space = spec.space(spec.cell_scene(spec.cells[0]))
    assert {k: before[0][k] for k in space.names} == space.values(moved_cell["search_unit_settings"])
    assert {k: before[0][k] for k in space.names} != {k: payload["rows"][0][k] for k in space.names}
    assert before[0]["cv_p90_percent"] == moved_cell["sweep"]["search_pick_verified"]["cv_p90_percent"]
    assert before[1] == payload["rows"][1]  # a cell the sweep kept reads the same
    effect = sweep_effect(payload)
    assert effect["moved"] == [(FERTILIZER, 3.0)]
    step = payload["rows"][0]["cv_p90_percent"] - before[0]["cv_p90_percent"]
    assert effect["cv_p90_percent_cost"]["mean"] == pytest.approx(step / 2)
    assert effect["cv_p90_percent_cost_moved"]["mean"] == pytest.approx(step)


def test_the_same_spec_gives_the_same_swept_chart_on_ray(chart, tmp_path):
    """The sweep's re-verification as a Ray task (one worker) gives the rows of the in-process chart."""
    spec, _, result = chart
    on_ray = run_chart(spec, tmp_path / "ray", engine="ray", workers=1, progress=False)

    def without_wall(rows):
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]

    assert without_wall(on_ray.payload["rows"]) == without_wall(result.payload["rows"])
    assert [c["sweep"] for c in on_ray.payload["cells"]] == [c["sweep"] for c in result.payload["cells"]]
    assert on_ray.payload["cells"][0]["sweep"]["moved"]


class _Space:
    """The settings space of `point`: unit settings back to rpm and pitch."""

    @staticmethod
    def values(unit):
        return {"rpm": 650.0 + 450.0 * unit[0], "pitch_deg": 30.0 * unit[1]}


def tie(*points, se=0.1):
    """A tie set of `points` (rpm, pitch, score), the first the best and the search pick."""
    return {"points": [{"unit_settings": list(point(rpm, pitch).unit), "score_percent": score,
                        "cv_search_percent": score, "cv_search_standard_error_percent": se}
                       for rpm, pitch, score in points], "best": 0, "search_pick": 0,
            "best_standard_error_percent": se}


def fake_score(tied):
    """A repair scorer: a candidate is tied when `tied(cell, rpm, pitch)`; it records what it was asked."""
    asked = []

    def score(jobs):
        asked.append(jobs)
        out = {}
        for k, wanted in jobs.items():
            out[k] = []
            for u, free in wanted:
                values = _Space.values(u)
                start = {} if free is None else {"start_unit_settings": u, "free_axes": free, "slice_evaluations": 13}
                out[k].append({"unit_settings": u, "score_percent": 1.0, "cv_search_percent": 1.0,
                               "cv_search_standard_error_percent": 0.1,
                               "tied": bool(tied(k, values["rpm"], values["pitch_deg"])), **start})
        return out

    return score, asked


def _picks(tie_sets, tried):
    row = row_points([_Space] * len(tie_sets), [{**t, "points": points_of(t, c)} for t, c in zip(tie_sets, tried)])
    picks = steadiest(row)
    return row, picks


def test_the_repair_removes_a_reversal_that_one_point_tie_sets_force():
    # 4 m ties one point at 1000 rpm between 800 and 850 (a 15 % turn the sweep cannot avoid); scored at its
    # neighbours' points and their interpolation, the two at or under 900 rpm tie: the row no longer turns
    widths = [3.0, 3.5, 4.0, 4.5]
    tie_sets = [tie((780, 10, 1.0)), tie((800, 10, 1.0)), tie((1000, 10, 1.0)), tie((850, 10, 1.0))]
    row, picks = _picks(tie_sets, [[]] * 4)
    assert row_turns(row, picks) == 1 and turning(row, picks) == [2]
    score, asked = fake_score(lambda k, rpm, pitch: k == 2 and rpm <= 900)
    tried = repair([_Space] * 4, widths, tie_sets, score)
    assert [c["source"] for c in tried[2]] == ["narrower", "wider", "between", "slice"]
    assert [round(_Space.values(c["unit_settings"])["rpm"], 6) for c in tried[2]] == [800, 850, 825, 825]
    assert asked[0][2][3][1] == [1]  # the steady slice keeps the turning rpm and searches the pitch
    assert [c["source"] for c in tried[1]] == ["wider"] and [c["source"] for c in tried[3]] == ["narrower"]
    assert tried[0] == [] and len(asked) == 1  # one pass: the row is steady after it
    row, picks = _picks(tie_sets, tried)
    assert row_turns(row, picks) == 0 and picks[2] >= 1  # 4 m moved to a tied candidate


def test_the_repair_scores_nothing_on_a_steady_row_or_without_rounds():
    score, asked = fake_score(lambda *a: True)
    steady = [tie((800, 10, 1.0)), tie((900, 12, 1.0), (700, 0, 1.1)), tie((1000, 14, 1.0))]
    assert repair([_Space] * 3, [3.0, 4.0, 5.0], steady, score) == [[], [], []] and asked == []
    unscored = [tie((800, 10, 1.0), se=None), tie((1000, 10, 1.0), se=None), tie((850, 10, 1.0), se=None)]
    assert repair([_Space] * 3, [3.0, 4.0, 5.0], unscored, score) == [[], [], []] and asked == []


def test_the_repair_stops_when_a_pass_does_not_help():
    tie_sets = [tie((800, 10, 1.0)), tie((1000, 10, 1.0)), tie((850, 10, 1.0))]
    score, asked = fake_score(lambda *a: False)  # nothing ties: one pass, then stop
    tried = repair([_Space] * 3, [3.0, 4.0, 5.0], tie_sets, score)
    assert len(asked) == 1 and len(tried[1]) == 4 and not any(c["tied"] for cells in tried for c in cells)


@pytest.fixture(scope="module")
def repaired(tmp_path_factory):
    """A 7-width chart (seed 2) whose sweep leaves a reversal when every turn counts (the targets' sizes set to
    zero), with every repair candidate declared tied (the real scores, the tie flag forced): the repair moves
    a cell off its tie set."""
    import spreadgym.agents.chart.quality as quality
    import spreadgym.agents.chart.runner as runner

    real = runner.score_candidates

    def all_tied(*args):
        points, wall = real(*args)
        return [{**p, "tied": True} for p in points], wall

    out = tmp_path_factory.mktemp("repaired")
    spec = make_spec("paper", FERTILIZER, "3:6:0.5", seed=2, **{**SMALL, "verify_model": "analytic"}, **OLD_RULE)[0]
    patch = pytest.MonkeyPatch()
    patch.setattr(runner, "score_candidates", all_tied)
    patch.setattr(quality, "RPM_REVERSAL", 0.0)
    patch.setattr(quality, "PITCH_REVERSAL_DEG", 0.0)
    try:
        result = run_chart(spec, out, engine="local", progress=False)
    finally:
        patch.undo()
    return spec, out, result


def test_a_repaired_cell_is_verified_on_its_own_seeds_and_resumes_unchanged(repaired):
    from spreadgym.agents.chart.runner import sweep_rows
    from spreadgym.agents.chart.store import ChartStore

    spec, out, result = repaired
    cells = result.payload["cells"]
    blocks = [c["sweep"] for c in cells]
    assert blocks[0]["row_reversals_search"] == 1 and blocks[0]["row_reversals_swept"] == 0
    assert any(b["repair"]["candidates"] for b in blocks)
    from spreadgym.agents.chart.quality import sweep_effect

    effect = sweep_effect(result.payload)["repair"]
    assert effect["tied"] == effect["candidates"] == sum(len(b["repair"]["candidates"]) for b in blocks)
    assert effect["simulations"] == sum(b["repair"]["simulations"] for b in blocks)
    moved = [k for k, c in enumerate(cells) if c["sweep"]["pick"] >= len(c["tie_set"]["points"])]
    assert moved, "the repair moved no cell to a candidate"
    records = _records(out, spec)
    for k in moved:
        cell, record = spec.cells[k], records[spec.cells[k].key]
        candidate = points_of(cells[k]["tie_set"], cells[k]["sweep"]["repair"]["candidates"])[cells[k]["sweep"]["pick"]]
        fresh = verified_record(spec, cell, np.asarray(candidate["unit_settings"]), 0.0, None, 0, {}, 0.0)
        assert _figures(record) == _figures(fresh) and record_problem(spec, cell, record) is None
        candidates = cells[k]["sweep"]["repair"]["candidates"]
        repair_runs = sum(cells[k]["rescores"] + c.get("slice_evaluations", 0) for c in candidates) * 4
        assert repair_runs == cells[k]["sweep"]["repair"]["simulations"] > 0
        runs = cells[k]["search_evaluations"] * 4 + repair_runs + 2 * spec.verify_simulations
        assert record["row"]["simulations"] == runs
        assert record["row"]["simulations"] <= spec.max_simulations
    # resumed (the real scorer now): every candidate is found in the records, nothing is scored or changes
    import spreadgym.agents.chart.quality as quality
    import spreadgym.agents.chart.runner as runner

    again = json.loads(json.dumps(records))
    patch = pytest.MonkeyPatch()
    patch.setattr(runner, "score_candidates", lambda *a: pytest.fail("a recorded candidate was scored again"))
    patch.setattr(quality, "RPM_REVERSAL", 0.0)
    patch.setattr(quality, "PITCH_REVERSAL_DEG", 0.0)
    try:
        sweep_rows(spec, ChartStore(out, spec), records)
    finally:
        patch.undo()
    assert json.loads(json.dumps(records)) == again


def test_the_repair_scores_a_candidate_on_the_cells_own_rounds(repaired):
    """A candidate's score is its re-score rounds' mean, on the tie set's draws: the tie set's own points score
    what the search recorded for them."""
    from spreadgym.agents.chart.search import score_candidates

    spec, out, result = repaired
    cell, detail = spec.cells[1], result.payload["cells"][1]
    points, _ = score_candidates(spec, cell, detail, [(p["unit_settings"], None) for p in detail["tie_set"]["points"]])
    assert [p["score_percent"] for p in points] == [p["score_percent"] for p in detail["tie_set"]["points"]]
    assert [p["cv_search_percent"] for p in points] == [p["cv_search_percent"] for p in detail["tie_set"]["points"]]
    assert all(p["tied"] for p in points)


def test_the_repair_gives_the_same_chart_on_ray_as_in_process(tmp_path, monkeypatch):
    """The repair's candidates scored as Ray tasks (one worker) give the in-process chart: candidates, ties,
    picks and rows (every turn counts, so that the row has one to repair)."""
    import spreadgym.agents.chart.quality as quality

    monkeypatch.setattr(quality, "RPM_REVERSAL", 0.0)
    monkeypatch.setattr(quality, "PITCH_REVERSAL_DEG", 0.0)
    spec = make_spec("paper", FERTILIZER, "3:6:0.5", seed=2, **{**SMALL, "verify_model": "analytic"}, **OLD_RULE)[0]
    here = run_chart(spec, tmp_path / "here", engine="local", progress=False)
    on_ray = run_chart(spec, tmp_path / "ray", engine="ray", workers=1, progress=False)

    def without_wall(rows):
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]

    assert any(c["sweep"]["repair"]["candidates"] for c in here.payload["cells"])
    assert without_wall(on_ray.payload["rows"]) == without_wall(here.payload["rows"])
    assert [c["sweep"] for c in on_ray.payload["cells"]] == [c["sweep"] for c in here.payload["cells"]]


def scores_of(means, se=0.1, tolerance_pp=0.0):
    """A repair scorer with known mean scores (`means(cell, rpm, pitch)`), tied by the chart's test
    (`search.tie_limit`: the best of the hand-made tie sets scores 1.0 with standard error `se`)."""
    from spreadgym.agents.chart.search import tie_limit

    def score(jobs):
        out = {}
        for k, wanted in jobs.items():
            out[k] = []
            for u, free in wanted:
                values = _Space.values(u)
                mean = means(k, values["rpm"], values["pitch_deg"])
                out[k].append({"unit_settings": u, "score_percent": mean, "cv_search_percent": mean,
                               "cv_search_standard_error_percent": se, "tied": mean <= tie_limit(1.0, se, tolerance_pp),
                               **({} if free is None else {"start_unit_settings": u, "free_axes": free,
                                                          "slice_evaluations": 13})})
        return out

    return score


def test_a_steady_tolerance_ties_a_candidate_just_outside_two_standard_errors():
    # 4 m ties one point at 1000 rpm between 800 and 850 (a turn); every candidate of 4 m scores 1.25, just
    # over the two standard errors (1.0 + 2 x 0.1): refused at tolerance 0, the reversal stays; a tolerance of
    # 0.06 pp covers it: the candidates tie and the row no longer turns
    widths = [3.0, 3.5, 4.0, 4.5]
    tie_sets = [tie((780, 10, 1.0)), tie((800, 10, 1.0)), tie((1000, 10, 1.0)), tie((850, 10, 1.0))]

    def means(k, rpm, pitch):
        return 1.25 if k == 2 else 5.0  # the neighbours at 4 m's point: far from their best

    strict = repair([_Space] * 4, widths, tie_sets, scores_of(means))
    assert strict[2] and not any(c["tied"] for cells in strict for c in cells)
    row, picks = _picks(tie_sets, strict)
    assert row_turns(row, picks) == 1
    wide = repair([_Space] * 4, widths, tie_sets, scores_of(means, tolerance_pp=0.06))
    assert [c["unit_settings"] for c in wide[2]] == [c["unit_settings"] for c in strict[2]]
    assert all(c["tied"] for c in wide[2]) and not any(c["tied"] for k in (1, 3) for c in wide[k])
    row, picks = _picks(tie_sets, wide)
    assert row_turns(row, picks) == 0 and picks[2] >= 1
    assert not any(c["tied"] for c in repair([_Space] * 4, widths, tie_sets, scores_of(means, tolerance_pp=0.04))[2])


def test_the_default_tolerance_is_the_two_standard_error_rule_to_the_bit():
    from spreadgym.agents.chart.search import TIE_STANDARD_ERRORS, tie_limit
    from spreadgym.agents.chart.sweep import REPAIR_RULE, RULE, repair_rule, rule

    rng = np.random.default_rng(0)
    for best, se in rng.uniform(0, 20, size=(200, 2)):
        assert tie_limit(best, se) == best + TIE_STANDARD_ERRORS * se == tie_limit(np.float64(best), se, 0.0)
    assert rule() == rule(0.0) == RULE and repair_rule(0.0) == REPAIR_RULE
    assert "plus a steady tolerance of 1.5 pp" in rule(1.5) and "plus a steady tolerance of 1.5 pp" in repair_rule(1.5)


def test_a_steady_tolerance_widens_a_cells_tie_set_and_its_candidates_tie(chart):
    """The spec's tolerance reaches the search's tie set (every re-scored point within it ties) and the repair's
    scoring (a candidate's `tied`); at 0 the cell is the chart's; the records and the rules say it."""
    from dataclasses import replace

    from spreadgym.agents.chart.search import run_cell, score_candidates
    from spreadgym.agents.chart.sweep import rule

    spec, out, _ = chart
    records = _records(out, spec)
    cell, previous = spec.cells[1], records[spec.cells[0].key]  # 3.5 m ties one point at 0
    strict = records[cell.key]["detail"]
    again = run_cell(spec, cell, previous)["detail"]
    assert [again[k] for k in ("tie_set", "ties", "search_unit_settings")] == \
        [strict[k] for k in ("tie_set", "ties", "search_unit_settings")]
    wide = run_cell(replace(spec, steady_tolerance_pp=100.0), cell, previous)["detail"]
    assert wide["tie_set"]["best_standard_error_percent"] == strict["tie_set"]["best_standard_error_percent"]
    assert wide["ties"] > strict["ties"] and len(wide["tie_set"]["points"]) == wide["ties"]
    best = wide["tie_set"]["points"][wide["tie_set"]["best"]]
    assert best == strict["tie_set"]["points"][strict["tie_set"]["best"]]
    # a candidate just outside two standard errors: tied only with a tolerance that covers its excess
    far = [u / 2 for u in best["unit_settings"]]
    (scored,), _ = score_candidates(spec, cell, strict, [(far, None)])
    limit = best["score_percent"] + 2 * strict["tie_set"]["best_standard_error_percent"]
    gap = scored["score_percent"] - limit
    assert gap > 0 and not scored["tied"]
    (loose,), _ = score_candidates(replace(spec, steady_tolerance_pp=gap * 1.01 + 1e-9), cell, strict, [(far, None)])
    assert loose["tied"] and loose["score_percent"] == scored["score_percent"]
    assert rule(1.0) != rule(0.0)


def test_a_chart_with_a_steady_tolerance_records_it_and_resumes_only_with_it(tmp_path):
    from spreadgym.agents.chart.outputs import markdown
    from spreadgym.errors import SpreadgymError

    spec = make_spec("paper", FERTILIZER, "3,3.5", seed=1, steady_tolerance_pp=0.5, tie_preference="nearest",
                     **SMALL)[0]
    result = run_chart(spec, tmp_path, engine="local", progress=False)
    assert result.payload["spec"]["steady_tolerance_pp"] == 0.5
    assert json.loads((tmp_path / "manifest.json").read_text())["steady_tolerance_pp"] == 0.5
    assert all("0.5 pp" in c["sweep"]["rule"] and "0.5 pp" in c["sweep"]["repair"]["rule"]
               for c in result.payload["cells"])
    assert "plus 0.5 pp (--steady-tolerance-pp)" in markdown(spec, result.payload)
    assert "plus 0.5 pp (--steady-tolerance-pp)" in (tmp_path / "chart.html").read_text(encoding="utf-8")
    again = run_chart(spec, tmp_path, engine="local", progress=False)
    assert again.computed == [] and again.payload["rows"] == result.payload["rows"]
    old = make_spec("paper", FERTILIZER, "3,3.5", seed=1, **SMALL, **OLD_RULE)[0]
    assert "steady_tolerance_pp" not in old.manifest() and "tie_preference" not in old.manifest()
    with pytest.raises(SpreadgymError, match="steady_tolerance_pp 0.5 -> 0.0"):
        run_chart(old, tmp_path, engine="local", progress=False)
    default = make_spec("paper", FERTILIZER, "3,3.5", seed=1, **SMALL)[0]
    assert default.manifest()["steady_tolerance_pp"] == 2.0 and default.manifest()["tie_preference"] == "lowest-rpm"
    with pytest.raises(SpreadgymError, match="steady_tolerance_pp 0.5 -> 2.0"):
        run_chart(default, tmp_path, engine="local", progress=False)


def test_among_tied_points_the_sweep_prefers_the_lowest_disc_speed_then_the_smallest_change():
    # every cell ties a fast point near its neighbours and a gentler one: the rule takes the gentler row even
    # though it moves more; the old rule ("nearest") keeps the row that moves least
    row = [[point(1100, 10), point(700, 20, 0.5)],
           [point(1100, 11), point(720, 22, 0.5)],
           [point(1100, 12), point(740, 24, 0.5)]]
    assert steadiest(row) == [1, 1, 1]
    assert steadiest(row, "nearest") == [0, 0, 0]
    # disc speeds within one RPM_STEP are one speed: the smallest change from the neighbours decides
    row = [[point(800, 10)], [point(804, 25), point(801, 11, 0.3)], [point(800, 12)]]
    assert speed_steps(row[1][0].values, "lowest-rpm") == speed_steps(row[1][1].values, "lowest-rpm")
    assert steadiest(row) == [0, 1, 0]
    # steady rows come first: a lower speed that turns the row is not taken
    row = [[point(900, 10)], [point(1000, 10), point(600, 10, 0.1)], [point(1100, 10)]]
    assert steadiest(row) == [0, 0, 0] and row_turns(row, [0, 1, 0]) == 1


def test_the_chains_pick_is_the_tied_point_with_the_lowest_disc_speed(chart):
    """A cell's search pick (where the next width starts) under the default preference: the lowest disc speed
    among its tied points, then the nearest to the neighbour."""
    from dataclasses import replace

    from spreadgym.agents.chart.search import run_cell

    spec, out, _ = chart
    cell = spec.cells[0]
    wide = run_cell(replace(spec, steady_tolerance_pp=100.0, tie_preference="lowest-rpm"), cell, None)["detail"]
    space = spec.space(spec.cell_scene(cell))
    speeds = [space.values(p["unit_settings"])["rpm"] for p in wide["tie_set"]["points"]]
    assert len(speeds) >= 2 and len(set(speeds)) == len(speeds)
    assert speeds[wide["tie_set"]["search_pick"]] == min(speeds)
    assert wide["search_unit_settings"] == wide["tie_set"]["points"][wide["tie_set"]["search_pick"]]["unit_settings"]


def _record(fertilizer, width, rpm, pitch, scored):
    """A finished cell's record for `reversal_prices`: its point (rpm, pitch) and the other scored points
    (rpm, pitch, score excess over the best, tied), in the box of `point`."""
    unit = list(point(rpm, pitch).unit)
    points = [{"unit_settings": unit, "score_percent": 1.0, "cv_search_percent": 1.0,
               "cv_search_standard_error_percent": 0.1}]
    candidates = [{"unit_settings": list(point(r, p).unit), "score_percent": 1.0 + e, "cv_search_percent": 1.0 + e,
                   "cv_search_standard_error_percent": 0.1, "tied": t} for r, p, e, t in scored]
    return {"row": {"fertilizer": fertilizer, "width_m": width, "rpm": rpm, "pitch_deg": pitch},
            "detail": {"unit_settings": unit, "tie_set": {"points": points, "best": 0, "search_pick": 0,
                                                           "best_standard_error_percent": 0.1},
                       "sweep": {"repair": {"candidates": candidates}}}}


def test_a_remaining_reversal_is_priced_by_the_cheapest_scored_point_that_removes_it():
    from types import SimpleNamespace

    from spreadgym.agents.chart.sweep import reversal_prices

    spec = SimpleNamespace(fertilizers=("f",), space=lambda scene: _Space, cell_scene=lambda cell: None)
    records = [_record("f", 3.0, 800, 10, []),
               _record("f", 3.5, 1000, 10, [(820, 10, 3.4, False), (860, 10, 2.6, False), (1200, 10, 0.1, True)]),
               _record("f", 4.0, 850, 10, [(1000, 10, 4.0, False)]),
               _record("f", 4.5, 800, 10, [])]
    (found,) = reversal_prices(spec, records)
    # 3.5 m turns (800 -> 1000 -> 850: 15 %); 860 rpm there removes it for +2.6 pp, 820 for +3.4, 4 m at 1000 for +4
    assert found["width_m"] == 3.5 and found["settings"] == ["rpm"]
    assert found["values"] == [[800.0, 1000.0, 850.0]]
    assert found["price_pp"] == pytest.approx(2.6) and found["priced_at_width_m"] == 3.5
    # with nothing scored that removes it, the reversal is flagged without a price
    bare = [_record("f", 3.0, 800, 10, []), _record("f", 3.5, 1000, 10, []), _record("f", 4.0, 850, 10, [])]
    (unpriced,) = reversal_prices(spec, bare)
    assert unpriced["price_pp"] is None
    steady = [_record("f", 3.0, 800, 10, []), _record("f", 3.5, 820, 10, []), _record("f", 4.0, 850, 10, [])]
    assert reversal_prices(spec, steady) == []
