"""The RL benchmark's protocol (docs/benchmark.md): which methods run on which rung, at what
budget and how many seeds, how every run is scored on the held-out jobs, how scores are
normalised per job and aggregated.

* **Jobs**: each rung's held-out evaluation jobs (its env config's `evaluation` section,
  disjoint from the training contexts, checked when the env is built).
* **Runs**: a method's run `s` (a training seed for PPO and SAC, the search seed for the
  searches, the draw of the random action) is scored on the scoring episodes
  `s * EPISODES ... s * EPISODES + EPISODES - 1` of every job: the same granule samples
  (and, on the robust rung, the same hidden batches) for every method, fresh ones per run.
* **Score**: the env's reward (what the agents optimise), normalised per job:
  0 = the mean reward of a uniformly random action (RANDOM_ACTIONS of them, each on its own
  sample), 1 = the best known setting, CMA-ES at a generous REFERENCE_BUDGET simulations
  with the searches' honest re-scoring, scored on REFERENCE_EPISODES samples of its own.
  The CV at the target is reported beside it, not normalised.
* **Aggregate**: `rliable` (Agarwal et al., NeurIPS 2021): the interquartile mean over all
  (run, job) scores with a 95 % stratified bootstrap interval (runs resampled within each
  job), the mean, and performance profiles.

Results are kept per (rung, method, run) as JSON under the benchmark folder, written whole
or not at all, so an interrupted benchmark resumes where it stopped (`python -m
spreadgym.agents.benchmark` runs parts of it; `spreadgym bench --only rl-benchmark` all).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from spreadgym.agents.baselines import ACTION_METHODS, SEARCHES, run_baseline, search_job
from spreadgym.agents.evaluation import EvalContext, Row, evaluation_set, make_env, run_policy, score_action
from spreadgym.errors import SpreadgymError

EPISODES = 2  # scoring episodes per job and run
SEARCH_BUDGET = 100  # simulations per job for random search, CMA-ES and TPE (half the compare default: CPU)
TRAIN_STEPS = 15_000  # env steps (= simulations) of each PPO and SAC run
TRAIN_GRANULES = 1000  # granules per training simulation (scoring uses the env default, 2048)
TRAIN_SETTINGS = {  # on top of configs/agents/<algo>.yaml: one env process per run (the shipped 2 x 128 rollout)
    "ppo": {"n_envs": 1, "n_steps": 256, "env_kwargs": {"granules": TRAIN_GRANULES}},
    "sac": {"n_envs": 1, "gradient_steps": 1, "env_kwargs": {"granules": TRAIN_GRANULES}},
}
REFERENCE_BUDGET = 500  # CMA-ES simulations per job for the best known setting (5 x the searches')
REFERENCE_EPISODES = 8  # scoring samples of the best known setting
RANDOM_ACTIONS = 32  # random actions whose mean reward is a job's 0
REFERENCE_SEED = 7
REFERENCE_FIRST_EPISODE = 900  # the references' scoring episodes: none of a run's
RANDOM_FIRST_EPISODE = 500
BOOTSTRAP_REPS = 2000  # rliable's stratified bootstrap resamples (its default for profiles)
PROFILE_TAUS = np.linspace(-0.25, 1.25, 61)


@dataclass(frozen=True)
class Rung:
    """One rung of the ladder: its env, the methods run on it and their runs (seeds)."""

    key: str
    env_id: str
    seeds: int
    methods: tuple


RUNGS = {
    "design": Rung("design", "spreadgym/SpinnerDesign-v1", 5,
                   ("random-action", "centre", "published", "random", "cmaes", "optuna", "ppo", "sac")),
    "pitch": Rung("pitch", "spreadgym/SpinnerDesignPitch-v1", 3, ("random-action", "cmaes", "ppo")),
    "twin": Rung("twin", "spreadgym/SpinnerDesignTwin-v1", 3, ("random-action", "cmaes", "ppo")),
    "wind": Rung("wind", "spreadgym/SpinnerDesignWind-v1", 3, ("random-action", "cmaes", "ppo")),
    "plates": Rung("plates", "spreadgym/SpinnerDesignPlates-v1", 3, ("random-action", "cmaes", "ppo")),
    "robust": Rung("robust", "spreadgym/SpinnerDesignRobust-v1", 3, ("random-action", "cmaes", "ppo", "ppo-exact")),
}
TRAINED = ("ppo", "sac")
EXACT_POLICY = {"ppo-exact": ("design", "ppo")}
"""Policies trained on another rung and scored on this one: PPO trained on exact properties
(the first rung), scored on the robust rung's hidden batches."""
TITLES = {"random-action": "random action", "centre": "centre action", "published": "published settings",
          "random": "random search", "cmaes": "CMA-ES", "optuna": "Optuna TPE", "ppo": "PPO", "sac": "SAC",
          "ppo-exact": "PPO trained on exact properties"}


def runs_of(rung: Rung, method: str) -> int:
    """Runs of `method` on `rung`: its seeds, or as many as the policies trained elsewhere."""
    if method in EXACT_POLICY:
        return RUNGS[EXACT_POLICY[method][0]].seeds
    return rung.seeds


def budget_of(method: str) -> dict:
    """What deciding costs a method: simulations per job, and training simulations per run."""
    if method in ACTION_METHODS:
        return {"decide_simulations": 0, "training_simulations": 0, "training_granules": None}
    if method in SEARCHES:
        return {"decide_simulations": SEARCH_BUDGET, "training_simulations": 0, "training_granules": None}
    return {"decide_simulations": 0, "training_simulations": TRAIN_STEPS, "training_granules": TRAIN_GRANULES}


# -- files -----------------------------------------------------------------------------------

REFERENCES_FILE = "benchmark_references.yaml"
"""Each v1 design task's per-job references (configs/), written by `spreadgym bench --only
rl-benchmark` when every rung's are complete; `spreadgym compare` normalises with them."""


def shipped_references(env_id: str) -> Optional[dict]:
    """The shipped references of `env_id` (any spelling), or None."""
    from spreadgym.agents.evaluation import canonical_env_id
    from spreadgym.config.resources import config_dir, read_yaml

    path = config_dir() / REFERENCES_FILE
    if not path.is_file():
        return None
    return (read_yaml(path) or {}).get(canonical_env_id(env_id))


def write_json(path: Path, payload) -> Path:
    """Write `payload` whole or not at all (a temporary file renamed into place)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(payload, indent=1, default=float), encoding="utf-8")
    os.replace(tmp, path)
    return path


def read_json(path: Path):
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def score_path(out: Path, rung: Rung, method: str, seed: int) -> Path:
    return out / rung.key / "scores" / f"{method}-seed{seed}.json"


def policy_dir(out: Path, rung_key: str, algo: str, seed: int) -> Path:
    return out / rung_key / algo / f"seed{seed}"


def method_policy_dir(out: Path, rung: Rung, method: str, seed: int) -> Optional[Path]:
    """The run folder whose policy `method` scores on `rung` (its own training, or the exact
    properties' for EXACT_POLICY), or None for a method that is no trained policy."""
    if method not in TRAINED and method not in EXACT_POLICY:
        return None
    source, algo = EXACT_POLICY.get(method, (rung.key, method))
    return policy_dir(out, source, algo, seed)


# -- work ------------------------------------------------------------------------------------

def rung_env(rung: Rung):
    """The rung's env at its scoring settings (default granules), counting simulations."""
    return make_env(rung.env_id, {})


def trained_record(folder: Path) -> Optional[dict]:
    """The `trained` record of a run folder trained to its end (`stopped: done`), else None:
    a run stopped by Ctrl-C or its time limit also writes model.zip, and is resumed, not scored."""
    from spreadgym.agents.run_config import read_config

    config = folder / "config.yaml"
    if not ((folder / "model.zip").is_file() and config.is_file()):
        return None
    record = read_config(config).get("trained") or {}
    return record if record.get("stopped") == "done" else None


def train_run(out: Path, rung: Rung, algo: str, seed: int, log=print) -> Path:
    """Train (or resume, or find done) one PPO/SAC run of `rung`; returns its folder."""
    from spreadgym.agents.training import train

    folder = policy_dir(out, rung.key, algo, seed)
    if trained_record(folder) is not None:
        return folder
    settings = TRAIN_SETTINGS[algo]
    overrides = {key: value for key, value in settings.items() if key != "env_kwargs"}
    overrides.update({f"env_kwargs.{k}": v for k, v in settings["env_kwargs"].items()})
    train(algo, folder, overrides=overrides, env_id=rung.env_id, timesteps=TRAIN_STEPS, seed=seed, log=log)
    return folder


def score_run(out: Path, rung: Rung, method: str, seed: int, env=None, jobs=None) -> dict:
    """Score run `seed` of `method` on `rung`'s held-out jobs (cached in the benchmark folder)."""
    path = score_path(out, rung, method, seed)
    done = read_json(path)
    trained = None
    folder = method_policy_dir(out, rung, method, seed)
    if folder is not None:
        trained = trained_record(folder)
        if trained is None:
            raise SpreadgymError(f"{method} seed {seed} of {rung.key}: {folder} holds no policy trained to its end "
                                 "(train it first: the benchmark's train part resumes it)")
    if done is not None and (trained is None or done.get("train") == trained):  # a score of this very policy
        return done
    env = env or rung_env(rung)
    jobs = jobs or evaluation_set(env=env)
    started = time.perf_counter()
    first = seed * EPISODES
    rows: list[Row] = []
    train = None
    if trained is not None:
        from spreadgym.agents.training import load_policy

        policy = load_policy(folder / "model.zip")
        train = trained  # steps reached, wall time
        for ctx in jobs:
            for episode in range(first, first + EPISODES):
                rows.append(run_policy(env, ctx, policy.act, method, episode))
    else:
        for ctx in jobs:
            rows.extend(run_baseline(env, ctx, method, SEARCH_BUDGET, seed, EPISODES, first_episode=first))
    payload = {"rung": rung.key, "env": rung.env_id, "method": method, "seed": seed, "episodes": EPISODES,
               **budget_of(method), "train": train, "wall_s": time.perf_counter() - started,
               "rows": [r.as_dict() for r in rows]}
    write_json(path, payload)
    return payload


def reference(out: Path, rung: Rung, env=None, jobs=None, progress=None) -> dict:
    """Each job's 0 and 1 (module docstring), cached as `<rung>/reference.json`, job by job."""
    path = out / rung.key / "reference.json"
    found = read_json(path) or {"env": rung.env_id, "budget": REFERENCE_BUDGET, "episodes": REFERENCE_EPISODES,
                                "random_actions": RANDOM_ACTIONS, "seed": REFERENCE_SEED, "jobs": {}}
    env = env or rung_env(rung)
    jobs = jobs or evaluation_set(env=env)
    for ctx in jobs:
        if ctx.label in found["jobs"]:
            continue
        started = time.perf_counter()
        rng = np.random.default_rng([REFERENCE_SEED, ctx.index])
        randoms = [score_action(env, ctx, rng.uniform(-1.0, 1.0, env.action_space.shape), "reference-random",
                                episode=RANDOM_FIRST_EPISODE + k).reward for k in range(RANDOM_ACTIONS)]
        best, used, _ = search_job(env, ctx, "cmaes", REFERENCE_BUDGET, REFERENCE_SEED)
        scored = [score_action(env, ctx, best.x, "reference-best", episode=REFERENCE_FIRST_EPISODE + k)
                  for k in range(REFERENCE_EPISODES)]
        found["jobs"][ctx.label] = {
            "context": ctx.as_dict(), "random_reward": float(np.mean(randoms)),
            "random_reward_se": float(np.std(randoms, ddof=1) / math.sqrt(len(randoms))),
            "best_reward": float(np.mean([r.reward for r in scored])),
            "best_reward_se": float(np.std([r.reward for r in scored], ddof=1) / math.sqrt(len(scored))),
            "best_cv_percent": float(np.mean([100.0 if r.cv_percent is None else r.cv_percent for r in scored])),
            "best_action": [float(a) for a in best.x], "best_settings": scored[0].settings,
            "search_simulations": int(used), "wall_s": time.perf_counter() - started}
        write_json(path, found)
        if progress:
            progress(f"{rung.key} reference {ctx.label}: random {found['jobs'][ctx.label]['random_reward']:.3f}, "
                     f"best {found['jobs'][ctx.label]['best_reward']:.3f}")
    return found


# -- aggregation -----------------------------------------------------------------------------

def score_matrix(runs: Sequence[dict], references: dict, key: str = "normalised") -> np.ndarray:
    """(runs x jobs) of one method: each run's mean over its episodes of the normalised
    reward (`key="normalised"`), the reward, or the CV at the target (`"cv"`), jobs in the
    references' order."""
    labels = list(references["jobs"])
    out = np.full((len(runs), len(labels)), np.nan)
    for i, run in enumerate(runs):
        by_job: dict[str, list] = {}
        for row in run["rows"]:
            label = EvalContext(0, row["context"]["fertilizer"], row["context"]["target_swath_m"],
                                row["context"]["spinner_material"], row["context"]["forward_speed_m_s"],
                                tuple(row["context"]["wind_m_s"])).label
            by_job.setdefault(label, []).append(row)
        for j, label in enumerate(labels):
            ref = references["jobs"][label]
            rows = by_job.get(label, [])
            if key == "cv":
                values = [100.0 if r["cv_percent"] is None else r["cv_percent"] for r in rows]
            elif key == "reward":
                values = [r["reward"] for r in rows]
            else:
                values = [normalise(r["reward"], ref["random_reward"], ref["best_reward"]) for r in rows]
            if not values:
                raise SpreadgymError(f"benchmark: run {i} has no episode on the job {label}")
            out[i, j] = float(np.mean(values))
    return out


def normalise(reward: float, random_reward: float, best_reward: float) -> float:
    """0 at the random action's mean reward, 1 at the best known setting's (which must be above it)."""
    span = best_reward - random_reward
    if not span > 0:
        raise SpreadgymError(f"benchmark references: the best known reward {best_reward:.6g} is not above the random "
                             f"action's {random_reward:.6g}; nothing to normalise against")
    return (reward - random_reward) / span


def aggregate(score_dict: dict[str, np.ndarray], reps: int = BOOTSTRAP_REPS, seed: int = 0) -> dict:
    """rliable's interquartile mean, mean and median of each method's (runs x jobs) scores,
    each with its 95 % stratified bootstrap interval: {method: {"iqm": (point, lo, hi), ...}}."""
    from rliable import library as rly
    from rliable import metrics

    funcs = {"iqm": metrics.aggregate_iqm, "mean": metrics.aggregate_mean, "median": metrics.aggregate_median}

    def all_aggregates(scores):
        return np.array([func(scores) for func in funcs.values()])

    found = {}
    for method, scores in score_dict.items():  # each its own resamples: its interval is the same beside any others
        own = method_seed(seed, method)
        with warnings.catch_warnings(), _global_numpy_seed(own):
            warnings.filterwarnings("ignore", "random_state is deprecated", FutureWarning)  # rliable -> arch 7
            points, intervals = rly.get_interval_estimates({method: scores}, all_aggregates, reps=reps,
                                                           random_state=np.random.RandomState(own))
        found[method] = {name: (float(points[method][k]), float(intervals[method][0, k]),
                                float(intervals[method][1, k])) for k, name in enumerate(funcs)}
    return found


def method_seed(seed: int, method: str) -> int:
    """The bootstrap seed of one method's scores: from `seed` and the method's name, so that
    adding, removing or reordering the other methods leaves its interval as it is."""
    return int(np.random.SeedSequence([seed, zlib.crc32(method.encode())]).generate_state(1)[0])


def probability_of_improvement(x: np.ndarray, y: np.ndarray, reps: int = BOOTSTRAP_REPS,
                               seed: int = 0) -> tuple[float, float, float]:
    """rliable's P(X > Y): the chance that a run of X beats a run of Y on a job, averaged over
    the jobs (Mann-Whitney per job; ties count half), with its 95 % stratified bootstrap
    interval: (point, low, high). 0.5 is a tie."""
    from rliable import library as rly
    from rliable import metrics

    with warnings.catch_warnings(), _global_numpy_seed(seed):
        warnings.filterwarnings("ignore", "random_state is deprecated", FutureWarning)
        points, intervals = rly.get_interval_estimates({"x,y": [x, y]}, metrics.probability_of_improvement,
                                                       reps=reps, random_state=np.random.RandomState(seed))
    point, (low, high) = np.ravel(points["x,y"])[0], np.reshape(intervals["x,y"], (2, -1))[:, 0]
    return float(point), float(low), float(high)


def profiles(score_dict: dict[str, np.ndarray], taus=PROFILE_TAUS, reps: int = BOOTSTRAP_REPS) -> tuple:
    """rliable's performance profiles: the share of (run, job) scores above each tau, with 95 % intervals."""
    from rliable import library as rly

    distributions, intervals = {}, {}
    for method, scores in score_dict.items():  # as `aggregate`: each method its own resamples
        with _global_numpy_seed(method_seed(0, method)):
            found, spread = rly.create_performance_profile({method: scores}, taus, reps=reps)
        distributions[method], intervals[method] = found[method], spread[method]
    return distributions, intervals


@contextlib.contextmanager
def _global_numpy_seed(seed: int):
    """numpy's global generator seeded for the block, then restored: rliable's stratified
    bootstrap draws its resamples from it (`np.random.choice`; the `random_state` it takes
    does not reach them), so a seeded call gives the same intervals every time."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def plot_profiles(score_dict: dict[str, np.ndarray], path: Path, titles: Optional[dict] = None) -> Path:
    """The performance profiles of a rung's methods, one curve each with its interval."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    found, intervals = profiles(score_dict)
    fig = Figure(figsize=(6.4, 4.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for method, curve in found.items():
        label = (titles or {}).get(method, method)
        ax.plot(PROFILE_TAUS, curve, label=label)
        ax.fill_between(PROFILE_TAUS, intervals[method][0], intervals[method][1], alpha=0.15)
    ax.set_xlabel("normalised score tau (0: random action, 1: best known setting)")
    ax.set_ylabel("share of (run, job) scores > tau")
    ax.grid(True, color="#e5e5e5")
    ax.legend(fontsize=8, frameon=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def rung_table(out: Path, rung: Rung) -> Optional[tuple[list[dict], dict]]:
    """The rung's rows of the baseline table and its normalised score matrices, or None
    while a reference or run is missing."""
    references = read_json(out / rung.key / "reference.json")
    if references is None:
        return None
    runs = {m: [read_json(score_path(out, rung, m, s)) for s in range(runs_of(rung, m))] for m in rung.methods}
    if any(run is None for found in runs.values() for run in found):
        return None
    matrices = {m: score_matrix(found, references) for m, found in runs.items()}
    stats = aggregate(matrices)
    cv_stats = aggregate({m: score_matrix(found, references, "cv") for m, found in runs.items()})
    rows = []
    for method, found in runs.items():
        budget = budget_of(method)
        trained = [r["train"] for r in found if r.get("train")]
        train_wall = [t.get("wall_s_last_invocation") for t in trained]  # no run resumed
        train_steps = sorted({int(t["num_timesteps"]) for t in trained})  # PPO: whole rollouts, 59 x 256 = 15104
        rows.append({
            "rung": rung.key, "env": rung.env_id, "method": TITLES.get(method, method), "key": method,
            "runs": len(found), "jobs": matrices[method].shape[1], "episodes_per_job": EPISODES,
            "iqm": stats[method]["iqm"][0], "iqm_low": stats[method]["iqm"][1], "iqm_high": stats[method]["iqm"][2],
            "mean": stats[method]["mean"][0], "mean_low": stats[method]["mean"][1],
            "mean_high": stats[method]["mean"][2],
            "cv_iqm_percent": cv_stats[method]["iqm"][0], "cv_iqm_low": cv_stats[method]["iqm"][1],
            "cv_iqm_high": cv_stats[method]["iqm"][2],
            "reward_mean": float(np.mean(score_matrix(found, references, "reward"))),
            "decide_simulations_per_job": budget["decide_simulations"],
            "training_simulations": train_steps[-1] if train_steps else budget["training_simulations"],
            "training_granules": budget["training_granules"],
            "training_wall_s_median": float(np.median(train_wall)) if train_wall else None,
            "decide_wall_s_per_job": float(np.mean([r["wall_s"] for r in found])) / matrices[method].shape[1],
        })
    return rows, matrices


# -- the whole benchmark ---------------------------------------------------------------------

def run_rung(out: Path, rung: Rung, methods: Optional[Sequence[str]] = None, parts=("train", "reference", "score"),
             progress: Callable[[str], None] = print) -> None:
    """Run what `rung` still lacks: training runs, its reference, each method's scored runs."""
    methods = [m for m in rung.methods if methods is None or m in methods]
    if "train" in parts:
        for method in methods:
            for seed in range(rung.seeds if method in TRAINED else 0):
                progress(f"{rung.key}: training {method} seed {seed}")
                train_run(out, rung, method, seed, log=progress)
    env = rung_env(rung)
    jobs = evaluation_set(env=env)
    if "reference" in parts:
        reference(out, rung, env, jobs, progress)
    if "score" in parts:
        for method in methods:
            for seed in range(runs_of(rung, method)):
                folder = method_policy_dir(out, rung, method, seed)
                if folder is not None and trained_record(folder) is None:
                    progress(f"{rung.key}: {method} seed {seed} not trained to its end yet")
                    continue
                progress(f"{rung.key}: scoring {method} seed {seed} (or its score, where it is this policy's)")
                score_run(out, rung, method, seed, env, jobs)


def rung_speed(rung: Rung, designs: int = 32, repeats: int = 3) -> dict:
    """Env steps per second of `rung` at its scoring settings: one env at one thread (one
    core), and its native vector env of `designs` sub-envs (fewer where the landing-point
    budget says so) at every thread spreadgym may use (all cores, same-step autoreset);
    medians of `repeats` interleaved blocks of `designs` random steps, with their ranges."""
    import gymnasium as gym

    from spreadgym import threads
    from spreadgym.config.scene import MAX_GRANULE_COPIES, granule_copies
    from spreadgym.studies.benchmarks import interleaved_rates

    env = gym.make(rung.env_id)
    batch = min(designs, MAX_GRANULE_COPIES // granule_copies(env.unwrapped.task.base_scene))
    venv = gym.make_vec(rung.env_id, num_envs=batch, autoreset_mode="same_step")
    env.reset(seed=0)
    venv.reset(seed=0)
    env.action_space.seed(0)
    venv.action_space.seed(0)

    def one_by_one():
        for _ in range(batch):
            env.step(env.action_space.sample())
            env.reset()

    series = {("one env", 1, 1): one_by_one,
              ("vector env", batch, threads.thread_count()): lambda: venv.step(venv.action_space.sample())}
    rows, _ = interleaved_rates(series, batch, repeats)
    env.close()
    venv.close()
    one, vector = rows
    return {"steps_per_s_one_core": one["designs_per_s"], "steps_per_s_one_core_low": one["designs_per_s_low"],
            "steps_per_s_one_core_high": one["designs_per_s_high"], "steps_per_s_all_cores": vector["designs_per_s"],
            "steps_per_s_all_cores_low": vector["designs_per_s_low"],
            "steps_per_s_all_cores_high": vector["designs_per_s_high"], "cores": vector["threads"],
            "vector_batch": batch}


def benchmark_rows(out: Path, docs: Path, progress: Callable[[str], None] = print, speed_repeats: int = 3,
                   run: bool = True) -> list[dict]:
    """`make bench`, section rl-benchmark: run what the benchmark still lacks (resumable, under
    `out`), then the baseline table, one row per (rung, method), with each rung's steps/s.
    Writes the profiles (`docs/<rung>-profiles.png`), the table (`docs/rl-benchmark.md`) and
    the references `spreadgym compare` normalises with (configs/benchmark_references.yaml) only
    when every rung that runs is complete; otherwise a SpreadgymError lists what is missing."""
    from spreadgym.agents.evaluation import canonical_env_id
    from spreadgym.config.resources import config_dir
    if run:
        for rung in RUNGS.values():
            run_rung(out, rung, progress=progress)
    rows, missing, references = [], [], {}
    for rung in RUNGS.values():
        progress(f"{rung.key}: steps/s")
        speed = rung_speed(rung, repeats=speed_repeats)
        found = rung_table(out, rung)
        if found is None:
            missing.append(rung.key)
            continue
        table, matrices = found
        if {"ppo", "ppo-exact"} <= set(matrices):  # which generalises to the held-out batches
            better = probability_of_improvement(matrices["ppo"], matrices["ppo-exact"])
            for row in table:
                if row["key"] == "ppo":
                    row.update({"p_better_than_exact": better[0], "p_better_low": better[1],
                                "p_better_high": better[2]})
        rows += [{**row, **speed} for row in table]
        plot_profiles(matrices, docs / "rl-benchmark" / f"{rung.key}-profiles.png", TITLES)
        references[canonical_env_id(rung.env_id)] = read_json(out / rung.key / "reference.json")
    if missing:
        raise SpreadgymError(f"rl-benchmark: rungs {', '.join(missing)} are not complete under {out}; "
                             "run the section again (it resumes) and nothing is written until they are")
    import yaml

    with open(config_dir() / REFERENCES_FILE, "w", encoding="utf-8") as handle:
        handle.write("# Per-job references of the benchmark's normalised scores (docs/benchmark.md), written by\n"
                     "# `spreadgym bench --only rl-benchmark`: 0 = random_reward, 1 = best_reward.\n")
        yaml.safe_dump(references, handle, sort_keys=False, width=120)
    (docs / "rl-benchmark.md").write_text(markdown(rows), encoding="utf-8")
    keys = list(dict.fromkeys(key for row in rows for key in row))  # one set of columns for the CSV
    return [{key: row.get(key) for key in keys} for row in rows]


def markdown(rows: list[dict]) -> str:
    """The baseline table as markdown: IQM [95 % CI] of the normalised reward and of the CV."""
    head = ("| rung | method | runs | normalised IQM [95 % CI] | CV IQM (%) [95 % CI] | mean reward | sims to decide "
            "/ job | training sims (granules) | training min (median) | steps/s one core | steps/s all cores |")
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        train = (f"{r['training_simulations']} ({r['training_granules']})" if r["training_simulations"] else "0")
        minutes = f"{r['training_wall_s_median'] / 60:.1f}" if r.get("training_wall_s_median") else "-"
        lines.append(
            f"| {r['rung']} | {r['method']} | {r['runs']} | {r['iqm']:.3f} [{r['iqm_low']:.3f}, {r['iqm_high']:.3f}] "
            f"| {r['cv_iqm_percent']:.2f} [{r['cv_iqm_low']:.2f}, {r['cv_iqm_high']:.2f}] | {r['reward_mean']:.4f} "
            f"| {r['decide_simulations_per_job']} | {train} | {minutes} | {r['steps_per_s_one_core']:.1f} "
            f"| {r['steps_per_s_all_cores']:.1f} |")
    for r in rows:
        if "p_better_than_exact" in r:
            lines.append(f"\n{r['rung']}: P(PPO trained there beats PPO trained on exact properties, on a job) = "
                         f"{r['p_better_than_exact']:.3f} [{r['p_better_low']:.3f}, {r['p_better_high']:.3f}] "
                         "(rliable's probability of improvement, 95 % stratified bootstrap; 0.5 is a tie)")
    return "\n".join(lines) + "\n"


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run parts of the benchmark (background use): `python -m spreadgym.agents.benchmark
    --out runs/benchmark --rungs design --methods cmaes --parts reference score`."""
    parser = argparse.ArgumentParser(prog="python -m spreadgym.agents.benchmark", description=main.__doc__)
    parser.add_argument("--out", type=Path, default=Path("runs/benchmark"))
    parser.add_argument("--rungs", nargs="+", choices=list(RUNGS), default=list(RUNGS))
    parser.add_argument("--methods", nargs="+")
    parser.add_argument("--parts", nargs="+", choices=("train", "reference", "score"),
                        default=["train", "reference", "score"])
    args = parser.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")

    def say(text: str) -> None:
        print(f"{time.strftime('%H:%M:%S')} {text}", file=sys.stderr, flush=True)

    for key in args.rungs:
        run_rung(args.out, RUNGS[key], args.methods, args.parts, say)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
