"""`spreadgym demo`: the main job. The paper's spinner at its published settings (full
model), better rpm and vane pitch for a wider target swath found by CMA-ES on the fast
compiled model, and the before/after with the full model: table and pictures."""

from __future__ import annotations

import argparse
from pathlib import Path

from spreadgym.cli import arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.agents import demo

    parser.add_argument("--out", type=arguments.output_folder, default=Path("out/demo"),
                        help="folder for tables and pictures (default out/demo; a demo's earlier outputs are "
                             "replaced)")
    arguments.force_flag(parser)
    parser.add_argument("--target-swath", type=arguments.real(0.0, 100.0, low_open=True),
                        default=demo.DEFAULT_TARGET_M, metavar="M",
                        help=f"target swath in m, on the 0.5 m tray grid (default {demo.DEFAULT_TARGET_M:g})")
    parser.add_argument("--budget", type=arguments.COUNT, default=demo.DEFAULT_BUDGET, metavar="N",
                        help=f"CMA-ES simulations on the {demo.SEARCH_MODEL} model (default {demo.DEFAULT_BUDGET})")
    parser.add_argument("--granules", type=arguments.integer(demo.MIN_GRANULES, 1_000_000),
                        default=demo.DEFAULT_GRANULES, metavar="N",
                        help=f"granules per simulation, search and full model (default {demo.DEFAULT_GRANULES})")
    parser.add_argument("--seed", type=arguments.SEED, default=0, help="seed of the search (default 0)")
    policy = parser.add_mutually_exclusive_group()
    policy.add_argument("--policy", type=Path, metavar="DIR/model.zip",
                        help=f"also show this trained policy (default: {demo.POLICY_PATH} if it exists)")
    policy.add_argument("--no-policy", action="store_true", help="do not show a trained policy")
    parser.add_argument("--json", action="store_true", help="print the before/after as JSON")


def run(args: argparse.Namespace) -> int:
    import io
    import time
    from contextlib import redirect_stdout

    from spreadgym.agents import demo
    from spreadgym.out_folder import OutFolder, named_files
    from spreadgym.report import print_json

    started = time.perf_counter()
    if args.policy is not None:  # before the work: a policy it cannot show would waste it
        from spreadgym.agents.training import saved_policy_file

        saved_policy_file(args.policy, flag="--policy")
    policy = None if args.no_policy else (args.policy or demo.POLICY_PATH)
    out = OutFolder(args.out, "demo", demo.OUTPUTS, named_files(args.policy), args.force, marker=demo.OUTPUTS[2])
    out.check()
    buffer = io.StringIO()
    with redirect_stdout(buffer) if args.json else _nothing(), out.writing() as folder:  # removed if it fails
        result = demo.run_demo(folder, target_m=args.target_swath, budget=args.budget, granules=args.granules,
                               seed=args.seed, policy_path=policy, policy_required=args.policy is not None)
    if args.json:
        print_json(result)
        return 0
    print()
    print(f"files in {args.out}/:")
    for path in result["files"]:
        print(f"  {path}")
    print(f"open {Path(args.out) / 'before_after.png'} for the before/after patterns and CV curves")
    print(f"demo done in {time.perf_counter() - started:.0f} s")
    return 0


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
