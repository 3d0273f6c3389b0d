"""`spreadgym fit`: fit scene keys to a measured tray test, with 90 % intervals.

The scene gives the test's settings (rpm, pitch, drop point, plates, tray width,
driving pattern); the keys named by --fit are searched within their ranges. See
docs/fit.md for the tray file, the likelihood and how honest the intervals are.
"""

from __future__ import annotations

import argparse
import sys

from spreadgym.cli import arguments
from spreadgym.report import format_table, print_json

HONEST_FIT_GRANULES = 1024  # below it a fit's intervals understate its simulation noise (a review's repeated fits)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.fit.run import FIT_GRANULES
    from spreadgym.physics.selection import MODELS

    parser.add_argument("--scene", default="paper", help="shipped scene name or a YAML path (default: paper)")
    parser.add_argument("--trays", required=True, metavar="FILE",
                        help="tray test CSV: columns x_m, mass_g[, pass]; '#' comment lines")
    parser.add_argument("--fit", dest="fit", action="append", required=True, metavar="KEY=LO:HI[,KEY=LO:HI ...]",
                        help="scene keys to fit with their search ranges (e.g. contact.vane_friction=0.2:0.8)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene key, VALUE parsed as YAML (the test's settings)")
    parser.add_argument("--model", default="auto", choices=MODELS, help="spinner model (default: auto)")
    parser.add_argument("--granules", type=arguments.GRANULES, default=FIT_GRANULES, metavar="N",
                        help=f"granules per evaluation (default {FIT_GRANULES}; a fit's time grows with it)")
    parser.add_argument("--seed", type=arguments.SEED, default=None, metavar="S",
                        help="sim.seed of every evaluation and the start design's seed (default: the scene's)")
    parser.add_argument("--threads", type=arguments.THREADS, default=None, metavar="N",
                        help="threads for the simulations (default: the cores this process may use)")
    arguments.add_materials_flag(parser)
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--out", type=arguments.output_folder, metavar="DIR",
                        help="write the fitted scene, estimates, pattern, CV curve and picture into DIR (created "
                             "when the fit is done; never over an input; an earlier fit's outputs need --force)")
    arguments.force_flag(parser)


def run(args: argparse.Namespace) -> int:
    from spreadgym.config.overrides import parse_assignments
    from spreadgym.config.scene import load_scene, scene_with
    from spreadgym.fit.outputs import OUTPUT_FILES, payload, predict, write_outputs
    from spreadgym.fit.run import fit_tray_test, work_text
    from spreadgym.fit.space import full_model_corner, parse_fit_specs
    from spreadgym.fit.trays import read_trays
    from spreadgym.out_folder import OutFolder, named_files
    from spreadgym.threads import set_threads

    if args.threads is not None:
        set_threads(args.threads)
    overrides = parse_assignments(args.overrides)
    scene = load_scene(args.scene, overrides, args.materials)
    seed = scene.sim.seed if args.seed is None else args.seed
    scene = scene_with(scene, {"sim.seed": seed})
    space = parse_fit_specs(args.fit, scene, fixed=overrides)
    test = read_trays(args.trays, scene.pattern.tray_width_m)
    out = None
    if args.out:
        out = OutFolder(args.out, "fit", files=OUTPUT_FILES, inputs=named_files(args.trays, args.scene, args.materials),
                        force=args.force, replaces_own=False)
        out.check()
    print(f"fitting {', '.join(space.keys)} to {test.count} trays: {work_text(scene, args.granules)} ...",
          file=sys.stderr)
    slow = full_model_corner(space, scene, args.model)
    if slow:  # said before the work: such a fit takes minutes to hours instead of seconds
        print(f"note: part of the search box runs the full model ({slow}); those evaluations are about a "
              "hundred times slower: narrow the range, or pass --model compiled to stay on the fast model "
              "(docs/fit.md)", file=sys.stderr)
    if args.granules < HONEST_FIT_GRANULES:  # said before the work, as above
        print(f"note: at {args.granules} granules per evaluation the intervals understate the simulation's own "
              f"noise (about half of it at 256, measured against repeated fits; they agree from "
              f"{HONEST_FIT_GRANULES}): use {HONEST_FIT_GRANULES} or more for intervals you quote (docs/fit.md)",
              file=sys.stderr)
    fit = fit_tray_test(scene, space, test, model=args.model, granules=args.granules, seed=seed)
    prediction = predict(fit)
    if out is None:
        data = payload(fit, prediction, None)
    else:
        with out.writing() as folder:
            data = write_outputs(fit, prediction, folder)
    if args.json:
        print_json(data)
    else:
        print(summary(data))
    return 0


def summary(data: dict) -> str:
    """The estimates and intervals, for people."""
    from spreadgym.fit.measured import MIN_SPANNED_SHARE
    from spreadgym.fit.uncertainty import REGIME_SWITCH  # loaded by the fit already

    rows = []
    for key, v in data["parameters"].items():
        switch = data.get("regime_switch", {}).get(key, 0.0)
        if data.get("estimate_at_search_bound", {}).get(key):
            state = "no: the estimate is at the search bound (the best fit may lie beyond it: widen the range)"
        elif data["identifiable"][key]:
            state = "yes"
        elif switch > REGIME_SWITCH:
            state = (f"no: vane friction turns {100 * switch:.0f} % of the granules between sliding and rolling "
                     "inside the interval (the fit model changes regime at another friction than the full model)")
        else:
            state = "no: the test does not determine it"
        rows.append((key, f"{v['estimate']:.4g}", f"[{v['low']:.4g}, {v['high']:.4g}]", state))
    table = format_table(rows, ("key", "estimate", "90 % interval", "identifiable"))
    lines = [f"fit of {data['scene']} to {data['trays_file']} ({data['trays_used']} trays, "
             f"{data['evaluations']} evaluations, {data['wall_s']:.0f} s)", table,
             f"catch noise: {100 * data['catch_noise_sd']:.1f} % per tray (estimated)"]
    if data["discrepancy_points"]:
        lines.append("intervals carry the compiled model's measured difference from the full model "
                     f"({data['discrepancy_points']} calibration points)")
    else:
        lines.append("intervals carry no model difference (none is stored for this scene, fertilizer and "
                     "rotation, or the fit ran the full model)")
    for pair in data["trade_offs"]:
        lines.append(f"trade-off: {pair['keys'][0]} and {pair['keys'][1]} (correlation {pair['correlation']:+.2f})")
    cv, band = data["cv_percent_at_target"], data["cv_percent_at_target_band"]
    if cv is not None:
        lines.append(f"fitted CV at {data['target_swath_m']:g} m ({data['driving']}): {cv:.1f} % "
                     f"(90 % band {band[0]:.1f}-{band[1]:.1f} %)")
    measured = data.get("measured_cv_percent_at_target")
    if measured is not None:
        lines.append(f"measured trays' own CV at {data['target_swath_m']:g} m: {measured:.1f} %")
    else:
        lines.append(f"measured trays' own CV: not given (the trays span {100 * data['measured_span_share']:.0f} % "
                     f"of the fitted pattern's mass; at least {100 * MIN_SPANNED_SHARE:.0f} % needed)")
    if data["scene_yaml"]:
        lines.append(f"wrote {data['scene_yaml']} and the rest of the fit beside it")
    return "\n".join(lines)
