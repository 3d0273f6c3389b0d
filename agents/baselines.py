"""Black-box baselines for SpinnerDesign: random search, grid search, CMA-ES and Optuna's TPE.

Each search maximises the env's reward over the unit action box [-1, 1]^A with a
budget of simulations (one env step = one simulation, counted by the env's
`SimulationCounter`). Scoring is honest, so that what a search believes is what fresh
granule samples give (`search_job`):

* every evaluation runs on a fresh granule sample (its own reset seed), so a search
  cannot tune itself to the luck of one sample;
* the search itself gets `1 - RESCORE_FRACTION` of the budget; the rest (and whatever
  the search leaves unspent) re-scores its leaders (the best `LEADERS` distinct points,
  fewer when that leaves under two re-scores each) on fresh samples, and the leader with
  the best mean re-scored reward wins. Its belief (`search_best_cv_percent`, with a
  standard error from the spread of its re-scores) rests on those re-scores only,
  never on the single lucky evaluation that made it a leader.

The chosen settings are then scored like every other method (`evaluation.score_action`).

* random: points drawn uniformly in the box.
* grid: the full grid with n = floor(budget^(1/A)) points per axis (ends included),
  e.g. 12 x 12 = 144 points for A = 2 and a search budget of 150.
* cmaes: `cma` (Hansen's CMA-ES) bounded to the box (its BoundTransform), started at
  the centre with sigma0 = 0.5 (a quarter of the box width); when it stops before the
  budget is spent (flat fitness, tolerances) it restarts from a uniform random point
  with the rest of the budget. Generations are cut to fit the budget exactly.
* optuna: Optuna's TPE sampler (multivariate, seeded, its defaults otherwise: the first
  10 trials uniform at random), one trial per simulation through the ask-and-tell interface,
  in-memory storage, Optuna's own logging silenced while it runs.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from spreadgym.agents.evaluation import SEARCH_SEED, WORST_CV_PERCENT, EvalContext, Row, score_action
from spreadgym.envs.vector import step_designs
from spreadgym.errors import SpreadgymError

DEFAULT_BUDGET = 200
CMA_SIGMA0 = 0.5
RESCORE_FRACTION = 0.25  # of the budget spent re-scoring the leaders on fresh samples
LEADERS = 4  # distinct best points re-scored
RANDOM_BATCH = 64  # random search's points per batch

Objective = Callable[[np.ndarray], float]  # unit action -> reward (to maximise)
Objectives = Callable[[list], list]  # unit actions -> their rewards, evaluated together (one batch)


@dataclass
class SearchResult:
    best_x: np.ndarray
    best_reward: float
    evaluations: int
    history: list = field(default_factory=list)  # reward of each evaluation, in order
    points: list = field(default_factory=list)  # the point of each evaluation, in order


class _Tracker:
    """Wraps an objective: counts calls, refuses to go over the budget, keeps the best."""

    def __init__(self, objective: Objective, dim: int, budget: int, many: Optional[Objectives] = None):
        self.objective = objective
        self.many = many or (lambda xs: [objective(x) for x in xs])
        self.dim = dim
        self.budget = int(budget)
        self.best_x = np.zeros(dim)
        self.best_reward = -math.inf
        self.history: list[float] = []
        self.points: list[np.ndarray] = []

    @property
    def left(self) -> int:
        return self.budget - len(self.history)

    def __call__(self, x) -> float:
        return self.batch([x])[0]

    def batch(self, xs) -> list[float]:
        """The rewards of the points `xs`, evaluated together (`many`), in order."""
        if self.left < len(xs):
            raise RuntimeError("search went over its budget")  # a bug in a search, not bad input
        xs = [np.clip(np.asarray(x, dtype=float).reshape(self.dim), -1.0, 1.0) for x in xs]
        rewards = [float(r) for r in self.many(xs)]
        for x, reward in zip(xs, rewards):
            self.history.append(reward)
            self.points.append(x.copy())
            if reward > self.best_reward:
                self.best_reward, self.best_x = reward, x.copy()
        return rewards

    def result(self) -> SearchResult:
        return SearchResult(self.best_x, self.best_reward, len(self.history), self.history, self.points)


def _check_budget(budget: int) -> int:
    if int(budget) < 1:
        raise SpreadgymError(f"budget must be at least 1 simulation, got {budget}")
    return int(budget)


def random_search(objective: Objective, dim: int, budget: int = DEFAULT_BUDGET, seed: int = 0,
                  many: Optional[Objectives] = None) -> SearchResult:
    """Uniform points, evaluated in batches of RANDOM_BATCH (the same points as one at a time)."""
    track = _Tracker(objective, dim, _check_budget(budget), many)
    rng = np.random.default_rng(seed)
    while track.left > 0:
        track.batch(list(rng.uniform(-1.0, 1.0, (min(RANDOM_BATCH, track.left), dim))))
    return track.result()


def grid_points(dim: int, budget: int) -> np.ndarray:
    """The grid of `grid_search`: n = floor(budget^(1/dim)) points per axis (the centre if n = 1)."""
    n = int(math.floor(budget ** (1.0 / dim) + 1e-9))
    if n <= 1:
        return np.zeros((1, dim))
    axis = np.linspace(-1.0, 1.0, n)
    mesh = np.meshgrid(*([axis] * dim), indexing="ij")
    return np.stack([m.reshape(-1) for m in mesh], axis=1)


def grid_search(objective: Objective, dim: int, budget: int = DEFAULT_BUDGET, seed: int = 0,
                many: Optional[Objectives] = None) -> SearchResult:
    track = _Tracker(objective, dim, _check_budget(budget), many)
    track.batch(list(grid_points(dim, budget)))
    return track.result()


def cmaes_search(objective: Objective, dim: int, budget: int = DEFAULT_BUDGET, seed: int = 0,
                 sigma0: float = CMA_SIGMA0, x0: Optional[np.ndarray] = None,
                 many: Optional[Objectives] = None) -> SearchResult:
    """CMA-ES; each generation (population) is evaluated as one batch."""
    import cma

    track = _Tracker(objective, dim, _check_budget(budget), many)
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
                track.batch(xs[: track.left])
                break
            es.tell(xs, [-reward for reward in track.batch(xs)])
        restart += 1
        start = rng.uniform(-1.0, 1.0, dim)
    return track.result()


def optuna_search(objective: Objective, dim: int, budget: int = DEFAULT_BUDGET, seed: int = 0,
                  many: Optional[Objectives] = None) -> SearchResult:
    """Optuna's TPE over the box: a Parzen model of the good and the bad trials proposes the
    next point; deterministic for a given seed (sequential trials, seeded sampler: each
    trial waits for the last, so `many` is not used)."""
    import optuna

    track = _Tracker(objective, dim, _check_budget(budget))
    space = {f"x{i}": optuna.distributions.FloatDistribution(-1.0, 1.0) for i in range(dim)}
    verbosity = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)  # no line per trial
    try:
        sampler = optuna.samplers.TPESampler(seed=int(seed), multivariate=True)
        study = optuna.create_study(direction="maximize", sampler=sampler)  # in-memory storage
        while track.left > 0:
            trial = study.ask(space)
            study.tell(trial, track([trial.params[name] for name in space]))
    finally:
        optuna.logging.set_verbosity(verbosity)
    return track.result()


SEARCHES = {"random": random_search, "grid": grid_search, "cmaes": cmaes_search, "optuna": optuna_search}
METHOD_TITLES = {"published": "published settings", "centre": "centre action", "random-action": "random action",
                 "random": "random search", "grid": "grid search", "cmaes": "CMA-ES", "optuna": "Optuna TPE"}
RANDOM_ACTION_SEED = 30_000


@dataclass
class Leader:
    """A point the search kept, with its rewards and CVs on fresh re-scoring samples."""

    x: np.ndarray
    rewards: list = field(default_factory=list)
    cvs: list = field(default_factory=list)  # CV at target (%); a run where nothing landed counts 100 %
    cv_ses: list = field(default_factory=list)  # each re-score's own standard error of the CV (pp)

    @property
    def mean_reward(self) -> float:
        return float(np.mean(self.rewards)) if self.rewards else -math.inf

    def cv_belief(self) -> tuple[Optional[float], Optional[float]]:
        """Mean CV of the re-scores and its standard error (from each run's own standard error,
        which rests on its replicates: steadier than the spread of a few re-scores)."""
        if not self.cvs:
            return None, None
        ses = [se for se in self.cv_ses if se is not None]
        se = float(math.sqrt(sum(v * v for v in ses)) / len(ses)) if len(ses) == len(self.cvs) else None
        return float(np.mean(self.cvs)), se


def split_budget(budget: int) -> tuple[int, int]:
    """(simulations for the search, simulations for re-scoring its leaders)."""
    rescore = int(round(RESCORE_FRACTION * budget))
    if rescore < 2:  # too small to re-score anything: the search takes it all
        return budget, 0
    return budget - rescore, rescore


def leaders(result: SearchResult, count: int = LEADERS) -> list[np.ndarray]:
    """The `count` best distinct points of a search, best first."""
    order = np.argsort(-np.asarray(result.history, dtype=float), kind="stable")
    chosen: list[np.ndarray] = []
    for i in order:
        x = result.points[i]
        if not any(np.array_equal(x, c) for c in chosen):
            chosen.append(x)
        if len(chosen) == count:
            break
    return chosen


def evaluation_seed(ctx: EvalContext, evaluation: int) -> int:
    """Reset seed of a search's `evaluation`-th simulation on job `ctx` (a fresh sample each)."""
    return int(np.random.SeedSequence([SEARCH_SEED, ctx.index, evaluation]).generate_state(1)[0])


def search_job(env, ctx: EvalContext, method: str, budget: int = DEFAULT_BUDGET, seed: int = 0) -> tuple:
    """Run one search on one job and re-score its leaders; returns (Leader, simulations, seconds)."""
    if method not in SEARCHES:
        raise SpreadgymError(f"unknown baseline {method!r}; known: {', '.join(SEARCHES)}")
    started = time.perf_counter()
    before = env.simulations
    counter = iter(range(budget))

    def simulate(xs: list) -> list[tuple[float, float, Optional[float]]]:
        """(reward, CV %, its standard error) of each point, each on a fresh sample, as one batch."""
        resets = [(evaluation_seed(ctx, next(counter)), ctx.options()) for _ in xs]
        found = []
        for _, reward, _, _, info in step_designs(env, resets, [np.asarray(x, dtype=np.float64) for x in xs]):
            cv, se = info["metrics"].get("cv_percent_at_target"), info["metrics"].get("cv_standard_error_percent")
            found.append((float(reward), (WORST_CV_PERCENT if cv is None else float(cv)), se))
        return found

    search_budget, _ = split_budget(_check_budget(budget))
    result = SEARCHES[method](lambda x: simulate([x])[0][0], env.action_space.shape[0], search_budget,
                              seed=seed + ctx.index, many=lambda xs: [r[0] for r in simulate(xs)])
    rescore_budget = budget - result.evaluations  # what the search left (a grid may leave more)
    kept = [Leader(x) for x in leaders(result, max(1, min(LEADERS, rescore_budget // 2)))]
    rescores = rescore_budget if budget >= 2 * len(kept) + result.evaluations else 0
    for k, (reward, cv, se) in enumerate(simulate([kept[k % len(kept)].x for k in range(rescores)])):
        leader = kept[k % len(kept)]
        leader.rewards.append(reward)
        leader.cvs.append(cv)
        leader.cv_ses.append(se)
    if kept[0].rewards:
        best = max(kept, key=lambda leader: leader.mean_reward)
    else:  # nothing re-scored: the belief is the search's own best evaluation
        best = Leader(result.best_x, [result.best_reward])
    used = env.simulations - before
    if used != result.evaluations + sum(len(k.rewards) for k in kept) or used > budget:
        raise RuntimeError(f"{method}: accounting mismatch ({used} steps, {result.evaluations} evaluations)")
    return best, used, time.perf_counter() - started


ACTION_METHODS = ("published", "centre", "random-action")
"""Methods that decide without simulating: the scene's own settings, the centre of the
action box, a uniformly random action (seeded by the run's seed and the job)."""


def fixed_action(env, ctx: EvalContext, method: str, seed: int) -> np.ndarray:
    """The action of a method of ACTION_METHODS on job `ctx` in run `seed`."""
    from spreadgym.agents.evaluation import published_action

    if method == "published":
        return published_action(env)
    if method == "centre":
        return np.zeros(env.action_space.shape)
    rng = np.random.default_rng([RANDOM_ACTION_SEED, int(seed), ctx.index])
    return rng.uniform(-1.0, 1.0, env.action_space.shape)


def run_baseline(env, ctx: EvalContext, method: str, budget: int = DEFAULT_BUDGET, seed: int = 0,
                 episodes: int = 1, first_episode: int = 0) -> list[Row]:
    """Search (or take a fixed action) and score the result: one Row per episode, scored on
    episodes `first_episode`, ... (their scoring samples, the same for every method)."""
    if method in ACTION_METHODS:
        action, used, decide_s, extra = fixed_action(env, ctx, method, seed), 0, 0.0, {}
    else:
        best, used, decide_s = search_job(env, ctx, method, budget, seed)
        action = best.x
        cv, cv_se = best.cv_belief()
        extra = {"search_best_reward": best.mean_reward, "search_best_cv_percent": cv,
                 "search_best_cv_se_percent": cv_se, "search_rescores": len(best.cvs)}  # 0: none re-scored
    rows = []
    for episode in range(first_episode, first_episode + episodes):
        row = score_action(env, ctx, action, method, episode=episode, search_simulations=used,
                           decide_s=decide_s)
        row.extra.update(extra)
        rows.append(row)
    return rows
