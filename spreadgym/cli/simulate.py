"""`spreadgym simulate`: run one scene end to end and report the spread pattern.

Runs of the scene are pooled until the CV at the target width has the standard error
asked for (`--precision`, spread.precision), and what is printed shows no more digits
than that standard error supports.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spreadgym.cli import arguments
from spreadgym.config.overrides import parse_assignments
from spreadgym.report import format_table, print_json, swath_text, with_error
from spreadgym.spread.precision import SIMULATE_MAX_RUNS, SIMULATE_PRECISION_PP, check_precision

MAX_RUNS_LIMIT = 4096


def precision_flag(text: str) -> float:
    """`--precision PP`: a standard error in percentage points (argparse names the flag)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    try:
        return check_precision(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--precision: ")) from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.physics.selection import MODELS

    parser.add_argument("--scene", default="paper", help="shipped scene name or a YAML path (default: paper)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene key, VALUE parsed as YAML (e.g. spinner.rpm=800, deflectors=[])")
    parser.add_argument("--model", default="auto", choices=MODELS, help="spinner model (default: auto)")
    parser.add_argument("--precision", type=precision_flag, default=SIMULATE_PRECISION_PP, metavar="PP",
                        help="standard error wanted for the CV at the target width, in percentage points: runs "
                             f"are pooled until it is reached (default {SIMULATE_PRECISION_PP:g})")
    parser.add_argument("--max-runs", type=arguments.integer(2, MAX_RUNS_LIMIT), default=SIMULATE_MAX_RUNS,
                        metavar="N", help=f"at most N runs of sim.granules each (default {SIMULATE_MAX_RUNS})")
    parser.add_argument("--threads", type=arguments.THREADS, metavar="N",
                        help="threads to use (default: SPREADGYM_THREADS, else every core this process may use)")
    arguments.add_materials_flag(parser)
    arguments.add_device(parser)
    parser.add_argument("--json", action="store_true", help="print the metrics as JSON")
    parser.add_argument("--plot", type=arguments.output_folder, metavar="DIR",
                        help="write PNG pictures into DIR (made when the run is done; never over an input)")
    arguments.force_flag(parser)
    parser.add_argument("--report", type=Path, metavar="FILE",
                        help="write a record worth printing (scene, machine, fertilizer, every setting, CV +- SE, "
                             "swath, the pattern and the CV curve, date, version) as FILE.html or FILE.pdf")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from spreadgym.config.scene import load_scene
    from spreadgym.device import set_device
    from spreadgym.spread.precision import simulate_precisely
    from spreadgym.threads import set_threads

    if args.threads is not None:
        set_threads(args.threads)
    if args.device is not None:
        set_device(args.device)
    scene = load_scene(args.scene, parse_assignments(args.overrides), args.materials)
    plots = None
    if args.plot:
        from spreadgym.out_folder import OutFolder, named_files
        from spreadgym.viz.plots import SIMULATION_PLOTS

        plots = OutFolder(args.plot, "simulate", SIMULATION_PLOTS, named_files(args.scene, args.materials), args.force,
                          marker=SIMULATION_PLOTS[0], flag="--plot")
        plots.check()
    if args.report is not None:
        from spreadgym.out_folder import named_files
        from spreadgym.viz.record import check_report_path

        check_report_path(args.report, named_files(args.scene, args.materials))
    with tqdm(desc="runs", unit="run", file=sys.stderr, disable=None, leave=False) as bar:
        precise = simulate_precisely(scene, args.precision, args.max_runs, model=args.model,
                                     tracks=30 if args.plot else 0, progress=lambda done, _cap: bar.update(1))
    written = []
    if plots is not None:
        from spreadgym.viz.plots import write_simulation_plots

        with plots.writing() as folder:
            written = write_simulation_plots(precise.as_result(), folder)
    payload = precise.to_json()
    if args.report is not None:
        from spreadgym.viz.record import write_report

        written.append(write_report(args.report, scene, payload, precise.as_result()))
    if args.json:
        print_json(payload)
    else:
        print(summary(payload, scene.name))
        for path in written:
            print(f"wrote {path}")
    return 0


def _departure_rows(d: dict) -> list[tuple[str, str]]:
    if d["speed_mean_m_s"] is None:
        return [("departure", "no granule left the spinner")]
    return [
        ("departure speed", f"{d['speed_mean_m_s']:.2f} +- {d['speed_std_m_s']:.2f} m/s"),
        ("departure angle", f"{d['angle_mean_deg']:.1f} deg from the tangent"),
        ("granule spin", f"{d['spin_mean_rad_s']:.0f} rad/s"),
        ("time on spinner", f"{1e3 * d['time_on_spinner_mean_s']:.1f} ms"),
    ]


def summary(m: dict, scene_name: str) -> str:
    """The headline numbers of a run, for people: the CV to the digits its standard error supports."""
    cv, se = m["cv_percent_at_target"], m["cv_standard_error_percent"]
    mass = m["mass"]
    precision = (f"standard error {m['precision_percent']:g} pp asked, "
                 + ("reached" if m["precision_met"] else "not reached" if se is not None else "none known")
                 + f" in {m['runs']} run(s)")
    rows = [
        ("model", f"{m['model']} ({m['model_reason']})"),
        ("time step", f"{m['dt_s']:.3g} s" if m["dt_s"] else "closed form"),
        ("granules", f"{m['granules_simulated']} in {m['runs']} run(s) ({m['outcomes']['departed']} departed)"),
        ("release angles", f"{m['angle_copies']} per granule ({m['angle_copies_reason']})"),
        *_departure_rows(m["departure"]),
        ("CV at target", "nothing landed" if cv is None else
         f"{with_error(cv, se, '%')} at {m['target_swath_m']:g} m ({m['driving']})"),
        ("precision", precision),
        ("effective swath", swath_text(m)),
        ("mass", f"released {1e3 * mass['released_kg']:.2f} g, landed {1e3 * mass['landed_kg']:.2f} g, "
                 f"retained {1e3 * mass['retained_kg']:.2f} g"
                 + (f", intercepted {1e3 * mass['intercepted_kg']:.2f} g" if mass['intercepted_kg'] else "")),
        ("wall time", f"{m['wall_s']:.2f} s"),
    ]
    notes = [("note", text) for text in m["notes"]]
    return f"scene {scene_name}\n" + format_table(rows + notes, ("quantity", "value"))
