"""One chart cell: search the scene's settings for the lowest CV at the cell's width on the
fast objective, scored honestly, then verify the winner with the full model.

* Objective (minimised): the corrected CV at the width (100 % when nothing lands) plus
  `SWATH_PENALTY_PERCENT` times the relative shortfall of the effective swath below the
  width, max(0, W - W_eff) / W, plus `LOST_MASS_PENALTY_PERCENT` times the share of the
  released mass that missed the trays (retained on the spinner, or on a twin machine
  thrown onto the other disc, whose fate is not modelled). A CV at or under the
  threshold already means W_eff >= W; the swath penalty steers a search that is still
  above it towards wider patterns, and the mass penalty keeps it from buying evenness
  by losing mass.
* Search: CMA-ES over the settings box (`agents.baselines.cmaes_search`), started at the
  scene's own settings. Honest scoring as in the baselines: every evaluation on a fresh
  granule sample (its own seed), the search gets 1 - RESCORE_FRACTION of the budget and
  the rest re-scores its leaders on fresh samples; the leader with the best mean wins and
  what the search believes (`cv_search_percent`) rests on those re-scores only.
* Verification: the winner run `verify_runs` times on the full model and pooled
  (`spread.reference`), so `cv_percent` and `cv_standard_error_percent` rest on
  verify_runs x granules granules in as many replicates.

Every seed comes from the cell's seed sequence (`spec.cell_seed`): the same spec gives
the same cell bit for bit, in any process and in any order.
"""

from __future__ import annotations

import math
import time
from typing import Optional

import numpy as np

from spreadgym.agents.baselines import LEADERS, Leader, cmaes_search, leaders, split_budget
from spreadgym.agents.chart.spec import Cell, ChartSpec, cell_seed
from spreadgym.agents.evaluation import WORST_CV_PERCENT
from spreadgym.config.materials import load_library
from spreadgym.config.scene import scene_with
from spreadgym.spread.metrics import RunMetrics
from spreadgym.spread.pipeline import run_scene
from spreadgym.spread.reference import pool_runs, reference_from

SWATH_PENALTY_PERCENT = 100.0  # percentage points per unit relative swath shortfall
LOST_MASS_PENALTY_PERCENT = 100.0  # percentage points per unit share of mass not in the trays
CMA_SEED_RANGE = 100_000  # cma seeds its generator with seed * 1000 + restart: keep it below 2**32


def objective(metrics: RunMetrics, width_m: float) -> tuple[float, float, Optional[float]]:
    """(cost, CV %, its standard error) of one run's metrics at bout width `width_m`."""
    cv = metrics.cv_percent_at_target
    cv = WORST_CV_PERCENT if cv is None else float(cv)
    shortfall = max(0.0, width_m - float(metrics.effective_swath_m)) / width_m
    landed = metrics.landed_fraction
    lost = 1.0 if landed is None else max(0.0, 1.0 - landed)
    cost = cv + SWATH_PENALTY_PERCENT * shortfall + LOST_MASS_PENALTY_PERCENT * lost
    return cost, cv, metrics.cv_standard_error_percent


def run_cell(spec: ChartSpec, cell: Cell) -> dict:
    """Search and verify one cell; returns {"row": the chart row, "detail": the rest}."""
    started = time.perf_counter()
    library = load_library()
    scene = spec.cell_scene(cell)
    space = spec.space(scene)
    evaluations_seq, cma_seq, verify_seq = cell_seed(spec.seed, cell).spawn(3)
    seeds = evaluations_seq.generate_state(spec.budget)
    runs: list[tuple[float, float, Optional[float]]] = []

    def simulate(unit: np.ndarray) -> tuple[float, float, Optional[float]]:
        overrides = space.overrides(unit) | {"sim.seed": int(seeds[len(runs)])}
        metrics = run_scene(scene_with(scene, overrides), model=spec.search_model, library=library, ci=False).metrics
        runs.append(objective(metrics, cell.width_m))
        return runs[-1]

    search_budget, _ = split_budget(spec.budget)
    result = cmaes_search(lambda u: -simulate(u)[0], space.size, search_budget,
                          seed=int(cma_seq.generate_state(1)[0]) % CMA_SEED_RANGE, x0=space.scene_unit(scene))
    rescore_budget = spec.budget - result.evaluations
    kept = [Leader(x) for x in leaders(result, max(1, min(LEADERS, rescore_budget // 2)))]
    if rescore_budget >= 2 * len(kept):
        for k in range(rescore_budget):
            leader = kept[k % len(kept)]
            cost, cv, se = simulate(leader.x)
            leader.rewards.append(-cost)
            leader.cvs.append(cv)
            leader.cv_ses.append(se)
        best = max(kept, key=lambda leader: leader.mean_reward)
    else:  # too small a budget to re-score: the belief is the search's own best evaluation
        i = int(np.argmax(result.history))
        best = Leader(result.best_x, [result.best_reward], [runs[i][1]], [runs[i][2]])
    cv_search, cv_search_se = best.cv_belief()

    verify_scene = scene_with(scene, space.overrides(best.x) | {"sim.seed": int(verify_seq.generate_state(1)[0])})
    pooled = pool_runs(verify_scene, spec.verify_runs, model=spec.verify_model, library=library)
    reference = reference_from(verify_scene, pooled)
    cv, cv_se = reference.at_target.cv_percent, reference.at_target.standard_error_percent
    agree = None
    if cv is not None and cv_se is not None and cv_search_se is not None:
        agree = abs(cv - cv_search) <= 2.0 * math.hypot(cv_se, cv_search_se)
    row = {"fertilizer": cell.fertilizer, "width_m": cell.width_m, "driving": spec.driving,
           **space.values(best.x),
           "cv_percent": cv, "cv_standard_error_percent": cv_se,
           "effective_swath_m": reference.effective_swath_m, "cv_search_percent": cv_search,
           "simulations": len(runs) + spec.verify_runs, "wall_s": time.perf_counter() - started}
    detail = {
        "key": cell.key,
        "unit_settings": [float(v) for v in best.x],
        "cv_search_standard_error_percent": cv_search_se,
        "search_evaluations": result.evaluations,
        "rescores": len(best.rewards) if rescore_budget >= 2 * len(kept) else 0,
        "search_agrees_within_2se": agree,
        "meets_threshold": cv is not None and cv <= scene.pattern.cv_threshold_percent,
        "verification": {"model": pooled.model, "granules": pooled.granules, "replicates": pooled.replicates,
                         "cv_raw_percent": reference.at_target.raw_percent,
                         "effective_swath_interval_m": list(reference.effective_swath_interval_m),
                         "wall_s": pooled.wall_s},
        "trays": {"center_m": reference.trays.center_m.tolist(), "mass_kg": reference.trays.mass_kg.tolist()},
        "cv_curve": {"bout_width_m": reference.widths_m.tolist(),
                     "cv_percent": [None if not np.isfinite(v) else float(v) for v in reference.cv_percent]},
    }
    return {"row": row, "detail": detail}
