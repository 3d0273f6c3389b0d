"""One chart cell: search the scene's settings for the lowest CV at the cell's width on the
fast objective, scored honestly, then verify the winner with the full model, at the
nominal scene and over the variability model.

* Objective (minimised): the corrected CV at the width (100 % when nothing lands) plus
  `SWATH_PENALTY_PERCENT` times the relative shortfall of the effective swath below the
  width, max(0, W - W_eff) / W, plus `LOST_MASS_PENALTY_PERCENT` times the share of the
  released mass that missed the trays (retained on the spinner, or on a twin machine
  thrown onto the other disc, whose fate is not modelled). A CV at or under the
  threshold already means W_eff >= W; the swath penalty steers a search that is still
  above it towards wider patterns, and the mass penalty keeps it from buying evenness
  by losing mass.
* Robust objective (the default): a candidate's score is the `quantile` (0.9) of the
  objective over the variability model's draws (`variability`), all run in one
  `run_batch` call; every candidate of the search is scored on the same draws (common
  random numbers). Nominal objective: one run of the nominal scene, a fresh granule
  sample per evaluation.
* Search: CMA-ES over the settings box (`agents.baselines.cmaes_search`), started at the
  narrower neighbour's settings (the first width: the scene's own; `policy+search`: the
  policy's proposal). The search gets 1 - RESCORE_FRACTION of the budget (candidates);
  the rest re-scores its leaders, the neighbour's settings and the policy's proposal, in
  rounds (fewer leaders where that leaves each point 2 rounds): each round scores every
  point on the same fresh samples (robust: a fresh set of draws).
* Steady rows: the leaders whose mean re-scored score is within two standard errors (of
  the best leader's mean, from the spread of its rounds) of the best, plus the spec's
  steady tolerance, are the cell's tie set; the one with the lowest disc speed (in
  `sweep.RPM_STEP` steps; the spec's `tie_preference`), then closest to the narrower
  neighbour's settings (in the unit box), then the best scored, is the search pick, where
  the next width starts. The row sweep (`agents.chart.sweep`) later
  picks one point of each tie set for the whole row. What the search believes
  (`cv_search_percent`, the CV of its objective) rests on the re-scores only.
* `policy`: no search; the policy's proposal is the cell's settings.
* Verification (`verified_record`; also of a point the row sweep moves a cell to): the
  settings run `verify_runs` times on the full model and pooled
  (`spread.reference`), so `cv_percent` and `cv_standard_error_percent` rest on
  verify_runs x granules granules in as many replicates; and run once on each of
  `verify_draws` fresh draws of the variability model on the full model: their
  `quantile` is `cv_p90_percent`, with a bootstrap standard error over the draws.

Every seed comes from the cell's seed sequence (`spec.cell_seed`): the same spec gives
the same cell bit for bit, in any process and in any order.
"""

from __future__ import annotations

import math
import time
from typing import Optional

import numpy as np

from spreadgym.agents.baselines import CMA_SIGMA0, LEADERS, cmaes_search, leaders, split_budget
from spreadgym.agents.chart import variability as var
from spreadgym.agents.chart.spec import Cell, ChartSpec, cell_seed
from spreadgym.agents.chart.sweep import SLICE_POINTS, SLICE_REFINE, speed_steps
from spreadgym.agents.evaluation import WORST_CV_PERCENT
from spreadgym.config.scene import scene_with
from spreadgym.physics.selection import choose_model
from spreadgym.spread.batch import run_batch
from spreadgym.spread.metrics import RunMetrics
from spreadgym.spread.reference import pool_runs, reference_from
from spreadgym.threads import thread_count

SWATH_PENALTY_PERCENT = 100.0  # percentage points per unit relative swath shortfall
LOST_MASS_PENALTY_PERCENT = 100.0  # percentage points per unit share of mass not in the trays
CMA_SEED_RANGE = 100_000  # cma seeds its generator with seed * 1000 + restart: keep it below 2**32
WARM_SIGMA = 0.5 * CMA_SIGMA0  # CMA-ES step size when started at a neighbour's or a policy's settings
TIE_STANDARD_ERRORS = 2.0  # leaders within this many standard errors of the best count as ties


def objective(metrics: RunMetrics, width_m: float) -> tuple[float, float, Optional[float]]:
    """(cost, CV %, its standard error) of one run's metrics at bout width `width_m`."""
    cv = metrics.cv_percent_at_target
    cv = WORST_CV_PERCENT if cv is None else float(cv)
    shortfall = max(0.0, width_m - float(metrics.effective_swath_m)) / width_m
    landed = metrics.landed_fraction
    lost = 1.0 if landed is None else max(0.0, 1.0 - landed)
    cost = cv + SWATH_PENALTY_PERCENT * shortfall + LOST_MASS_PENALTY_PERCENT * lost
    return cost, cv, metrics.cv_standard_error_percent


class Scorer:
    """Scores unit settings on the cell's objective; counts the simulations."""

    def __init__(self, spec: ChartSpec, cell: Cell, seq: np.random.SeedSequence):
        self.spec, self.cell = spec, cell
        self.scene = spec.cell_scene(cell)
        self.space = spec.space(self.scene)
        self.quantile = spec.variability["quantile"]
        self.rounds_seq, self.fresh_seq = var.child(seq, 1), var.child(seq, 2)
        self.search_draws = self._draws(var.child(seq, 0))
        self.simulations = 0

    def _draws(self, seq: np.random.SeedSequence) -> list:
        return var.draws(self.spec.variability, self.spec.variability["draws"], seq)

    def round_draws(self, r: int) -> list:
        """The draws of re-scoring round `r` (fresh, common to every leader)."""
        return self._draws(var.child(self.rounds_seq, r))

    def fresh_seed(self, k: int) -> int:
        """The granule seed of the `k`-th nominal evaluation."""
        return int(var.child(self.fresh_seq, k).generate_state(1)[0])

    def model(self, settings: dict) -> str:
        """The model of a candidate's runs: the search model, `auto` resolved once on the candidate as
        dialled, so a draw whose disc speed or pitch the variability model nudges past the envelope the
        compiled model was validated in (`selection.VALIDATED`) stays on the candidate's model."""
        return choose_model(scene_with(self.scene, settings), self.spec.search_model, self.spec.library())[0]

    def score_many(self, units: list, cell_draws: Optional[list] = None,
                   seeds: Optional[list] = None) -> list[tuple]:
        """(cost, CV %) of each of `units`: robust, the quantile over `cell_draws`; nominal, one run at its seed
        in `seeds`. All runs in one `run_batch` per model (the same bits as one call per unit or per run)."""
        spec, library = self.spec, self.spec.library()
        if spec.objective != "nominal":
            library = var.draw_library(library, self.cell.fertilizer, cell_draws)
        runs = []  # (model, scenes) of each unit
        for unit, seed in zip(units, seeds or [None] * len(units)):
            settings = self.space.overrides(unit)
            if spec.objective == "nominal":
                scenes = [scene_with(self.scene, settings | {"sim.seed": seed})]
            else:
                scenes = [scene_with(self.scene, var.perturbed(self.scene, settings, d, library)) for d in cell_draws]
            runs.append((self.model(settings), scenes))
        found: dict = {}
        for model in dict.fromkeys(m for m, _ in runs):
            mine = [i for i, (m, _) in enumerate(runs) if m == model]
            results = iter(run_batch([s for i in mine for s in runs[i][1]], model=model, library=library, ci=False))
            found.update({i: [objective(next(results).metrics, self.cell.width_m) for _ in runs[i][1]] for i in mine})
        self.simulations += sum(len(scenes) for _, scenes in runs)
        return [(var.quantile([f[0] for f in found[i]], self.quantile), var.quantile([f[1] for f in found[i]],
                                                                                        self.quantile))
                for i in range(len(runs))]


def search(scorer: Scorer, x0: np.ndarray, sigma0: float, neighbour: Optional[np.ndarray], cma_seed: int,
           proposal: Optional[np.ndarray] = None) -> dict:
    """CMA-ES from `x0`, then the leaders (and `neighbour`, and the policy's `proposal`) re-scored in rounds;
    the pick by the tie rule, and the tie set (every re-scored point tied with the best) for the row sweep."""
    spec = scorer.spec
    count = iter(range(spec.budget))
    nominal = spec.objective == "nominal"

    search_cvs: list[float] = []

    def evaluate_many(units):
        seeds = [scorer.fresh_seed(next(count)) for _ in units] if nominal else None
        found = scorer.score_many(units, None if nominal else scorer.search_draws, seeds)
        search_cvs.extend(cv for _, cv in found)
        return [-cost for cost, _ in found]

    search_budget, _ = split_budget(spec.budget)
    result = cmaes_search(lambda unit: evaluate_many([unit])[0], scorer.space.size, search_budget, seed=cma_seed,
                          sigma0=sigma0, x0=x0, many=evaluate_many)
    rescore_budget = spec.budget - result.evaluations
    extras = [x for x in (neighbour, proposal) if x is not None]
    kept = leaders(result, max(1, min(LEADERS, rescore_budget // 2 - len(extras))))
    for extra in extras:
        if not any(np.array_equal(extra, x) for x in kept):
            kept.append(extra)
    rounds = rescore_budget // len(kept)
    if rounds < 2:  # too small a budget to re-score: the belief is the search's own best evaluation
        i = int(np.argmax(result.history))
        point = tie_point(result.best_x, -float(result.history[i]), search_cvs[i], None)
        return {"x": result.best_x, "cv": search_cvs[i], "cv_se": None, "rounds": 0, "ties": 1,
                "evaluations": result.evaluations, "tie_set": tie_set([point], 0, 0, None)}
    scores = rescore(scorer, kept, rounds)
    means = scores[:, :, 0].mean(axis=1)
    best = int(np.argmin(means))
    best_se = rounds_se(scores[best, :, 0])
    limit = tie_limit(float(means[best]), best_se, spec.steady_tolerance_pp)
    ties = [i for i in range(len(kept)) if means[i] <= limit]
    pick = min(ties, key=lambda i: (speed_steps(scorer.space.values(kept[i]), spec.tie_preference),
                                    0.0 if neighbour is None else float(np.linalg.norm(kept[i] - neighbour)),
                                    means[i], i))
    cv_se = [rounds_se(scores[i, :, 1]) for i in range(len(kept))]
    points = [tie_point(kept[i], float(means[i]), float(scores[i, :, 1].mean()), cv_se[i]) for i in ties]
    return {"x": kept[pick], "cv": float(scores[pick, :, 1].mean()), "cv_se": cv_se[pick],
            "rounds": rounds, "ties": len(ties), "evaluations": result.evaluations + rounds * len(kept),
            "tie_set": tie_set(points, ties.index(best), ties.index(pick), best_se)}


def rescore(scorer: Scorer, points: list, rounds: int) -> np.ndarray:
    """(cost, CV %) of each of `points` in each re-score round (points x rounds x 2): round `r` scores every
    point on the same fresh samples (robust: `round_draws(r)`; nominal: the granule seed after the search's)."""
    nominal = scorer.spec.objective == "nominal"
    search_budget, _ = split_budget(scorer.spec.budget)  # the search spends exactly this (cmaes_search)
    scores = np.zeros((len(points), rounds, 2))
    for r in range(rounds):
        cell_draws = None if nominal else scorer.round_draws(r)
        seed = scorer.fresh_seed(search_budget + r) if nominal else None
        scores[:, r] = scorer.score_many(points, cell_draws, [seed] * len(points))
    return scores


def slice_search(scorer: Scorer, start: np.ndarray, free: list) -> tuple[np.ndarray, int]:
    """The row repair's steady slice: from `start`, each axis of `free` in turn on a grid of SLICE_POINTS
    (then SLICE_REFINE steps around its best), the others kept, scored like the search (its draws): (the
    best point, the evaluations)."""
    x, evaluations = np.asarray(start, dtype=float).copy(), 0
    grid = np.linspace(-1.0, 1.0, SLICE_POINTS)

    def costs_along(axis: int, values: list) -> list[float]:
        units = [np.where(np.arange(x.size) == axis, v, x) for v in values]
        return [c for c, _ in scorer.score_many(units, scorer.search_draws, [scorer.fresh_seed(0)] * len(values))]

    for axis in free:
        values = list(grid)
        costs = costs_along(axis, values)
        centre, step = values[int(np.argmin(costs))], grid[1] - grid[0]
        near = [float(np.clip(centre + f * step, -1.0, 1.0)) for f in SLICE_REFINE]
        near = [v for v in dict.fromkeys(near) if v not in values]
        costs += costs_along(axis, near)
        values += near
        evaluations += len(values)
        x[axis] = values[int(np.argmin(costs))]
    return x, evaluations


def score_candidates(spec: ChartSpec, cell: Cell, detail: dict, jobs: list) -> tuple[list[dict], float]:
    """The row repair's candidates of a cell, `jobs` of (unit settings, free axes or None): a steady slice
    (free axes given) searched first (`slice_search`); each re-scored on the cell's own re-score rounds (the
    tie set's common random numbers). (A tie point with `tied` (`tie_limit`: within TIE_STANDARD_ERRORS of the
    tie set's best plus the spec's steady tolerance, the chain's rule) per job, the wall time.)"""
    started = time.perf_counter()
    scorer = Scorer(spec, cell, cell_seed(spec.seed, cell).spawn(5)[0])
    units, extra = [], []
    for unit, free in jobs:
        if free is None:
            units.append(np.asarray(unit, dtype=float))
            extra.append({})
            continue
        found, evaluations = slice_search(scorer, np.asarray(unit, dtype=float), free)
        units.append(found)
        extra.append({"start_unit_settings": [float(v) for v in unit], "free_axes": list(free),
                      "slice_evaluations": evaluations})
    rounds = detail["rescores"]
    scores = rescore(scorer, units, rounds)
    tie = detail["tie_set"]
    limit = tie_limit(tie["points"][tie["best"]]["score_percent"], tie["best_standard_error_percent"],
                      spec.steady_tolerance_pp)
    out = []
    for unit, score, more in zip(units, scores, extra):
        mean = float(score[:, 0].mean())
        point = tie_point(unit, mean, float(score[:, 1].mean()), rounds_se(score[:, 1]))
        out.append({**point, "tied": mean <= limit, **more})
    return out, time.perf_counter() - started


def rounds_se(values: np.ndarray) -> float:
    """The standard error of the mean of one point's re-score rounds (`values`, one per round)."""
    return float(values.std(ddof=1) / math.sqrt(values.size))


def tie_limit(best: float, best_se: float, tolerance_pp: float = 0.0) -> float:
    """The highest mean score that ties with the best: TIE_STANDARD_ERRORS of its standard error above it, plus
    `tolerance_pp` percentage points of the objective (`--steady-tolerance-pp`; 0, the default, adds nothing:
    the same limit to the bit)."""
    return best + TIE_STANDARD_ERRORS * best_se + tolerance_pp


def tie_point(x: np.ndarray, score: Optional[float], cv: Optional[float], cv_se: Optional[float]) -> dict:
    """One point of a cell's tie set: its unit settings, mean score and search CV (robust: p90) with its SE."""
    return {"unit_settings": [float(v) for v in x], "score_percent": score, "cv_search_percent": cv,
            "cv_search_standard_error_percent": cv_se}


def tie_set(points: list[dict], best: int, pick: int, best_se: Optional[float]) -> dict:
    """The points tied with the best (`best`: its index; `search_pick`: the chain's pick, by the nearness rule)."""
    return {"points": points, "best": best, "search_pick": pick, "best_standard_error_percent": best_se}


def verify_p90(spec: ChartSpec, cell: Cell, scene, settings: dict, seq: np.random.SeedSequence) -> dict:
    """The winner on `verify_draws` fresh draws, `verify_runs_per_draw` full-model runs pooled each: the
    quantile and its bootstrap SE."""
    draws_seq, bootstrap_seq = var.child(seq, 0), var.child(seq, 1)
    cell_draws = var.draws(spec.variability, spec.variability["verify_draws"], draws_seq)
    library = var.draw_library(spec.library(), cell.fertilizer, cell_draws)
    runs = spec.variability["verify_runs_per_draw"]  # n runs pooled are one run of n times the granules
    pooled = {"sim.granules": runs * scene.sim.granules, "sim.replicates": runs * scene.sim.replicates}
    scenes = [scene_with(scene, var.perturbed(scene, settings, d, library) | pooled) for d in cell_draws]
    results = run_batch(scenes, model=spec.verify_model, library=library, ci=False)
    found = [objective(r.metrics, cell.width_m) for r in results]
    cvs = [f[1] for f in found]
    q = spec.variability["quantile"]
    return {"cv_percent": var.quantile(cvs, q), "standard_error_percent": var.bootstrap_se(cvs, q, bootstrap_seq),
            "draws": len(cvs), "runs_per_draw": runs, "granules": runs * scene.sim.granules, "model": spec.verify_model,
            "cv_draws_percent": cvs, "cv_draws_standard_error_percent": [f[2] for f in found]}


def run_cell(spec: ChartSpec, cell: Cell, previous: Optional[dict] = None) -> dict:
    """Search and verify one cell; `previous` is the record of the narrower neighbour
    (`spec.previous(cell)`, None for the first width). Returns {"row": the chart row, "detail": the rest}.
    The chain runs on the search's own picks (`search_unit_settings`), never on what a row sweep made of
    them, so a cell is the same whether its neighbour was swept yet or not."""
    started = time.perf_counter()
    scorer_seq, cma_seq, _, _, policy_seq = cell_seed(spec.seed, cell).spawn(5)
    scorer = Scorer(spec, cell, scorer_seq)
    scene, space = scorer.scene, scorer.space
    neighbour = None if previous is None else np.asarray(previous["detail"]["search_unit_settings"], dtype=float)
    proposal = None
    if spec.method != "cmaes":
        from spreadgym.agents.chart.policy import propose

        proposal = propose(spec, cell, policy_seq)
    if spec.method == "policy":
        found = {"x": proposal, "cv": None, "cv_se": None, "rounds": 0, "ties": 1, "evaluations": 0,
                 "tie_set": tie_set([tie_point(proposal, None, None, None)], 0, 0, None)}
    else:
        x0 = proposal if proposal is not None else (neighbour if neighbour is not None else space.scene_unit(scene))
        warm = proposal is not None or neighbour is not None
        found = search(scorer, x0, WARM_SIGMA if warm else CMA_SIGMA0, neighbour,
                       int(cma_seq.generate_state(1)[0]) % CMA_SEED_RANGE, proposal)
    best_x = np.asarray(found["x"], dtype=float)
    detail = {"key": cell.key, "search_unit_settings": [float(v) for v in best_x], "objective": spec.objective,
              "method": spec.method, "search_evaluations": found["evaluations"], "rescores": found["rounds"],
              "ties": found["ties"], "tie_set": found["tie_set"], "sweep": None}
    return verified_record(spec, cell, best_x, found["cv"], found["cv_se"], scorer.simulations, detail, started)


def verified_record(spec: ChartSpec, cell: Cell, x: np.ndarray, cv_search: Optional[float],
                    cv_search_se: Optional[float], search_simulations: int, detail: dict, started: float) -> dict:
    """The cell's record with settings `x` verified on the full model (nominal, pooled, and the p90), on the
    cell's own verification seeds: whatever settings a cell ends with are verified alike."""
    _, _, verify_seq, p90_seq, _ = cell_seed(spec.seed, cell).spawn(5)
    scene = spec.cell_scene(cell)
    space = spec.space(scene)
    settings = space.overrides(x)
    verify_scene = scene_with(scene, settings | {"sim.seed": int(verify_seq.generate_state(1)[0])})
    pooled = pool_runs(verify_scene, spec.verify_runs, model=spec.verify_model, library=spec.library())
    reference = reference_from(verify_scene, pooled)
    cv, cv_se = reference.at_target.cv_percent, reference.at_target.standard_error_percent
    p90 = verify_p90(spec, cell, scene, settings, p90_seq)
    verified, verified_se = (cv, cv_se) if spec.objective == "nominal" else (p90["cv_percent"],
                                                                             p90["standard_error_percent"])
    agree = None
    if verified is not None and verified_se is not None and cv_search_se is not None:
        agree = abs(verified - cv_search) <= 2.0 * math.hypot(verified_se, cv_search_se)
    row = {"fertilizer": cell.fertilizer, "width_m": cell.width_m, "driving": spec.driving,
           **space.values(x),
           "cv_percent": cv, "cv_standard_error_percent": cv_se,
           "cv_p90_percent": p90["cv_percent"], "cv_p90_standard_error_percent": p90["standard_error_percent"],
           "effective_swath_m": reference.effective_swath_m, "cv_search_percent": cv_search,
           "simulations": search_simulations + spec.verify_runs + p90["draws"] * p90["runs_per_draw"],
           "wall_s": time.perf_counter() - started}
    detail = {
        **detail,
        "unit_settings": [float(v) for v in x],
        "cv_search_standard_error_percent": cv_search_se,
        "search_agrees_within_2se": agree,
        "meets_threshold": cv is not None and cv <= scene.pattern.cv_threshold_percent,
        "verification": {"model": pooled.model, "granules": pooled.granules, "replicates": pooled.replicates,
                         "cv_raw_percent": reference.at_target.raw_percent,
                         "effective_swath_interval_m": list(reference.effective_swath_interval_m),
                         "wall_s": pooled.wall_s, "threads": thread_count()},
        "verification_p90": p90,
        "trays": {"center_m": reference.trays.center_m.tolist(), "mass_kg": reference.trays.mass_kg.tolist()},
        "cv_curve": {"bout_width_m": reference.widths_m.tolist(),
                     "cv_percent": [None if not np.isfinite(v) else float(v) for v in reference.cv_percent]},
    }
    return {"row": row, "detail": detail}
