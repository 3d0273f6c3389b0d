"""`spreadgym study paper`: rerun the seed paper's simulation study, write CSV and PNGs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spreadgym.cli import arguments
from spreadgym.report import format_table, print_json

STUDIES = ("paper",)
TABLE = (
    ("sweep", "sweep"),
    ("material", "material"),
    ("rpm", "rpm"),
    ("diameter_m", "diam (m)"),
    ("rotation", "rotation"),
    ("departed", "departed"),
    ("speed_mean_m_s", "speed (m/s)"),
    ("speed_std_m_s", "sd"),
    ("spin_mean_rad_s", "spin (rad/s)"),
    ("angle_mean_deg", "angle (deg)"),
    ("radial_mean_m_s", "radial (m/s)"),
    ("tangential_mean_m_s", "tangential (m/s)"),
    ("time_on_spinner_mean_s", "time (s)"),
    ("closed_form_speed_m_s", "closed form (m/s)"),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.physics.selection import MODELS

    parser.add_argument("name", choices=STUDIES, help="which study (paper: the seed paper's Figs. 6-9)")
    parser.add_argument("--granules", type=arguments.GRANULES, default=200, help="granules per case (default 200)")
    parser.add_argument("--model", default="pymunk", choices=MODELS, help="spinner model (default: pymunk)")
    parser.add_argument("--out", type=arguments.output_folder, default=Path("docs/study"),
                        help="folder for the CSV and PNGs (default docs/study; a study's earlier outputs are "
                             "replaced)")
    arguments.force_flag(parser)
    parser.add_argument("--json", action="store_true", help='print {"rows": [...]} as JSON')


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from spreadgym.errors import SpreadgymError
    from spreadgym.out_folder import OutFolder
    from spreadgym.studies.paper import CSV_NAME, FIGURES, paper_cases, paper_study, plot_paper_study, write_study

    if args.granules < 1:
        raise SpreadgymError(f"--granules: {args.granules} must be at least 1")
    out = OutFolder(args.out, "study", (CSV_NAME, *FIGURES), force=args.force, marker=CSV_NAME)
    out.check()
    total = 2 * len(paper_cases())
    with tqdm(total=total, desc="study paper", unit="case", file=sys.stderr, disable=None, leave=False) as bar:
        def progress(done: int, _total: int) -> None:
            bar.update(done - bar.n)

        rows = paper_study(granules=args.granules, model=args.model, progress=progress)
    with out.writing() as folder:
        written = [write_study(rows, folder)] + plot_paper_study(rows, folder)
    if args.json:
        print_json({"rows": rows})
    else:
        print(format_table([[row[key] for key, _ in TABLE] for row in rows], [label for _, label in TABLE]))
        print()
        for path in written:
            print(f"wrote {path}")
    return 0
