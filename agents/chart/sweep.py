"""The row sweep: once every cell of a fertilizer's row has its tie set, pick one point per
cell so that the row is as steady as the ties allow.

A cell's tie set (`search.search`) holds the re-scored points whose mean score is within
`TIE_STANDARD_ERRORS` standard errors of the best's, plus the spec's `steady_tolerance_pp`
percentage points of the objective (`--steady-tolerance-pp`, default 0; `search.tie_limit`) (the best among them; with
`policy+search` the policy's proposal and the narrower neighbour's settings are re-scored
too; with `policy`, or a budget too small to re-score, the set is the cell's one point).
Among all paths that take one tied point per cell, the sweep chooses, lexicographically:

1. the fewest reversals over the targets' sizes (`quality.RPM_REVERSAL` of the disc speed
   at the turning width, `quality.PITCH_REVERSAL_DEG` in any pitch): the figures
   `quality.row_reversals` reads off the finished chart;
2. then (the spec's `tie_preference` "lowest-rpm", the default) the gentlest disc: the
   lowest sum of the disc speeds in steps of `RPM_STEP` (speeds closer than a step are one
   speed to this rule; "nearest", the rule of charts made before it, skips this step);
3. then the least movement along the row: the sum of the Euclidean steps between
   neighbouring widths' points in the unit box of the settings;
4. then the smallest sum of the points' score excesses over their cells' best (so a cell
   keeps its best when no tied point makes the row steadier);
5. then the lowest indices (deterministic).

A reversal is a property of three neighbouring widths, so the dynamic programme (Viterbi)
runs over pairs of neighbouring points: O(cells x points^3), a few hundred steps for a
row. The sweep reads the tie sets only: it needs no simulation, and the same tie sets
give the same picks in any process.

The repair (`repair`) widens the tie sets where the sweep leaves a reversal: a cell
turning over the targets' sizes gets its neighbours' chosen points, their linear
interpolation at its width and the steady slice's best point (the interpolation's
turning settings kept, each other setting searched on a grid along its axis) as
candidates, each neighbour the turning cell's point; the caller scores them on the
cell's own re-score rounds (the tie set's common random numbers) and marks those within
two standard errors of the cell's best (plus the steady tolerance) as tied; the tied ones join the tie sets and the
sweep runs again. At most `REPAIR_PASSES` passes, and only
while a pass lowers the row's reversals; a candidate is scored once per cell.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import numpy as np

from spreadgym.agents.chart.quality import over_target, reversals

RULE = ("fewest rpm (> 5 %) and pitch (> 3 deg) reversals, then least movement in the unit box, "
        "then least score excess over each cell's best, among each cell's tied points")
REPAIR_RULE = ("where the sweep leaves a reversal: the turning cell scored at its neighbours' points, their "
               "interpolation at its width and the best point of the steady slice (the interpolation's turning "
               "settings kept, the others searched), each neighbour at the turning cell's point, on the cell's "
               "own re-score rounds; those within two standard errors of the cell's best join its tie set; the "
               "sweep again")
REPAIR_PASSES = 3  # passes of candidates, each only while the last one lowered the row's reversals
REPAIR_CANDIDATES = 6  # most candidates of a cell in one pass (4 as a turning cell, 1 as each turn's neighbour)
SLICE_POINTS = 9  # the steady slice's grid along each searched axis (ends included), then SLICE_REFINE around its best
SLICE_REFINE = (-0.5, -0.25, 0.25, 0.5)  # in grid steps
RPM_STEP = 10.0  # rpm: the tie preference's unit of disc speed (a dial's resolution; closer speeds are one speed)
GENTLE_RULE = RULE.replace("reversals, then", f"reversals, then the lowest disc speeds (in {RPM_STEP:g} rpm steps), "
                                              "then")


def tolerance_text(tolerance_pp: float) -> str:
    """What `--steady-tolerance-pp` adds to the rule's words ('' at 0, the default: the text is as it was)."""
    return "" if tolerance_pp == 0.0 else f" plus a steady tolerance of {tolerance_pp:g} pp of the objective"


def rule(tolerance_pp: float = 0.0, preference: str = "nearest") -> str:
    """The sweep's rule (RULE, or GENTLE_RULE with the lowest-rpm preference; the tie test widened by a non-zero
    steady tolerance)."""
    text = GENTLE_RULE if preference == "lowest-rpm" else RULE
    if tolerance_pp == 0.0:
        return text
    return text + f" (tied: within two standard errors of the cell's best{tolerance_text(tolerance_pp)})"


def speed_steps(values: dict, preference: str) -> int:
    """The tie preference's disc-speed term of a point's dial values: its rpm in RPM_STEP steps ("lowest-rpm"),
    or 0 ("nearest": the speed is not preferred)."""
    return int(np.floor(values["rpm"] / RPM_STEP + 0.5)) if preference == "lowest-rpm" else 0


def repair_rule(tolerance_pp: float = 0.0) -> str:
    """The repair's rule (REPAIR_RULE; the tie test widened by a non-zero steady tolerance)."""
    return REPAIR_RULE.replace("two standard errors of the cell's best",
                               "two standard errors of the cell's best" + tolerance_text(tolerance_pp))


@dataclass(frozen=True)
class Point:
    """One tied point of a cell: unit settings, the dial's values (`rpm`, `*pitch_deg`, ...) and its
    score's excess over the cell's best (0 for the best)."""

    unit: tuple
    values: dict
    excess: float = 0.0


def turns(a: Point, b: Point, c: Point) -> int:
    """Reversals over the targets' sizes at the middle width `b` (rpm relative to `b`'s, pitches in degrees)."""
    return sum(over_target(key, size, b.values[key]) for key in b.values
               if key == "rpm" or key.endswith("pitch_deg")
               for _, size in reversals([a.values[key], b.values[key], c.values[key]]))


def step(a: Point, b: Point) -> float:
    return float(np.linalg.norm(np.subtract(a.unit, b.unit)))


def _add(cost: tuple, reversals: int, speed: int, movement: float, excess: float) -> tuple:
    return cost[0] + reversals, cost[1] + speed, cost[2] + movement, cost[3] + excess


def steadiest(row: Sequence[Sequence[Point]], preference: str = "lowest-rpm") -> list[int]:
    """The index of the chosen point in each cell of `row` (cells in width order, each a non-empty list), by the
    module's order (`preference`: the spec's `tie_preference`)."""
    if any(len(cell) == 0 for cell in row):
        raise ValueError("every cell needs at least one point")
    n = len(row)
    if n == 0:
        return []
    speed = [[speed_steps(p.values, preference) for p in cell] for cell in row]
    if n == 1:
        return [min(range(len(row[0])), key=lambda i: (speed[0][i], row[0][i].excess, i))]
    # cost[(a, b)]: the best cost of cells 0..k ending with point a at k-1 and point b at k; back[k][(a, b)]: cell k-2's
    cost = {(a, b): (0, speed[0][a] + speed[1][b], step(pa, pb), pa.excess + pb.excess)
            for a, pa in enumerate(row[0]) for b, pb in enumerate(row[1])}
    back: list[dict] = [{}, {}]
    for k in range(2, n):
        new, links = {}, {}
        for b, pb in enumerate(row[k - 1]):
            for c, pc in enumerate(row[k]):
                options = [(_add(cost[(a, b)], turns(pa, pb, pc), speed[k][c], step(pb, pc), pc.excess), a)
                           for a, pa in enumerate(row[k - 2])]
                new[(b, c)], links[(b, c)] = min(options)
        cost = new
        back.append(links)
    a, b = min(cost, key=lambda pair: (cost[pair], pair))
    path = [a, b]
    for k in range(n - 1, 1, -1):
        path.insert(0, back[k][(path[0], path[1])])
    return path


def row_points(spaces: Sequence, tie_sets: Sequence[dict]) -> list[list[Point]]:
    """The sweep's points of a row from its cells' settings spaces and tie sets (`detail["tie_set"]`), in
    width order."""
    row = []
    for space, tie in zip(spaces, tie_sets):
        points = tie["points"]
        best = points[tie["best"]]["score_percent"]
        row.append([Point(tuple(p["unit_settings"]), space.values(p["unit_settings"]),
                          0.0 if best is None or p["score_percent"] is None else max(0.0, p["score_percent"] - best))
                    for p in points])
    return row


def row_turns(row: Sequence[Sequence[Point]], picks: Sequence[int]) -> int:
    """Reversals over the targets' sizes along the path `picks`."""
    chosen = [cell[i] for cell, i in zip(row, picks)]
    return sum(turns(*chosen[k - 1:k + 2]) for k in range(1, len(chosen) - 1))


def turning(row: Sequence[Sequence[Point]], picks: Sequence[int]) -> list[int]:
    """The cells where the path `picks` turns over the targets' sizes."""
    chosen = [cell[i] for cell, i in zip(row, picks)]
    return [k for k in range(1, len(chosen) - 1) if turns(*chosen[k - 1:k + 2])]


def points_of(tie: dict, candidates: Sequence[dict]) -> list[dict]:
    """A cell's points the sweep chooses among: its tie set's, then the repair's tied candidates."""
    return list(tie["points"]) + [c for c in candidates if c["tied"]]


def row_with(spaces: Sequence, tie_sets: Sequence[dict], candidates: Sequence[Sequence[dict]]) -> list[list[Point]]:
    """The sweep's points of a row whose cells have `candidates` from the repair (`points_of` of each)."""
    return row_points(spaces, [{**t, "points": points_of(t, c)} for t, c in zip(tie_sets, candidates)])


def turning_axes(a: Point, b: Point, c: Point) -> list[int]:
    """The unit axes of the settings that turn over the targets' sizes at `b` (rpm, pitches)."""
    return [i for i, key in enumerate(b.values) if (key == "rpm" or key.endswith("pitch_deg"))
            and any(over_target(key, size, b.values[key]) for _, size in reversals([a.values[key], b.values[key],
                                                                                    c.values[key]]))]


def neighbour_candidates(row: Sequence[Sequence[Point]], picks: Sequence[int], widths: Sequence[float],
                         k: int) -> list[tuple[int, list, str, Optional[list]]]:
    """(cell, unit settings, source, free axes) of the candidates of a turn at cell `k`: for `k` the
    neighbours' chosen points, their linear interpolation at `k`'s width, and the steady slice (the
    interpolation's turning settings kept, the others searched: free axes given); for each neighbour `k`'s
    point."""
    a, b, c = (row[j][picks[j]] for j in (k - 1, k, k + 1))
    t = (widths[k] - widths[k - 1]) / (widths[k + 1] - widths[k - 1])
    ua, ub, uc = (np.asarray(p.unit, dtype=float) for p in (a, b, c))
    between = np.clip(ua + t * (uc - ua), -1.0, 1.0).tolist()
    out = [(k, ua.tolist(), "narrower", None), (k, uc.tolist(), "wider", None), (k, between, "between", None)]
    free = [i for i in range(len(ub)) if i not in turning_axes(a, b, c)]
    if 0 < len(free) < len(ub):
        out.append((k, between, "slice", free))
    return out + [(k - 1, ub.tolist(), "wider", None), (k + 1, ub.tolist(), "narrower", None)]


def job_key(unit: Sequence[float], free: Optional[Sequence[int]]) -> tuple:
    """What identifies a candidate: where it starts and the axes searched from there (None: none)."""
    return tuple(unit), None if free is None else tuple(free)


def start_of(candidate: dict) -> tuple:
    """The `job_key` of a scored candidate."""
    return job_key(candidate.get("start_unit_settings", candidate["unit_settings"]), candidate.get("free_axes"))


def repair(spaces: Sequence, widths: Sequence[float], tie_sets: Sequence[dict],
           score: Callable[[dict], dict], passes: int = REPAIR_PASSES,
           preference: str = "lowest-rpm") -> list[list[dict]]:
    """The candidates each cell of a row was scored at (in order), each a tie point with `tied`, `source`
    and `pass`. `score({cell: [(unit settings, free axes or None), ...]})` returns {cell: [point, ...]} (a
    tie point with `tied`; where free axes are given, the best point of a search of them from the unit
    settings). Cells whose tie set has no standard error (no re-score rounds) get no candidates."""
    tried: list[list[dict]] = [[] for _ in tie_sets]
    for pass_ in range(passes):
        row = row_with(spaces, tie_sets, tried)
        picks = steadiest(row, preference)
        now = row_turns(row, picks)
        jobs: dict[int, list] = {}
        for k in turning(row, picks):
            for j, unit, source, free in neighbour_candidates(row, picks, widths, k):
                known = [job_key(q.unit, None) for q in row[j]] + [start_of(c) for c in tried[j]]
                known += [job_key(u, f) for u, _, f in jobs.get(j, [])]
                if tie_sets[j]["best_standard_error_percent"] is not None and job_key(unit, free) not in known:
                    jobs.setdefault(j, []).append((unit, source, free))
        if not jobs:
            break
        found = score({j: [(u, f) for u, _, f in jobs[j]] for j in sorted(jobs)})
        for j in sorted(jobs):
            tried[j] += [{**point, "source": source, "pass": pass_}
                         for point, (_, source, _) in zip(found[j], jobs[j])]
        row = row_with(spaces, tie_sets, tried)
        if row_turns(row, steadiest(row, preference)) >= now:
            break
    return tried


def sweep_block(tie: dict, pick: int, search_pick_verified: Optional[dict], before: int, after: int,
                repair_block: dict, tolerance_pp: float = 0.0, preference: str = "nearest") -> dict:
    """What the sweep did to a cell (`detail["sweep"]`): its pick among its points (`points_of`), whether
    that moved the cell off the search's pick, the search pick's own verification when it did, the row's
    reversals over the targets' sizes along the search's picks and along the sweep's, and the repair's
    candidates of the cell."""
    return {"rule": rule(tolerance_pp, preference), "pick": pick, "moved": pick != tie["search_pick"],
            "at_best": pick == tie["best"],
            "row_reversals_search": before, "row_reversals_swept": after,
            "search_pick_verified": search_pick_verified, "repair": repair_block}


def repair_block(spec, detail: dict, candidates: list[dict]) -> dict:
    """The repair's record of a cell: its scored candidates and their simulations (each candidate's re-score
    rounds, and a steady slice's search)."""
    evaluations = sum(detail["rescores"] + c.get("slice_evaluations", 0) for c in candidates)
    return {"rule": repair_rule(spec.steady_tolerance_pp), "candidates": candidates,
            "simulations": evaluations * spec.draws}


def candidates_of(detail: dict) -> list[dict]:
    """The repair's candidates recorded in a cell's sweep block (none before a sweep)."""
    return ((detail.get("sweep") or {}).get("repair") or {}).get("candidates", [])


def verified_figures(row: dict) -> dict:
    """A row's verified figures (what `sweep.search_pick_verified` keeps of the search pick's verification)."""
    keys = ("cv_percent", "cv_standard_error_percent", "cv_p90_percent", "cv_p90_standard_error_percent",
            "effective_swath_m", "cv_search_percent")
    return {k: row[k] for k in keys}


def swept_record(spec, cell, record: dict, pick: int, before: int, after: int, candidates: Sequence[dict] = (),
                 repair_wall_s: float = 0.0) -> dict:
    """`record` with the sweep's `pick` among the tie set and the tied `candidates`: the same verification
    when the pick is the point it is verified at; otherwise the pick verified on the cell's own verification
    seeds (the search pick's verified figures kept in the block). Its simulations: the search's, the
    repair's and one verification, two when moved off the search pick; `repair_wall_s` (the repair's new
    scoring) and a new verification's time are added to its wall time."""
    import time

    from spreadgym.agents.chart.search import verified_record

    detail, row = record["detail"], record["row"]
    tie = detail["tie_set"]
    point = points_of(tie, candidates)[pick]
    kept = (detail["sweep"] or {}).get("search_pick_verified")
    if kept is None and detail["unit_settings"] == tie["points"][tie["search_pick"]]["unit_settings"]:
        kept = verified_figures(row)
    repaired = repair_block(spec, detail, list(candidates))
    block = sweep_block(tie, pick, kept if pick != tie["search_pick"] else None, before, after, repaired,
                        spec.steady_tolerance_pp, spec.tie_preference)
    simulations = (detail["search_evaluations"] * spec.draws + repaired["simulations"]
                   + spec.verify_simulations * (1 if pick == tie["search_pick"] else 2))
    if detail["unit_settings"] == point["unit_settings"]:
        return {"row": {**row, "simulations": simulations, "wall_s": row["wall_s"] + repair_wall_s},
                "detail": {**detail, "sweep": block}}
    base = {k: detail[k] for k in ("key", "search_unit_settings", "objective", "method", "search_evaluations",
                                   "rescores", "ties", "tie_set")}
    base["sweep"] = block
    return verified_record(spec, cell, np.asarray(point["unit_settings"], dtype=float), point["cv_search_percent"],
                           point["cv_search_standard_error_percent"], simulations - spec.verify_simulations, base,
                           time.perf_counter() - row["wall_s"] - repair_wall_s)


def reversal_prices(spec, records: Sequence[dict]) -> list[dict]:
    """Every reversal over the targets' sizes left in the finished rows of `records` (spec order), with its price:
    the least a scored point of the turning cell or of a neighbour (its tie set or any repair candidate, tied or
    not) that leaves no turn there would add to that cell's score over the point it has (percentage points of the
    objective on the cell's own re-score rounds; None where no scored point removes it, e.g. cells never
    re-scored). The turn is priced where it is: a replacement may move a turn to the next width."""
    from spreadgym.agents.chart.spec import Cell

    out = []
    for fertilizer in spec.fertilizers:
        mine = [r for r in records if r["row"]["fertilizer"] == fertilizer]
        if len(mine) < 3:
            continue
        details = [r["detail"] for r in mine]
        spaces = [spec.space(spec.cell_scene(Cell(fertilizer, r["row"]["width_m"]))) for r in mine]
        # a chart made before tie sets (issue 31) has no scored alternatives: its reversals are listed unpriced
        scored = [row_points([space], [{**d["tie_set"], "points": list(d["tie_set"]["points"]) + candidates_of(d)}])[0]
                  if d.get("tie_set") else [] for space, d in zip(spaces, details)]
        chosen = [next((p for p in cell if list(p.unit) == d["unit_settings"]),
                       Point(tuple(d["unit_settings"]), space.values(d["unit_settings"]), 0.0))
                  for cell, d, space in zip(scored, details, spaces)]
        for k in range(1, len(mine) - 1):
            here = chosen[k - 1:k + 2]
            if not turns(*here):
                continue
            prices = []
            for j in range(3):
                for alternative in scored[k - 1 + j]:
                    trial = [alternative if i == j else p for i, p in enumerate(here)]
                    if not turns(*trial):
                        prices.append((alternative.excess - here[j].excess, mine[k - 1 + j]["row"]["width_m"]))
            price = min(prices) if prices else None
            axes = turning_axes(*here)
            out.append({"fertilizer": fertilizer, "width_m": mine[k]["row"]["width_m"],
                        "settings": [list(here[1].values)[i] for i in axes],
                        "values": [[p.values[list(here[1].values)[i]] for p in here] for i in axes],
                        "price_pp": None if price is None else max(0.0, price[0]),
                        "priced_at_width_m": None if price is None else price[1]})
    return out
