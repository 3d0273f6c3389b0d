"""`spreadgym compare`: a trained policy against the published settings, random search,
grid search, CMA-ES and Optuna's TPE on the evaluation set, with every simulation counted."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from spreadgym.cli import arguments

METHODS = ("published", "random", "grid", "cmaes", "optuna")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.agents.baselines import DEFAULT_BUDGET
    from spreadgym.envs.common.config import DESIGN, load_env_config

    parser.add_argument("--model", type=Path, action="append", metavar="DIR/model.zip",
                        help="policy saved by spreadgym train (repeat the flag to compare several)")
    parser.add_argument("--budget", type=arguments.COUNT, default=DEFAULT_BUDGET, metavar="N",
                        help=f"simulations per job for each search (default {DEFAULT_BUDGET})")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS, metavar="METHOD",
                        help=f"baselines to run (default: all of {', '.join(METHODS)})")
    parser.add_argument("--episodes", type=arguments.COUNT, default=1, metavar="N",
                        help="scoring episodes per job, each on another granule sample (default 1)")
    parser.add_argument("--granules", type=arguments.GRANULES, metavar="N",
                        help=f"granules per simulation (default: the env's, {load_env_config(DESIGN).granules})")
    parser.add_argument("--fertilizers", nargs="+", metavar="NAME", help="restrict the evaluation set")
    parser.add_argument("--swaths", nargs="+", type=arguments.real(0.0, 100.0, low_open=True), metavar="M",
                        help="target swaths (default 2 3 4 5)")
    parser.add_argument("--seed", type=arguments.SEED, default=0, help="seed of the searches (default 0)")
    parser.add_argument("--workers", type=arguments.COUNT, default=1, metavar="N",
                        help="processes for the searches (default 1; wall times are per core either way)")
    parser.add_argument("--threads", type=arguments.integer(1, 4096), metavar="N",
                        help="threads in all, shared by the --workers (default: SPREADGYM_THREADS, else every core "
                             "this process may use); each search evaluates its batches on its share")
    arguments.add_device(parser)
    parser.add_argument("--json", action="store_true", help="print the table and rows as JSON")
    parser.add_argument("--out", type=arguments.output_folder, default=Path("out/compare"), metavar="DIR",
                        help="folder for compare.csv/.md/.json and compare.png (default out/compare)")


_ENVS: dict = {}


def _env(env_id: str, env_kwargs: dict):
    from spreadgym.agents.evaluation import make_env

    key = (env_id, repr(sorted(env_kwargs.items())))
    if key not in _ENVS:
        _ENVS[key] = make_env(env_id, env_kwargs)
    return _ENVS[key]


def baseline_job(env_id: str, env_kwargs: dict, ctx, method: str, budget: int, seed: int, episodes: int):
    """One method on one job (runs in a worker process when --workers > 1)."""
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from spreadgym.agents.baselines import run_baseline

    return run_baseline(_env(env_id, env_kwargs), ctx, method, budget, seed, episodes)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from spreadgym.agents import evaluation as ev
    from spreadgym.agents.baselines import METHOD_TITLES
    from spreadgym.agents.commands.evaluate import evaluation_env_kwargs
    from spreadgym.errors import SpreadgymError
    from spreadgym.report import print_json

    if args.budget < 1:
        raise SpreadgymError(f"--budget must be at least 1 simulation, got {args.budget}")
    if args.episodes < 1:
        raise SpreadgymError(f"--episodes must be at least 1, got {args.episodes}")
    if args.workers < 1:
        raise SpreadgymError(f"--workers must be at least 1, got {args.workers}")
    if args.device is not None:
        from spreadgym.device import checked

        checked(args.device, "--device")
        if args.device == "cuda" and args.workers > 1:  # one process drives the GPU: the two never multiply
            raise SpreadgymError("--device cuda: one process drives the GPU; use --workers 1")
    started = time.perf_counter()
    from spreadgym.threads import set_threads, thread_count

    per_worker = max(1, (args.threads or thread_count()) // args.workers)  # the two levels never multiply
    set_threads(per_worker)
    policies = _load_policies(args.model or [])
    env_id = ev.DESIGN_ENV
    train_kwargs = policies[0][1].env_kwargs if policies else {}
    env_kwargs = evaluation_env_kwargs(train_kwargs, args.granules)
    if args.device is not None:
        env_kwargs["device"] = args.device
    env = _env(env_id, env_kwargs)  # checks the kwargs here
    env_kwargs = {**env_kwargs, "granules": env.unwrapped.task.base_scene.sim.granules}  # the count that runs
    jobs = ev.evaluation_set(args.fertilizers, args.swaths)
    from spreadgym.agents.commands.evaluate import _check_jobs

    _check_jobs(env, jobs)
    methods = list(dict.fromkeys(args.methods))
    rows: dict[str, list] = {}
    titles = dict(METHOD_TITLES)
    for name, policy, title in policies:
        titles[name] = title
        rows[name] = []
        for ctx in tqdm(jobs, desc=title, unit="job", file=sys.stderr, disable=None, leave=False):
            for episode in range(args.episodes):
                rows[name].append(ev.run_policy(env, ctx, policy.act, name, episode))
    tasks = [(m, ctx) for m in methods for ctx in jobs]
    for m in methods:
        rows[m] = []
    bar = tqdm(total=len(tasks), desc="baselines", unit="job", file=sys.stderr, disable=None, leave=False)
    if args.workers == 1:
        for m, ctx in tasks:
            bar.set_description(f"{titles[m]}")
            rows[m].extend(baseline_job(env_id, env_kwargs, ctx, m, args.budget, args.seed, args.episodes))
            bar.update()
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("forkserver"),
                                 initializer=set_threads, initargs=(per_worker,)) as pool:
            futures = {pool.submit(baseline_job, env_id, env_kwargs, ctx, m, args.budget, args.seed,
                                   args.episodes): m for m, ctx in tasks}
            for future in as_completed(futures):
                rows[futures[future]].extend(future.result())
                bar.update()
    bar.close()
    for m in rows:
        rows[m].sort(key=lambda r: (r.context["fertilizer"], r.context["target_swath_m"], r.episode))
    order = [name for name, _, _ in policies] + methods
    summaries = []
    for m in order:
        s = ev.summarise(m, rows[m])
        s["method"] = titles.get(m, m)
        s["key"] = m
        summaries.append(s)
    ev.mark_ties(summaries)
    elapsed = time.perf_counter() - started
    written = write_outputs(args.out, summaries, rows, order, titles, args, env_kwargs, elapsed)
    payload = {"budget": args.budget, "episodes": args.episodes, "env": env_id, "env_kwargs": env_kwargs,
               "jobs": [c.as_dict() for c in jobs], "table": summaries,
               "rows": [r.as_dict() for m in order for r in rows[m]], "elapsed_s": elapsed,
               "files": [str(p) for p in written]}
    if args.json:
        print_json(payload)
        return 0
    print(f"{len(jobs)} jobs, search budget {args.budget} simulations per job, "
          f"{env_kwargs['granules']} granules per simulation")
    print(ev.text_table(summaries, ev.SUMMARY_COLUMNS))
    print(f"elapsed {elapsed:.0f} s")
    for path in written:
        print(f"wrote {path}")
    return 0


def _load_policies(paths) -> list:
    """(key, SavedPolicy, title) per --model; all SpinnerDesign, all on the same env kwargs."""
    from spreadgym.agents import evaluation as ev
    from spreadgym.agents.training import load_policy
    from spreadgym.errors import SpreadgymError

    out = []
    for path in paths:
        policy = load_policy(path)
        if policy.env_id != ev.DESIGN_ENV:
            raise SpreadgymError(f"--model {path}: compare needs a {ev.DESIGN_ENV} policy "
                                 f"(the searches set absolute settings), this one is for {policy.env_id}")
        out.append(policy)
    if not out:
        return []
    same = [{k: v for k, v in p.env_kwargs.items() if k != "granules"} for p in out]
    for path, kwargs in zip(paths[1:], same[1:]):
        if kwargs != same[0]:
            raise SpreadgymError(f"--model {path}: trained on other env kwargs ({kwargs}) than {paths[0]} "
                                 f"({same[0]}); compare runs every method on one env")
    algos = [p.algo for p in out]
    result = []
    for policy in out:
        if algos.count(policy.algo) == 1:
            key, title = policy.algo, f"{policy.algo.upper()} policy"
        else:
            run_name = policy.path.parent.name
            key, title = f"{policy.algo}:{run_name}", f"{policy.algo.upper()} policy ({run_name})"
        result.append((key, policy, title))
    return result


def write_outputs(out: Path, summaries, rows, order, titles, args, env_kwargs, elapsed) -> list:
    from spreadgym.agents import evaluation as ev
    from spreadgym.report import print_json

    out.mkdir(parents=True, exist_ok=True)
    written = [ev.write_csv(out / "compare.csv", summaries, ev.SUMMARY_COLUMNS)]
    flat = [ev.flat_row(r) | {"method": titles.get(r.method, r.method)} for m in order for r in rows[m]]
    written.append(ev.write_csv(out / "compare_rows.csv", flat, ev.ROW_COLUMNS))
    md = out / "compare.md"
    granules = env_kwargs["granules"]
    md.write_text(
        f"Evaluation set: {len({(r['fertilizer'], r['target_swath_m']) for r in flat})} jobs; "
        f"search budget {args.budget} simulations per job; {granules} granules per simulation; "
        f"{args.episodes} scoring episode(s) per job; elapsed {elapsed:.0f} s.\n\n"
        + ev.markdown_table(summaries, ev.SUMMARY_COLUMNS) + "\n\nPer job:\n\n"
        + ev.markdown_table(flat, ev.ROW_COLUMNS) + "\n", encoding="utf-8")
    written.append(md)
    with open(out / "compare.json", "w", encoding="utf-8") as handle:
        print_json({"table": summaries, "rows": [r.as_dict() for m in order for r in rows[m]]}, handle)
    written.append(out / "compare.json")
    written.append(cv_bars(out / "compare.png", rows, order, titles))
    return written


def cv_bars(path: Path, rows, order, titles) -> Path:
    """CV at target per job, one bar per method."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    jobs = sorted({(r.context["fertilizer"], r.context["target_swath_m"]) for m in order for r in rows[m]})
    fig = Figure(figsize=(max(7.0, 0.75 * len(jobs) + 2), 4.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    width = 0.8 / max(1, len(order))
    x = np.arange(len(jobs))
    for i, m in enumerate(order):
        by_job = {}
        for r in rows[m]:
            key = (r.context["fertilizer"], r.context["target_swath_m"])
            by_job.setdefault(key, []).append(100.0 if r.cv_percent is None else r.cv_percent)
        values = [float(np.mean(by_job.get(j, [np.nan]))) for j in jobs]
        ax.bar(x + (i - (len(order) - 1) / 2) * width, values, width, label=titles.get(m, m))
    ax.set_xticks(x, [f"{f.split('-')[0]}\n{s:g} m" for f, s in jobs], fontsize=8)
    ax.set_ylabel("CV at target swath (%)")
    ax.axhline(15.0, color="#c0392b", ls="--", lw=1, label="15 % threshold")
    ax.legend(fontsize=8, ncol=min(len(order) + 1, 7), loc="lower center", bbox_to_anchor=(0.5, 1.01),
              frameon=False)
    ax.set_title("CV at the target swath per job (lower is better)", pad=28)
    ax.grid(True, axis="y", color="#e5e5e5")
    ax.set_axisbelow(True)
    fig.savefig(path)
    return path
