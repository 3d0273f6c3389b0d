"""`spreadgym reference`: a converged pattern of one scene (independent runs pooled)."""

from __future__ import annotations

import argparse
import sys

from tqdm import tqdm

from spreadgym.cli import arguments
from spreadgym.cli.simulate import precision_flag
from spreadgym.config.overrides import parse_assignments
from spreadgym.config.scene import load_scene
from spreadgym.device import set_device
from spreadgym.errors import ConfigError, SpreadgymError
from spreadgym.physics.selection import MODELS
from spreadgym.report import format_table, print_json, with_error
from spreadgym.spread.precision import REFERENCE_MAX_RUNS, REFERENCE_PRECISION_PP, reached, reference_precisely
from spreadgym.spread.reference import MIN_RUNS
from spreadgym.threads import set_threads


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scene", default="paper", help="shipped scene name or a YAML path (default: paper)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene key, VALUE parsed as YAML (e.g. spinner.rpm=800)")
    parser.add_argument("--model", default="auto", choices=MODELS, help="spinner model (default: auto)")
    parser.add_argument("--granules", type=arguments.GRANULES, metavar="N",
                        help="granules per run (default: the scene's)")
    parser.add_argument("--precision", type=precision_flag, default=REFERENCE_PRECISION_PP, metavar="PP",
                        help="standard error wanted for the CV at the target width, in percentage points: runs are "
                             f"pooled until it is reached (default {REFERENCE_PRECISION_PP:g})")
    parser.add_argument("--max-runs", type=arguments.integer(MIN_RUNS, 65536), default=REFERENCE_MAX_RUNS,
                        metavar="N", help=f"at most N runs (default {REFERENCE_MAX_RUNS})")
    parser.add_argument("--replicates", type=arguments.integer(2, 65536), metavar="K",
                        help=f"exactly K independent runs pooled instead (at least {MIN_RUNS}; ignores --precision)")
    parser.add_argument("--threads", type=arguments.THREADS, metavar="N",
                        help="threads to use (default: SPREADGYM_THREADS, else every core this process may use)")
    arguments.add_materials_flag(parser)
    arguments.add_device(parser)
    parser.add_argument("--json", action="store_true", help="print the reference as JSON")


def run(args: argparse.Namespace) -> int:
    if args.threads is not None:
        set_threads(args.threads)
    if args.device is not None:
        set_device(args.device)
    if args.replicates is not None and args.replicates < MIN_RUNS:
        raise SpreadgymError(f"--replicates: {args.replicates} must be at least {MIN_RUNS}")
    overrides = parse_assignments(args.overrides)
    if args.granules is not None:
        if args.granules < 1:
            raise SpreadgymError(f"--granules: {args.granules} must be at least 1")
        overrides["sim.granules"] = args.granules
    try:
        scene = load_scene(args.scene, overrides, args.materials)
    except ConfigError as exc:  # the flag that set the key, where one did
        if args.granules is not None and exc.key == "sim.granules":
            raise SpreadgymError(f"--granules: {exc.message}") from None
        raise
    with tqdm(desc="reference", unit="run", file=sys.stderr, disable=None, leave=False) as bar:
        reference = reference_precisely(scene, args.precision, args.max_runs, model=args.model,
                                        progress=lambda done, _cap: bar.update(done - bar.n), runs=args.replicates)
    payload = reference.to_json()
    payload.update({"granules_simulated": reference.pooled.granules,
                    "runs": reference.pooled.granules // scene.sim.granules,
                    "precision_percent": None if args.replicates else args.precision,
                    "precision_met": None if args.replicates else reached(payload["cv_standard_error_percent"],
                                                                           args.precision)})
    if args.json:
        print_json(payload)
    else:
        print(summary(payload))
    return 0


def _pm(value, error, unit: str) -> str:
    return "-" if value is None else with_error(value, error, unit)


def summary(ref: dict) -> str:
    """The reference's headline numbers, for people."""
    lo, hi = ref["effective_swath_interval_m"]
    rows = [
        ("model", f"{ref['model']} ({ref['model_reason']})"),
        ("granules", f"{ref['granules']} in {ref['runs']} runs, {ref['replicates']} replicates "
                     f"({ref['landed_granules']} landed)"),
        ("CV at target", _pm(ref["cv_percent_at_target"], ref["cv_standard_error_percent"], "%")
         + f" at {ref['target_swath_m']:g} m ({ref['driving']})"),
        ("plain tray CV", _pm(ref["cv_raw_percent"], None, "%")),
        ("effective swath", f"{ref['effective_swath_m']:g} m (CV <= {ref['cv_threshold_percent']:g} %; "
                            f"{lo:g}-{hi:g} m within 2 SE)"),
        ("wall time", f"{ref['wall_s']:.1f} s"),
    ]
    return f"reference {ref['scene']}\n" + format_table(rows, ("quantity", "value"))
