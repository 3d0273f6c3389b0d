"""`spreadgym evaluate`: run a policy on the env's evaluation jobs: a spreadgym train run, an
rl_zoo3 or stable-baselines3 model file, or a `module:function` callable."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spreadgym.cli import arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:

    parser.add_argument("--model", required=True, metavar="MODEL",
                        help="a spreadgym train run (DIR or DIR/model.zip), an rl_zoo3 or stable-baselines3 model "
                             "file, or module:function (policy(obs) -> action, one observation at a time)")
    parser.add_argument("--env", metavar="ID",
                        help="env of a model that names none (a plain SB3 file, a callable; default "
                             "spreadgym/SpinnerDesign-v1); a train or zoo run's own env otherwise")
    parser.add_argument("--episodes", type=arguments.COUNT, default=1, metavar="N",
                        help="episodes per job, each on another granule sample (default 1)")
    parser.add_argument("--granules", type=arguments.GRANULES, metavar="N",
                        help="granules per simulation (default: the env's, the scene's sim.granules, 2048 on the "
                             "paper scene, whatever training used)")
    parser.add_argument("--fertilizers", nargs="+", metavar="NAME", help="restrict the evaluation set")
    parser.add_argument("--swaths", nargs="+", type=arguments.real(0.0, 100.0, low_open=True), metavar="M",
                        help="target swaths (default: the env's evaluation jobs; v0: 2 3 4 5)")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    parser.add_argument("--out", type=arguments.output_folder, metavar="DIR2",
                        help="folder for the table and plots (default: the model's folder/eval, out/eval for a "
                             "callable; an evaluation's earlier outputs are replaced)")
    arguments.force_flag(parser)
    parser.add_argument("--no-plots", action="store_true", help="skip the pattern plots")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from spreadgym.agents import evaluation as ev
    from spreadgym.agents.commands.compare import _check_fits
    from spreadgym.agents.policies import describe, load_any_policy, model_files
    from spreadgym.errors import SpreadgymError
    from spreadgym.out_folder import OutFolder, named_files
    from spreadgym.report import print_json

    if args.episodes < 1:
        raise SpreadgymError(f"--episodes must be at least 1, got {args.episodes}")
    policy = load_any_policy(args.model, args.env)
    out = OutFolder(args.out or _default_out(policy.kind, Path(args.model)), "evaluate", OUTPUTS,
                    named_files(*model_files(args.model)), args.force, marker="eval.json")
    out.check()
    env_kwargs = evaluation_env_kwargs(policy.env_kwargs, args.granules)
    env_id = ev.canonical_env_id(policy.env_id)
    env = ev.make_env(env_id, env_kwargs)
    jobs = ev.evaluation_set(args.fertilizers, args.swaths, env=env)
    _check_jobs(env, jobs)
    _check_fits(policy, env)
    method = policy.name if policy.kind == "callable" else f"{policy.name} policy"
    rows = []
    with tqdm(total=len(jobs) * args.episodes, desc="evaluate", unit="episode", file=sys.stderr,
              disable=None, leave=False) as bar:
        for ctx in jobs:
            for episode in range(args.episodes):
                rows.append(ev.run_policy(env, ctx, policy.act, method, episode))
                bar.update()
    summary = ev.summarise(method, rows)
    with out.writing() as folder:
        written = write_outputs(folder, rows, summary, env, None if args.no_plots else method)
    payload = {"model": str(args.model), "kind": policy.kind, "env": env_id, "env_kwargs": env_kwargs,
               "rows": [_json_row(r) for r in rows], "summary": summary,
               "files": [str(p) for p in written]}
    if args.json:
        print_json(payload)
        return 0
    flat = [ev.flat_row(r) for r in rows]
    print(f"{method} ({describe(policy)}) from {args.model} on {len(jobs)} jobs ({env_id}, "
          f"{env_kwargs.get('granules', 'default')} granules)")
    print(ev.text_table(flat, ev.ROW_COLUMNS))
    print()
    print(ev.text_table([summary], ev.SUMMARY_COLUMNS))
    for path in written:
        print(f"wrote {path}")
    return 0


def _default_out(kind: str, model: Path) -> Path:
    """DIR/eval beside the model (out/eval for a callable)."""
    if kind == "callable":
        return Path("out/eval")
    return (model if model.is_dir() else model.parent) / "eval"


def evaluation_env_kwargs(train_kwargs: dict, granules) -> dict:
    """The training env's kwargs with the granule count of the evaluation (env default unless given)."""
    kwargs = {k: v for k, v in train_kwargs.items() if k != "granules"}
    if granules is not None:
        kwargs["granules"] = int(granules)
    return kwargs


def _check_jobs(env, jobs) -> None:
    from spreadgym.errors import SpreadgymError

    if env.unwrapped.task.evaluation_jobs:  # the env's own held-out jobs (v1)
        return
    known = env.unwrapped.task.cfg.context.fertilizers
    for ctx in jobs:
        if ctx.fertilizer not in known:
            raise SpreadgymError(f"fertilizer {ctx.fertilizer!r} is not in the env's context.fertilizers {known}")
    if env.unwrapped.task.cfg.context.target_swath_m:
        lo, hi = env.unwrapped.task.cfg.context.target_swath_m
        for ctx in jobs:
            if not lo <= ctx.target_swath_m <= hi:
                print(f"note: target {ctx.target_swath_m:g} m is outside the training range [{lo:g}, {hi:g}] m",
                      file=sys.stderr)


def _json_row(row) -> dict:
    out = row.as_dict()
    out["cv_percent_at_target"] = out["cv_percent"]
    return out


OUTPUTS = ("eval.csv", "eval.md", "eval.json", "patterns.png")


def write_outputs(out: Path, rows, summary, env, plot_method) -> list:
    from spreadgym.agents import evaluation as ev
    from spreadgym.report import print_json

    out.mkdir(parents=True, exist_ok=True)
    flat = [ev.flat_row(r) for r in rows]
    written = [ev.write_csv(out / "eval.csv", flat, ev.ROW_COLUMNS)]
    md = out / "eval.md"
    md.write_text(ev.markdown_table(flat, ev.ROW_COLUMNS) + "\n\n" + ev.markdown_table([summary], ev.SUMMARY_COLUMNS)
                  + "\n", encoding="utf-8")
    written.append(md)
    with open(out / "eval.json", "w", encoding="utf-8") as handle:
        print_json({"rows": [_json_row(r) for r in rows], "summary": summary}, handle)
    written.append(out / "eval.json")
    if plot_method:
        results = [(f"{r.context['fertilizer']} @ {r.context['target_swath_m']:g} m", ev.simulate_row(env, r))
                   for r in rows if r.episode == 0]
        written.append(ev.pattern_grid(results, out / "patterns.png", title=f"{plot_method}: transverse patterns"))
    return written
