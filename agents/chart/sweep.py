"""The row sweep: once every cell of a fertilizer's row has its tie set, pick one point per
cell so that the row is as steady as the ties allow.

A cell's tie set (`search.search`) holds the re-scored points whose mean score is within
`TIE_STANDARD_ERRORS` standard errors of the best's (the best among them; with
`policy+search` the policy's proposal and the narrower neighbour's settings are re-scored
too; with `policy`, or a budget too small to re-score, the set is the cell's one point).
Among all paths that take one tied point per cell, the sweep chooses, lexicographically:

1. the fewest reversals over the targets' sizes (`quality.RPM_REVERSAL` of the disc speed
   at the turning width, `quality.PITCH_REVERSAL_DEG` in any pitch): the figures
   `quality.row_reversals` reads off the finished chart;
2. then the least movement along the row: the sum of the Euclidean steps between
   neighbouring widths' points in the unit box of the settings;
3. then the smallest sum of the points' score excesses over their cells' best (so a cell
   keeps its best when no tied point makes the row steadier);
4. then the lowest indices (deterministic).

A reversal is a property of three neighbouring widths, so the dynamic programme (Viterbi)
runs over pairs of neighbouring points: O(cells x points^3), a few hundred steps for a
row. The sweep reads the tie sets only: it needs no simulation, and the same tie sets
give the same picks in any process.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from spreadgym.agents.chart.quality import over_target, reversals

RULE = ("fewest rpm (> 5 %) and pitch (> 3 deg) reversals, then least movement in the unit box, "
        "then least score excess over each cell's best, among each cell's tied points")


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


def _add(cost: tuple, reversals: int, movement: float, excess: float) -> tuple:
    return cost[0] + reversals, cost[1] + movement, cost[2] + excess


def steadiest(row: Sequence[Sequence[Point]]) -> list[int]:
    """The index of the chosen point in each cell of `row` (cells in width order, each a non-empty list)."""
    if any(len(cell) == 0 for cell in row):
        raise ValueError("every cell needs at least one point")
    n = len(row)
    if n == 0:
        return []
    if n == 1:
        return [min(range(len(row[0])), key=lambda i: (row[0][i].excess, i))]
    # cost[(a, b)]: the best cost of cells 0..k ending with point a at k-1 and point b at k; back[k][(a, b)]: cell k-2's
    cost = {(a, b): (0, step(pa, pb), pa.excess + pb.excess)
            for a, pa in enumerate(row[0]) for b, pb in enumerate(row[1])}
    back: list[dict] = [{}, {}]
    for k in range(2, n):
        new, links = {}, {}
        for b, pb in enumerate(row[k - 1]):
            for c, pc in enumerate(row[k]):
                options = [(_add(cost[(a, b)], turns(pa, pb, pc), step(pb, pc), pc.excess), a)
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


def sweep_block(tie: dict, pick: int, search_pick_verified: Optional[dict], before: int, after: int) -> dict:
    """What the sweep did to a cell (`detail["sweep"]`): its pick in the tie set, whether that moved the
    cell off the search's pick, the search pick's own verification when it did, and the row's reversals
    over the targets' sizes along the search's picks and along the sweep's."""
    return {"rule": RULE, "pick": pick, "moved": pick != tie["search_pick"], "at_best": pick == tie["best"],
            "row_reversals_search": before, "row_reversals_swept": after,
            "search_pick_verified": search_pick_verified}


def current_pick(detail: dict) -> Optional[int]:
    """The index in the tie set of the point the record is verified at (None: none of them)."""
    for i, point in enumerate(detail["tie_set"]["points"]):
        if point["unit_settings"] == detail["unit_settings"]:
            return i
    return None


def verified_figures(row: dict) -> dict:
    """A row's verified figures (what `sweep.search_pick_verified` keeps of the search pick's verification)."""
    keys = ("cv_percent", "cv_standard_error_percent", "cv_p90_percent", "cv_p90_standard_error_percent",
            "effective_swath_m", "cv_search_percent")
    return {k: row[k] for k in keys}


def swept_record(spec, cell, record: dict, pick: int, before: int, after: int) -> dict:
    """`record` with the sweep's `pick`: the same record with its sweep block when the pick is the point it
    is verified at; otherwise the pick verified on the cell's own verification seeds (the search pick's
    verified figures kept in the block), its simulations and wall time added to the cell's."""
    import time

    from spreadgym.agents.chart.search import verified_record

    detail, row = record["detail"], record["row"]
    tie = detail["tie_set"]
    kept = (detail["sweep"] or {}).get("search_pick_verified")
    if kept is None and detail["unit_settings"] == tie["points"][tie["search_pick"]]["unit_settings"]:
        kept = verified_figures(row)
    if current_pick(detail) == pick:
        block = sweep_block(tie, pick, kept if pick != tie["search_pick"] else None, before, after)
        return {"row": row, "detail": {**detail, "sweep": block}}
    point = tie["points"][pick]
    base = {k: detail[k] for k in ("key", "search_unit_settings", "objective", "method", "search_evaluations",
                                   "rescores", "ties", "tie_set")}
    base["sweep"] = sweep_block(tie, pick, kept if pick != tie["search_pick"] else None, before, after)
    # the new verification's runs and time come on top of the search's and the search pick's verification
    # (a record already moved by an earlier sweep counts that pick's verification once, not again)
    simulations = row["simulations"] - (spec.verify_simulations if current_pick(detail) != tie["search_pick"] else 0)
    return verified_record(spec, cell, np.asarray(point["unit_settings"], dtype=float), point["cv_search_percent"],
                           point["cv_search_standard_error_percent"], simulations, base,
                           time.perf_counter() - row["wall_s"])
