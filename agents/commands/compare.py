"""`spreadgym compare`: policies (spreadgym train runs, rl_zoo3 or stable-baselines3 model
files, `module:function` callables) against the baselines (published settings, the centre
and a random action, random search, grid search, CMA-ES, Optuna's TPE) on the env's
evaluation jobs, with every simulation counted; with `--seeds N` each method gets N runs,
and where the benchmark's reference scores exist the normalised scores are aggregated
with rliable (interquartile mean, stratified bootstrap intervals, performance profiles)."""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

from spreadgym.cli import arguments

METHODS = ("published", "centre", "random-action", "random", "grid", "cmaes", "optuna")
DEFAULT_METHODS = ("published", "random", "grid", "cmaes", "optuna")


MAX_RUNS = 1000  # seeds or episodes: rliable's intervals are tight long before; the task list is held whole


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.agents.baselines import DEFAULT_BUDGET

    parser.add_argument("--model", action="append", metavar="[LABEL=]MODEL",
                        help="a policy: a spreadgym train run (DIR or DIR/model.zip), an rl_zoo3 or "
                             "stable-baselines3 model file, or module:function (policy(obs) -> action); repeat "
                             "the flag for several, the same LABEL for the seeds of one method")
    parser.add_argument("--env", metavar="ID",
                        help="env (default: the models', else spreadgym/SpinnerDesign-v1); its evaluation jobs "
                             "are the held-out ones of docs/benchmark.md")
    parser.add_argument("--budget", type=arguments.COUNT, default=DEFAULT_BUDGET, metavar="N",
                        help=f"simulations per job for each search (default {DEFAULT_BUDGET})")
    parser.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS), choices=METHODS, metavar="METHOD",
                        help=f"baselines to run (default: {', '.join(DEFAULT_METHODS)}; also centre, random-action)")
    parser.add_argument("--seeds", type=arguments.integer(1, MAX_RUNS), default=1, metavar="N",
                        help="runs of each baseline, seeds --seed ... --seed + N - 1, each scored on its own "
                             f"samples (default 1, at most {MAX_RUNS})")
    parser.add_argument("--episodes", type=arguments.integer(1, MAX_RUNS), default=1, metavar="N",
                        help="scoring episodes per job and run, each on another granule sample (default 1, at "
                             f"most {MAX_RUNS})")
    parser.add_argument("--granules", type=arguments.GRANULES, metavar="N",
                        help="granules per simulation (default: the env's, the scene's sim.granules, 2048 on the "
                             "paper scene)")
    parser.add_argument("--fertilizers", nargs="+", metavar="NAME", help="restrict the evaluation set")
    parser.add_argument("--swaths", nargs="+", type=arguments.real(0.0, 100.0, low_open=True), metavar="M",
                        help="target swaths (default: the env's evaluation jobs; v0: 2 3 4 5)")
    parser.add_argument("--seed", type=arguments.SEED, default=0, help="seed of the searches (default 0)")
    parser.add_argument("--workers", type=arguments.COUNT, default=1, metavar="N",
                        help="processes for the searches (default 1; wall times are per core either way)")
    parser.add_argument("--threads", type=arguments.THREADS, metavar="N",
                        help="threads in all, shared by the --workers (default: SPREADGYM_THREADS, else every core "
                             "this process may use); each search evaluates its batches on its share")
    arguments.add_device(parser)
    parser.add_argument("--json", action="store_true", help="print the table and rows as JSON")
    parser.add_argument("--out", type=arguments.output_folder, default=Path("out/compare"), metavar="DIR",
                        help="folder for compare.csv/.md/.json and compare.png (default out/compare; a comparison's "
                             "earlier outputs are replaced)")
    arguments.force_flag(parser)


_ENVS: dict = {}


def _env(env_id: str, env_kwargs: dict):
    from spreadgym.agents.evaluation import make_env

    key = (env_id, repr(sorted(env_kwargs.items())))
    if key not in _ENVS:
        _ENVS[key] = make_env(env_id, env_kwargs)
    return _ENVS[key]


def baseline_job(env_id: str, env_kwargs: dict, ctx, method: str, budget: int, seed: int, episodes: int,
                 run: int = 0):
    """Run `run` of one method on one job (in a worker process when --workers > 1): the
    search seed `seed + run`, the scoring episodes of that run."""
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from spreadgym.agents.baselines import run_baseline

    rows = run_baseline(_env(env_id, env_kwargs), ctx, method, budget, seed + run, episodes,
                        first_episode=run * episodes)
    for row in rows:
        row.extra["run"] = run
    return rows


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
    out_folder(args).check()
    if args.workers < 1:
        raise SpreadgymError(f"--workers must be at least 1, got {args.workers}")
    if args.seeds < 1:
        raise SpreadgymError(f"--seeds must be at least 1, got {args.seeds}")
    if args.device is not None:
        from spreadgym.device import checked

        checked(args.device, "--device")  # with --workers, each worker's searches launch on the same GPU
    started = time.perf_counter()
    from spreadgym.threads import set_threads, shares

    per_worker = min(shares(args.workers, args.threads))  # the same for every pool worker
    set_threads(per_worker)
    policies = _load_policies(args.model or [], args.env)
    from spreadgym.agents.policies import DEFAULT_ENV

    env_id = ev.canonical_env_id(args.env or (policies[0][1].env_id if policies else DEFAULT_ENV))
    train_kwargs = policies[0][1].env_kwargs if policies else {}
    env_kwargs = evaluation_env_kwargs(train_kwargs, args.granules)
    if args.device is not None:
        env_kwargs["device"] = args.device
    env = _env(env_id, env_kwargs)  # checks the kwargs here
    if "SpinnerDesign" not in env_id:
        raise SpreadgymError(f"--env {env_id}: compare needs a SpinnerDesign task (the searches set absolute "
                             "settings)")
    env_kwargs = {**env_kwargs, "granules": env.unwrapped.task.base_scene.sim.granules}  # the count that runs
    jobs = ev.evaluation_set(args.fertilizers, args.swaths, env=env)
    from spreadgym.agents.commands.evaluate import _check_jobs

    _check_jobs(env, jobs)
    methods = list(dict.fromkeys(args.methods))
    rows: dict[str, list] = {}
    titles = dict(METHOD_TITLES)
    runs_seen: dict[str, int] = {}
    for key, policy, title in policies:
        titles[key] = title
        run_index = runs_seen[key] = runs_seen.get(key, -1) + 1
        rows.setdefault(key, [])
        _check_fits(policy, env)
        for ctx in tqdm(jobs, desc=title, unit="job", file=sys.stderr, disable=None, leave=False):
            for episode in range(run_index * args.episodes, (run_index + 1) * args.episodes):
                row = ev.run_policy(env, ctx, policy.act, key, episode)
                row.extra["run"] = run_index
                rows[key].append(row)
    tasks = [(m, ctx, r) for m in methods for r in range(args.seeds) for ctx in jobs]
    for m in methods:
        rows[m] = []
    bar = tqdm(total=len(tasks), desc="baselines", unit="job", file=sys.stderr, disable=None, leave=False)
    if args.workers == 1:
        for m, ctx, r in tasks:
            bar.set_description(f"{titles[m]}")
            rows[m].extend(baseline_job(env_id, env_kwargs, ctx, m, args.budget, args.seed, args.episodes, r))
            bar.update()
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("forkserver"),
                                 initializer=set_threads, initargs=(per_worker,)) as pool:
            futures = {pool.submit(baseline_job, env_id, env_kwargs, ctx, m, args.budget, args.seed,
                                   args.episodes, r): m for m, ctx, r in tasks}
            for future in as_completed(futures):
                rows[futures[future]].extend(future.result())
                bar.update()
    bar.close()
    for m in rows:
        rows[m].sort(key=lambda r: (r.extra.get("run", 0), r.context["fertilizer"], r.context["target_swath_m"],
                                    r.episode))
    order = list(dict.fromkeys(key for key, _, _ in policies)) + methods
    summaries = []
    for m in order:
        s = ev.summarise(m, rows[m])
        s["method"] = titles.get(m, m)
        s["key"] = m
        s["runs"] = 1 + max((r.extra.get("run", 0) for r in rows[m]), default=0)
        summaries.append(s)
    ev.mark_ties(summaries)
    aggregated = _aggregate(env_id, jobs, rows, order, summaries, env_kwargs)
    elapsed = time.perf_counter() - started
    with out_folder(args).writing() as folder:
        written = write_outputs(folder, summaries, rows, order, titles, args, env_kwargs, elapsed, aggregated)
    payload = {"budget": args.budget, "episodes": args.episodes, "seeds": args.seeds, "env": env_id,
               "env_kwargs": env_kwargs, "jobs": [c.as_dict() for c in jobs], "table": summaries,
               "rows": [r.as_dict() for m in order for r in rows[m]], "elapsed_s": elapsed,
               "normalised": aggregated["note"], "files": [str(p) for p in written]}
    if args.json:
        print_json(payload)
        return 0
    print(f"{env_id}: {len(jobs)} jobs, search budget {args.budget} simulations per job, "
          f"{env_kwargs['granules']} granules per simulation, {args.seeds} run(s) per baseline")
    print(ev.text_table(summaries, ev.SUMMARY_COLUMNS))
    if aggregated["matrices"]:
        print()
        print(ev.text_table(summaries, NORMALISED_COLUMNS))
    print(aggregated["note"])
    print(f"elapsed {elapsed:.0f} s")
    for path in written:
        print(f"wrote {path}")
    return 0


NORMALISED_COLUMNS = (
    ("method", "method"),
    ("runs", "runs"),
    ("iqm", "normalised IQM"),
    ("iqm_low", "95 % CI low"),
    ("iqm_high", "95 % CI high"),
    ("mean_normalised", "normalised mean"),
    ("cv_iqm_percent", "CV IQM (%)"),
    ("cv_iqm_low", "CV CI low"),
    ("cv_iqm_high", "CV CI high"),
)


def _aggregate(env_id: str, jobs, rows: dict, order: list, summaries: list, env_kwargs: dict) -> dict:
    """rliable's IQM (stratified bootstrap 95 % interval) of each method's normalised scores
    (docs/benchmark.md), put into `summaries`, where the benchmark's references cover every job
    and were made on the env as it runs here (no keyword but the granules and the device changed)."""
    from spreadgym.agents import benchmark

    changed = {k: v for k, v in env_kwargs.items() if k not in ("device", "granules")}  # the reward's own keys
    if changed:
        return {"matrices": {}, "note": f"no normalised scores: the benchmark's references were made on {env_id} "
                                         f"as shipped; this evaluation changes {', '.join(sorted(changed))}"}
    references = benchmark.shipped_references(env_id)
    labels = [ctx.label for ctx in jobs]
    if references is None or any(label not in references["jobs"] for label in labels):
        return {"matrices": {}, "note": f"no normalised scores: the benchmark's references "
                                         f"({benchmark.REFERENCES_FILE}) lack {env_id} or some of its jobs"}
    references = {**references, "jobs": {label: references["jobs"][label] for label in labels}}
    runs = {m: [{"rows": [r.as_dict() for r in rows[m] if r.extra.get("run", 0) == k]}
                for k in range(1 + max((r.extra.get("run", 0) for r in rows[m]), default=0))] for m in order}
    matrices = {m: benchmark.score_matrix(found, references) for m, found in runs.items()}
    stats = benchmark.aggregate(matrices)
    cv = benchmark.aggregate({m: benchmark.score_matrix(found, references, "cv") for m, found in runs.items()})
    for s in summaries:
        m = s["key"]
        s.update({"iqm": stats[m]["iqm"][0], "iqm_low": stats[m]["iqm"][1], "iqm_high": stats[m]["iqm"][2],
                  "mean_normalised": stats[m]["mean"][0], "cv_iqm_percent": cv[m]["iqm"][0],
                  "cv_iqm_low": cv[m]["iqm"][1], "cv_iqm_high": cv[m]["iqm"][2]})
    single = [m for m, found in runs.items() if len(found) < 2]
    alone = (f"; {', '.join(single)}: one run, which a bootstrap over runs cannot resample (its interval is the "
             "point itself: give --seeds 3 or more)") if single else ""
    return {"matrices": matrices, "note": "normalised: 0 = a random action's mean reward, 1 = the best known "
                                          "setting (CMA-ES at a generous budget, docs/benchmark.md); "
                                          "IQM over (run, job) with rliable's stratified bootstrap 95 % interval"
                                          + alone}


def _check_fits(policy, env) -> None:
    """A one-line error when the policy does not take the env's observation or give its action."""
    from spreadgym.errors import SpreadgymError

    obs, _ = env.reset(seed=0)
    try:
        action = policy.act(obs)
        env.unwrapped.task.settings_map.to_settings(_action_of(action, env.action_space.shape))
    except Exception as exc:  # the policy's own failure, whatever it is, is the message
        raise SpreadgymError(f"--model {policy.source}: does not fit {env.spec.id if env.spec else 'the env'} "
                             f"(observation {obs.shape}, action {env.action_space.shape}): "
                             f"{type(exc).__name__}: {exc}") from None


def _action_of(action, shape):
    import numpy as np

    action = np.asarray(action, dtype=np.float64)
    if action.shape != shape:
        raise ValueError(f"action of shape {action.shape}, expected {shape}")
    return action


def _load_policies(specs, env_id) -> list:
    """(label, Policy, title) per --model; all SpinnerDesign, all on the same env kwargs."""
    from spreadgym.agents import evaluation as ev
    from spreadgym.agents.policies import load_any_policy
    from spreadgym.errors import SpreadgymError

    out = []
    for spec in specs:
        labelled = re.match(r"^([\w.-]+)=(.+)$", spec)
        label, given = (labelled.group(1), labelled.group(2)) if labelled else ("", spec)
        if label in METHODS:
            raise SpreadgymError(f"--model {spec}: {label!r} names a baseline method; label the run otherwise")
        policy = load_any_policy(given, env_id)
        if "SpinnerDesign" not in policy.env_id:
            raise SpreadgymError(f"--model {given}: compare needs a SpinnerDesign policy "
                                 f"(the searches set absolute settings), this one is for {policy.env_id}")
        out.append((label, policy))
    if not out:
        return []
    tasks = {ev.canonical_env_id(p.env_id) for _, p in out}
    if len(tasks) > 1:
        raise SpreadgymError(f"--model: the policies are for different envs ({', '.join(sorted(tasks))}); "
                             "compare runs every method on one env")
    same = [{k: v for k, v in p.env_kwargs.items() if k != "granules"} for _, p in out]
    for spec, kwargs in zip(specs[1:], same[1:]):
        if kwargs != same[0]:
            raise SpreadgymError(f"--model {spec}: trained on other env kwargs ({kwargs}) than {specs[0]} "
                                 f"({same[0]}); compare runs every method on one env")
    names = [label or p.name for label, p in out]
    result = []
    for (label, policy), name in zip(out, names):
        if label:
            key, title = label, label
        elif policy.kind == "callable":
            key, title = name, name
        elif names.count(name) == 1:
            key, title = name, f"{name.upper()} policy"
        else:
            run_name = Path(policy.source).parent.name
            key, title = f"{name}:{run_name}", f"{name.upper()} policy ({run_name})"
        result.append((key, policy, title))
    return result


OUTPUTS = ("compare.csv", "compare_rows.csv", "compare.md", "compare.json", "compare.png", "profiles.png")


def out_folder(args: argparse.Namespace):
    """--out as an output folder (`spreadgym.out_folder`): the policies read are its inputs."""
    from spreadgym.agents.policies import model_files
    from spreadgym.out_folder import OutFolder, named_files

    inputs = named_files(*(path for spec in args.model or [] for path in model_files(spec)))
    return OutFolder(args.out, "compare", OUTPUTS, inputs, args.force,
                     marker="compare.json")


def write_outputs(out: Path, summaries, rows, order, titles, args, env_kwargs, elapsed, aggregated=None) -> list:
    from spreadgym.agents import evaluation as ev
    from spreadgym.report import print_json

    out.mkdir(parents=True, exist_ok=True)
    normalised = bool(aggregated and aggregated["matrices"])
    columns = ev.SUMMARY_COLUMNS + (NORMALISED_COLUMNS[1:] if normalised else ())
    written = [ev.write_csv(out / "compare.csv", summaries, columns)]
    flat = [ev.flat_row(r) | {"method": titles.get(r.method, r.method)} for m in order for r in rows[m]]
    written.append(ev.write_csv(out / "compare_rows.csv", flat, ev.ROW_COLUMNS))
    md = out / "compare.md"
    granules = env_kwargs["granules"]
    md.write_text(
        f"Evaluation set: {len({(r['fertilizer'], r['target_swath_m']) for r in flat})} jobs; "
        f"search budget {args.budget} simulations per job; {granules} granules per simulation; "
        f"{args.episodes} scoring episode(s) per job; elapsed {elapsed:.0f} s.\n\n"
        + ev.markdown_table(summaries, ev.SUMMARY_COLUMNS) + "\n\n"
        + ((ev.markdown_table(summaries, NORMALISED_COLUMNS) + "\n\n") if normalised else "")
        + (f"{aggregated['note']}\n\n" if aggregated else "") + "Per job:\n\n"
        + ev.markdown_table(flat, ev.ROW_COLUMNS) + "\n", encoding="utf-8")
    written.append(md)
    with open(out / "compare.json", "w", encoding="utf-8") as handle:
        print_json({"table": summaries, "rows": [r.as_dict() for m in order for r in rows[m]]}, handle)
    written.append(out / "compare.json")
    written.append(cv_bars(out / "compare.png", rows, order, titles))
    if normalised:
        from spreadgym.agents.benchmark import plot_profiles

        written.append(plot_profiles(aggregated["matrices"], out / "profiles.png",
                                     legend_labels({m: titles.get(m, m) for m in order})))
    return written


def legend_labels(titles: dict[str, str], most: int = 32) -> dict[str, str]:
    """Each method's title short enough for a legend: a policy file's name without its
    folders ("runs/a/policy.py:act" -> "policy.py:act"), at most `most` characters; titles
    that would then read alike keep their ends instead ("...a/policy.py:act"), or in full."""
    def cut(text: str) -> str:
        return text if len(text) <= most else text[:most - 1] + "\u2026"

    names = {m: cut(t.rsplit("/", 1)[-1]) for m, t in titles.items()}
    taken = list(names.values())
    short = {m: names[m] if taken.count(names[m]) == 1 else t if len(t) <= most else "\u2026" + t[-(most - 1):]
             for m, t in titles.items()}
    if len(set(short.values())) < len(short):
        return dict(titles)
    return short


def cv_bars(path: Path, rows, order, titles) -> Path:
    """CV at target per job, one bar per method."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    jobs = sorted({(r.context["fertilizer"], r.context["target_swath_m"]) for m in order for r in rows[m]})
    labels = legend_labels({m: titles.get(m, m) for m in order})
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
        ax.bar(x + (i - (len(order) - 1) / 2) * width, values, width, label=labels[m])
    ax.set_xticks(x, [f"{f.split('-')[0]}\n{s:g} m" for f, s in jobs], fontsize=8)
    ax.set_ylabel("CV at target swath (%)")
    ax.axhline(15.0, color="#c0392b", ls="--", lw=1, label="15 % threshold")
    fig.legend(fontsize=8, loc="outside right upper", frameon=False)  # beside the axes: any count of methods fits
    ax.set_title("CV at the target swath per job (lower is better)")
    ax.grid(True, axis="y", color="#e5e5e5")
    ax.set_axisbelow(True)
    fig.savefig(path)
    return path
