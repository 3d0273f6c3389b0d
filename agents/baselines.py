"""Black-box baselines for SpinnerDesign: random search, grid search and CMA-ES.

Each search maximises the env's reward over the unit action box [-1, 1]^A with a
budget of simulations (one env step = one simulation, counted by the env's
`SimulationCounter`). The searches step one job repeatedly without a reset: the env
then re-runs the same job with the same granule sample (common random numbers), so
the searches compare settings without sampling noise between them. The chosen
settings are then scored like every other method (`evaluation.score_action`), on a
different granule sample.

* random: `budget` points drawn uniformly in the box.
* grid: the full grid with n = floor(budget^(1/A)) points per axis (ends included),
  e.g. 14 x 14 = 196 points for A = 2 and a budget of 200.
* cmaes: `cma` (Hansen's CMA-ES) bounded to the box (its BoundTransform), started at
  the centre with sigma0 = 0.5 (a quarter of the box width); when it stops before the
  budget is spent (flat fitness, tolerances) it restarts from a uniform random point
  with the rest of the budget. Generations are cut to fit the budget exactly.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from spreadgym.agents.evaluation import EvalContext, Row, score_action
from spreadgym.errors import SpreadgymError

DEFAULT_BUDGET = 200
CMA_SIGMA0 = 0.5

Objective = Callable[[np.ndarray], float]  # unit action -> reward (to maximise)


@dataclass
class SearchResult:
    best_x: np.ndarray
    best_reward: float
    evaluations: int
    history: list = field(default_factory=list)  # reward of each evaluation, in order
    best_metrics: dict = field(default_factory=dict)  # metrics of the best run (search_job only)


class _Tracker:
    """Wraps an objective: counts calls, refuses to go over the budget, keeps the best."""

    def __init__(self, objective: Objective, dim: int, budget: int):
        self.objective = objective
        self.dim = dim
        self.budget = int(budget)
        self.best_x = np.zeros(dim)
        self.best_reward = -math.inf
        self.history: list[float] = []

    @property
    def left(self) -> int:
        return self.budget - len(self.history)

    def __call__(self, x) -> float:
        if self.left <= 0:
            raise RuntimeError("search went over its budget")  # a bug in a search, not bad input
        x = np.clip(np.asarray(x, dtype=float).reshape(self.dim), -1.0, 1.0)
        reward = float(self.objective(x))
        self.history.append(reward)
        if reward > self.best_reward:
            self.best_reward, self.best_x = reward, x.copy()
        return reward

    def result(self) -> SearchResult:
        return SearchResult(self.best_x, self.best_reward, len(self.history), self.history)


def _check_budget(budget: int) -> int:
    if int(budget) < 1:
        raise SpreadgymError(f"budget must be at least 1 simulation, got {budget}")
    return int(budget)


def random_search(objective: Objective, dim: int, budget: int = DEFAULT_BUDGET, seed: int = 0) -> SearchResult:
    track = _Tracker(objective, dim, _check_budget(budget))
    rng = np.random.default_rng(seed)
    while track.left > 0:
        track(rng.uniform(-1.0, 1.0, dim))
    return track.result()


def grid_points(dim: int, budget: int) -> np.ndarray:
    """The grid of `grid_search`: n = floor(budget^(1/dim)) points per axis (the centre if n = 1)."""
    n = int(math.floor(budget ** (1.0 / dim) + 1e-9))
    if n <= 1:
        return np.zeros((1, dim))
    axis = np.linspace(-1.0, 1.0, n)
    mesh = np.meshgrid(*([axis] * dim), indexing="ij")
    return np.stack([m.reshape(-1) for m in mesh], axis=1)


def grid_search(objective: Objective, dim: int, budget: int = DEFAULT_BUDGET, seed: int = 0) -> SearchResult:
    track = _Tracker(objective, dim, _check_budget(budget))
    for x in grid_points(dim, budget):
        track(x)
    return track.result()


def cmaes_search(objective: Objective, dim: int, budget: int = DEFAULT_BUDGET, seed: int = 0,
                 sigma0: float = CMA_SIGMA0, x0: Optional[np.ndarray] = None) -> SearchResult:
    import cma

    track = _Tracker(objective, dim, _check_budget(budget))
    rng = np.random.default_rng(seed)
    start = np.zeros(dim) if x0 is None else np.clip(np.asarray(x0, dtype=float).reshape(dim), -1, 1)
    restart = 0
    while track.left > 0:
        opts = {"bounds": [-1.0, 1.0], "seed": int(seed) * 1000 + restart + 1, "verbose": -9,
                "maxfevals": track.left}
        if dim == 1:  # cma wants at least two dimensions for its defaults; pad with a dummy axis
            raise SpreadgymError("CMA-ES needs at least two action entries")
        es = cma.CMAEvolutionStrategy(start.tolist(), sigma0, opts)
        while track.left > 0 and not es.stop():
            xs = es.ask()
            if len(xs) > track.left:  # last, partial generation: evaluate what the budget allows
                for x in xs[: track.left]:
                    track(x)
                break
            es.tell(xs, [-track(x) for x in xs])
        restart += 1
        start = rng.uniform(-1.0, 1.0, dim)
    return track.result()


SEARCHES = {"random": random_search, "grid": grid_search, "cmaes": cmaes_search}
METHOD_TITLES = {"published": "published settings", "random": "random search", "grid": "grid search",
                 "cmaes": "CMA-ES"}


def search_job(env, ctx: EvalContext, method: str, budget: int = DEFAULT_BUDGET, seed: int = 0) -> tuple:
    """Run one search on one job (its search seed); returns (SearchResult, simulations, seconds)."""
    if method not in SEARCHES:
        raise SpreadgymError(f"unknown baseline {method!r}; known: {', '.join(SEARCHES)}")
    started = time.perf_counter()
    before = env.simulations
    env.reset(seed=ctx.search_seed, options=ctx.options())
    best: dict = {"reward": -math.inf}

    def objective(x: np.ndarray) -> float:
        _, reward, _, _, info = env.step(x)
        if reward > best["reward"]:
            best.update(reward=float(reward), metrics=info["metrics"])
        return float(reward)

    result = SEARCHES[method](objective, env.action_space.shape[0], budget, seed=seed + ctx.index)
    result.best_metrics = best.get("metrics", {})
    used = env.simulations - before
    if used != result.evaluations or used > budget:
        raise RuntimeError(f"{method}: accounting mismatch ({used} steps, {result.evaluations} evaluations)")
    return result, used, time.perf_counter() - started


def run_baseline(env, ctx: EvalContext, method: str, budget: int = DEFAULT_BUDGET, seed: int = 0,
                 episodes: int = 1) -> list[Row]:
    """Search (or take the published settings) and score the result: one Row per episode."""
    from spreadgym.agents.evaluation import published_action

    if method == "published":
        action, used, decide_s, extra = published_action(env), 0, 0.0, {}
    else:
        result, used, decide_s = search_job(env, ctx, method, budget, seed)
        action = result.best_x
        m = result.best_metrics
        extra = {"search_best_reward": result.best_reward,
                 "search_best_cv_percent": m.get("cv_percent_at_target"),
                 "search_best_effective_swath_m": m.get("effective_swath_m")}
    rows = []
    for episode in range(episodes):
        row = score_action(env, ctx, action, method, episode=episode, search_simulations=used,
                           decide_s=decide_s)
        row.extra.update(extra)
        rows.append(row)
    return rows
