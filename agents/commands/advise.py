"""`spreadgym advise`: after a tray test, what to change on the machine for an even spread at the working
width wanted (fit the material to the test, search the settings on the fitted model, compare)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spreadgym.cli import arguments

ADVICE_FILES = ("advice.json", "fitted.yaml", "advised.yaml")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.agents.advise.run import ADVICE_BUDGET, ADVICE_GRANULES, DEFAULT_FIT
    from spreadgym.agents.chart.spec import MAX_BUDGET, MAX_WIDTH_M
    from spreadgym.fit.run import FIT_GRANULES

    parser.add_argument("--scene", required=True, metavar="S",
                        help="the machine of the test: a shipped scene name or a YAML path")
    parser.add_argument("--trays", required=True, metavar="FILE",
                        help="the tray test CSV (columns x_m, mass_g[, pass]: docs/fit.md)")
    parser.add_argument("--width", required=True, type=arguments.real(0.0, MAX_WIDTH_M, low_open=True),
                        metavar="W", help="the working width wanted, m (a multiple of the tray width)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="the settings the test was made at, as scene keys (e.g. spinner.rpm=720)")
    arguments.add_materials_flag(parser)
    parser.add_argument("--fit", dest="fit", action="append", metavar="KEY=LO:HI[,KEY=LO:HI ...]",
                        help="the keys to fit with their ranges (default: " + ",".join(DEFAULT_FIT) + ")")
    parser.add_argument("--budget", type=arguments.integer(4, MAX_BUDGET), default=ADVICE_BUDGET, metavar="N",
                        help=f"candidates of the settings search (default {ADVICE_BUDGET})")
    parser.add_argument("--granules", type=arguments.GRANULES, default=ADVICE_GRANULES, metavar="N",
                        help=f"granules per search run (default {ADVICE_GRANULES})")
    parser.add_argument("--fit-granules", type=arguments.GRANULES, default=FIT_GRANULES, metavar="N",
                        help=f"granules per fit evaluation (default {FIT_GRANULES})")
    parser.add_argument("--seed", type=arguments.SEED, default=None, metavar="S",
                        help="seed of the fit and the search (default: the scene's sim.seed)")
    parser.add_argument("--threads", type=arguments.COUNT, default=None, metavar="N",
                        help="threads for the simulations (default: the cores this process may use)")
    parser.add_argument("--json", action="store_true", help="print the advice as JSON")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="write advice.json, fitted.yaml (the fitted scene at the test's settings) and "
                             "advised.yaml (at the advised settings and width) into DIR, once the advice is done "
                             "(the output-folder rule: never over an input, nothing left by a failed run)")
    arguments.force_flag(parser)


def write_out(folder: Path, data: dict, fitted_yaml: str, advised_yaml: str) -> list[Path]:
    """The advice's files in `folder`, each written whole."""
    import json

    from spreadgym.out_folder import write_atomic

    texts = (json.dumps(data, indent=2) + "\n", fitted_yaml, advised_yaml)
    return [write_atomic(folder / name, text) for name, text in zip(ADVICE_FILES, texts)]


def run(args: argparse.Namespace) -> int:
    import yaml

    from spreadgym.agents.advise.run import DEFAULT_FIT, advice_payload, advise, check_width
    from spreadgym.config.materials import user_materials
    from spreadgym.config.overrides import parse_assignments
    from spreadgym.config.scene import load_scene, scene_with
    from spreadgym.fit.outputs import payload, predict, scene_yaml
    from spreadgym.fit.trays import read_trays
    from spreadgym.out_folder import OutFolder, named_files
    from spreadgym.report import print_json
    from spreadgym.threads import set_threads

    if args.threads is not None:
        set_threads(args.threads)
    overrides = parse_assignments(args.overrides)
    scene = load_scene(args.scene, overrides, args.materials)
    check_width(args.width, scene)
    out = None
    if args.out is not None:
        out = OutFolder(args.out, "advise", files=ADVICE_FILES,
                        inputs=named_files(args.trays, args.scene, args.materials), force=args.force,
                        replaces_own=False)
        out.check()
    test = read_trays(args.trays, scene.pattern.tray_width_m)
    with user_materials(args.materials):  # the search's batches of the fertilizer are drawn from the library
        advice = advise(scene, test, args.width, fit=args.fit or DEFAULT_FIT, budget=args.budget,
                        granules=args.granules, fit_granules=args.fit_granules, seed=args.seed, fixed=overrides,
                        progress=lambda text: print(f"{text} ...", file=sys.stderr))
    data = advice_payload(advice, payload(advice.fit, predict(advice.fit), None))
    if out is not None:
        advised = scene_with(advice.fit.fitted_scene, {**advice.advised, "pattern.target_swath_m": args.width})
        advised_yaml = (f"# {advised.name} fitted to {test.source}, at the advised settings for {args.width:g} m\n"
                        + yaml.safe_dump(advised.model_dump(mode="json"), sort_keys=False))
        with out.writing() as folder:
            data["files"] = [str(p) for p in write_out(folder, data, scene_yaml(advice.fit), advised_yaml)]
    if args.json:
        print_json(data)
    else:
        print(summary(data))
    return 0


def summary(data: dict) -> str:
    """The advice for people: the instruction, the settings table, the fit's estimates."""
    from spreadgym.report import format_table, setting_label, setting_text

    rows = []
    for key, value in data["advised"].items():
        old = data["tested"][key]
        pairs = [(key, old, value)] if not isinstance(value, list) else \
            [(f"{key}.{k}", a, b) for k, (a, b) in enumerate(zip(old, value))]
        rows += [(setting_label(k), setting_text(k, a), setting_text(k, b), "change" if a != b else "keep")
                 for k, a, b in pairs]
    fit = data["fit"]
    estimates = ", ".join(f"{k} {v['estimate']:.3g} [{v['low']:.3g}, {v['high']:.3g}]"
                          for k, v in fit["parameters"].items())
    lines = [data["instruction"], "", format_table(rows, ("setting", "tested", "advised", "")), "",
             f"fitted to {fit['trays_used']} trays: {estimates} (90 % intervals)",
             f"p90 CV over the variability model: {_maybe(data['cv_p90_before_percent'])} tested, "
             f"{_maybe(data['cv_p90_after_percent'])} advised",
             f"{data['search']['simulations']} search runs, {data['wall_s']:.0f} s"]
    lines += [f"wrote {path}" for path in data.get("files", [])]
    return "\n".join(lines)


def _maybe(value) -> str:
    return "-" if value is None else f"{value:.1f} %"
