"""`spreadgym simulate`: run one scene end to end and report the spread pattern."""

from __future__ import annotations

import argparse
import sys

from spreadgym.cli import arguments
from spreadgym.config.overrides import parse_assignments
from spreadgym.report import format_table, print_json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.physics.selection import MODELS

    parser.add_argument("--scene", default="paper", help="shipped scene name or a YAML path (default: paper)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene key, VALUE parsed as YAML (e.g. spinner.rpm=800, deflectors=[])")
    parser.add_argument("--model", default="auto", choices=MODELS, help="spinner model (default: auto)")
    parser.add_argument("--json", action="store_true", help="print the metrics as JSON")
    parser.add_argument("--plot", type=arguments.output_folder, metavar="DIR", help="write PNG pictures into DIR")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from spreadgym.config.scene import load_scene
    from spreadgym.spread.pipeline import run_scene

    scene = load_scene(args.scene, parse_assignments(args.overrides))
    with tqdm(desc="spinner", unit="ms", file=sys.stderr, disable=None, leave=False,
              bar_format="{desc}: {n:.0f} ms simulated [{elapsed}]") as bar:
        def progress(t_s: float) -> None:
            bar.n = 1e3 * t_s
            bar.refresh() if int(bar.n) % 10 == 0 else None

        result = run_scene(scene, model=args.model, progress=progress, tracks=30 if args.plot else 0)
    written = []
    if args.plot:
        from spreadgym.viz.plots import write_simulation_plots

        written = write_simulation_plots(result, args.plot)
    if args.json:
        print_json(result.metrics.to_json())
    else:
        print(summary(result.metrics.to_json(), scene.name))
        for path in written:
            print(f"wrote {path}")
    return 0


def summary(m: dict, scene_name: str) -> str:
    """The headline numbers of a run, for people."""
    d = m["departure"]
    cv = m["cv_percent_at_target"]
    ci = m["cv_ci_percent"]
    rows = [
        ("model", f"{m['model']} ({m['model_reason']})"),
        ("time step", f"{m['dt_s']:.3g} s" if m["dt_s"] else "closed form"),
        ("granules", f"{m['granules']} ({m['outcomes']['departed']} departed)"),
        ("release angles", f"{m['angle_copies']} per granule ({m['angle_copies_reason']})"),
        ("departure speed", f"{d['speed_mean_m_s']:.2f} +- {d['speed_std_m_s']:.2f} m/s"),
        ("departure angle", f"{d['angle_mean_deg']:.1f} deg from the tangent"),
        ("granule spin", f"{d['spin_mean_rad_s']:.0f} rad/s"),
        ("time on spinner", f"{1e3 * d['time_on_spinner_mean_s']:.1f} ms"),
        ("CV at target", "nothing landed" if cv is None else
         f"{cv:.1f} % at {m['target_swath_m']:g} m ({m['driving']})"
         + (f", 95 % CI {ci[0]:.1f}-{ci[1]:.1f} %" if ci else "")),
        ("effective swath", f"{m['effective_swath_m']:g} m (CV <= {m['cv_threshold_percent']:g} %)"),
        ("mass", f"released {1e3 * m['mass']['released_kg']:.2f} g, landed {1e3 * m['mass']['landed_kg']:.2f} g, "
                 f"retained {1e3 * m['mass']['retained_kg']:.2f} g"
                 + (f", intercepted {1e3 * m['mass']['intercepted_kg']:.2f} g" if m['mass']['intercepted_kg'] else "")),
        ("wall time", f"{m['wall_s']:.2f} s"),
    ]
    return f"scene {scene_name}\n" + format_table(rows, ("quantity", "value"))
