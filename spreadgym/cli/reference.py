"""`spreadgym reference`: a converged pattern of one scene (independent runs pooled)."""

from __future__ import annotations

import argparse
import sys

from tqdm import tqdm

from spreadgym.cli import arguments
from spreadgym.config.overrides import parse_assignments
from spreadgym.config.scene import load_scene
from spreadgym.errors import SpreadgymError
from spreadgym.physics.selection import MODELS
from spreadgym.report import format_table, print_json
from spreadgym.spread.reference import MIN_RUNS, pool_runs, reference_from

DEFAULT_RUNS = 32


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scene", default="paper", help="shipped scene name or a YAML path (default: paper)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene key, VALUE parsed as YAML (e.g. spinner.rpm=800)")
    parser.add_argument("--model", default="auto", choices=MODELS, help="spinner model (default: auto)")
    parser.add_argument("--granules", type=arguments.GRANULES, metavar="N",
                        help="granules per run (default: the scene's)")
    parser.add_argument("--replicates", type=arguments.integer(2, 65536), default=DEFAULT_RUNS, metavar="K",
                        help=f"independent runs pooled (default {DEFAULT_RUNS}, at least {MIN_RUNS})")
    parser.add_argument("--json", action="store_true", help="print the reference as JSON")


def run(args: argparse.Namespace) -> int:
    if args.replicates < MIN_RUNS:
        raise SpreadgymError(f"--replicates: {args.replicates} must be at least {MIN_RUNS}")
    overrides = parse_assignments(args.overrides)
    if args.granules is not None:
        if args.granules < 1:
            raise SpreadgymError(f"--granules: {args.granules} must be at least 1")
        overrides["sim.granules"] = args.granules
    scene = load_scene(args.scene, overrides)
    with tqdm(total=args.replicates, desc="reference", unit="run", file=sys.stderr, disable=None,
              leave=False) as bar:
        pooled = pool_runs(scene, args.replicates, model=args.model,
                           progress=lambda done, _total: bar.update(done - bar.n))
    reference = reference_from(scene, pooled)
    if args.json:
        print_json(reference.to_json())
    else:
        print(summary(reference.to_json()))
    return 0


def _pm(value, error, unit: str) -> str:
    if value is None:
        return "-"
    return f"{value:.2f} +- {error:.2f} {unit}" if error is not None else f"{value:.2f} {unit}"


def summary(ref: dict) -> str:
    """The reference's headline numbers, for people."""
    lo, hi = ref["effective_swath_interval_m"]
    rows = [
        ("model", f"{ref['model']} ({ref['model_reason']})"),
        ("granules", f"{ref['granules']} in {ref['replicates']} replicates ({ref['landed_granules']} landed)"),
        ("CV at target", _pm(ref["cv_percent_at_target"], ref["cv_standard_error_percent"], "%")
         + f" at {ref['target_swath_m']:g} m ({ref['driving']})"),
        ("plain tray CV", _pm(ref["cv_raw_percent"], None, "%")),
        ("effective swath", f"{ref['effective_swath_m']:g} m (CV <= {ref['cv_threshold_percent']:g} %; "
                            f"{lo:g}-{hi:g} m within 2 SE)"),
        ("wall time", f"{ref['wall_s']:.1f} s"),
    ]
    return f"reference {ref['scene']}\n" + format_table(rows, ("quantity", "value"))
