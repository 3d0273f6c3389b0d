"""`spreadgym chart`: a spreading chart, the settings per fertilizer and working width,
searched on the fast model and verified with the full one; cells run as Ray tasks."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from spreadgym.cli import arguments

DRIVING = ("racetrack", "back-and-forth")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.agents.baselines import DEFAULT_BUDGET
    from spreadgym.agents.chart.spec import (
        MAX_BUDGET,
        MAX_STEADY_TOLERANCE_PP,
        METHODS,
        OBJECTIVES,
        STEADY_TOLERANCE_PP,
        VERIFY_MODEL,
    )
    from spreadgym.physics.selection import MODELS

    parser.add_argument("--scene", required=True, metavar="S", help="shipped scene name or a YAML path")
    parser.add_argument("--fertilizers", required=True, metavar="F1,F2|all",
                        help="fertilizers, comma separated, or all (every one with measured pairs on the scene)")
    parser.add_argument("--widths", required=True, metavar="W1,W2,...|LO:HI:STEP",
                        help="working widths in metres, multiples of the scene's tray width")
    parser.add_argument("--driving", choices=DRIVING, help="driving pattern (default: the scene's)")
    parser.add_argument("--budget", type=arguments.integer(1, MAX_BUDGET), default=DEFAULT_BUDGET, metavar="N",
                        help=f"candidates per cell for the search, each one fast-model simulation per batch of "
                             f"the variability model (robust) or one (nominal) (default {DEFAULT_BUDGET})")
    parser.add_argument("--granules", type=arguments.GRANULES, metavar="N",
                        help="granules per simulation, search and verification runs alike (default: the scene's)")
    parser.add_argument("--seed", type=arguments.SEED, default=0,
                        help="base seed; each cell's seeds derive from it and the cell (default 0)")
    parser.add_argument("--workers", type=arguments.COUNT, metavar="N",
                        help=f"CPUs of the embedded (private) local Ray (default: all, {os.cpu_count()} here)")
    parser.add_argument("--address", metavar="ADDR",
                        help="join the Ray cluster at ADDR (HOST:PORT, ray://HOST:PORT or auto) instead; "
                             "without it no cluster is joined, RAY_ADDRESS included")
    parser.add_argument("--out", type=Path, default=Path("out/chart"), metavar="DIR",
                        help="chart folder, created when the chart starts; rerunning the same command resumes it "
                             "(default out/chart)")
    parser.add_argument("--method", choices=METHODS, default="cmaes",
                        help="cmaes: search every cell; policy: a trained policy's proposal; policy+search: a "
                             "search started at it (default cmaes)")
    parser.add_argument("--objective", choices=OBJECTIVES, default="robust",
                        help="robust: the search minimises the CV 90 %% of batches stay under (the variability "
                             "model); nominal: the CV of the nominal scene (default robust)")
    parser.add_argument("--policy", metavar="PATH",
                        help="a SpinnerDesign policy saved by spreadgym train (DIR or DIR/model.zip), for "
                             "--method policy and policy+search (default: the one shipped for the scene, "
                             "configs/policies/SCENE/)")
    parser.add_argument("--verify-model", choices=MODELS, default=VERIFY_MODEL,
                        help=f"the model every cell is verified with, nominal and p90 runs (default "
                             f"{VERIFY_MODEL}, the full model; compiled: its contact laws per granule, within "
                             f"0.5 pp CV of it at a few hundredths of its cost: docs/fidelity.md)")
    parser.add_argument("--variability", metavar="FILE",
                        help="a YAML file with a 'variability:' section over the defaults "
                             "(configs/chart_variability.yaml)")
    parser.add_argument("--steady-tolerance-pp", type=arguments.real(0.0, MAX_STEADY_TOLERANCE_PP),
                        default=STEADY_TOLERANCE_PP, metavar="X",
                        help="steady rows: a point ties with a cell's best when its mean score is within two "
                             "standard errors of it plus X percentage points of the objective; among tied points "
                             "the lowest disc speed, then the smallest change from the neighbours; a wider tie set "
                             f"removes reversals at a price in CV (docs/charts.md; default {STEADY_TOLERANCE_PP:g}; "
                             "0: the two-standard-error rule)")
    arguments.add_materials_flag(parser)
    arguments.force_flag(parser)
    parser.add_argument("--json", action="store_true", help="print chart.json on stdout")


def run(args: argparse.Namespace) -> int:
    from spreadgym.agents.chart import chart
    from spreadgym.agents.chart.outputs import markdown
    from spreadgym.config.materials import user_materials
    from spreadgym.report import print_json

    with user_materials(args.materials):  # the spec records the chart's fertilizers from it: workers need no file
        result = chart(args.scene, args.fertilizers, args.widths, args.out, driving=args.driving,
                       budget=args.budget, granules=args.granules, seed=args.seed, workers=args.workers,
                       address=args.address, method=args.method, objective=args.objective, policy=args.policy,
                       variability=args.variability, verify_model=args.verify_model,
                       steady_tolerance_pp=args.steady_tolerance_pp, force=args.force)
    for key, problem in result.replaced.items():
        print(f"cells/{key}.json was not its cell's record ({problem}): computed again", file=sys.stderr)
    if args.json:
        print_json(result.payload)
        return 0
    print(markdown(result.spec, result.payload), end="")
    print(f"\n{len(result.computed)} cell(s) computed, {len(result.reused)} reused; elapsed {result.wall_s:.0f} s")
    for path in result.files:
        print(f"wrote {path}")
    return 0
