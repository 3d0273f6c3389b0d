"""`spreadgym materials`: list the material library, what each fertilizer can run on, and
where every number comes from (`--json`)."""

from __future__ import annotations

import argparse

from spreadgym.cli import arguments
from spreadgym.config.materials import PAIR_QUANTITIES, Fertilizer, MaterialLibrary, load_library
from spreadgym.errors import MaterialError
from spreadgym.report import format_table, print_json

_PAIR_TITLES = {
    "friction": "Friction coefficient (sliding, -)",
    "restitution": "Coefficient of restitution (bounce test, -)",
    "impact_time_s": "Impact (contact) time (high-speed video, s)",
    "rolling_resistance": "Rolling resistance at the vanes (-)",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    arguments.add_materials_flag(parser)
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")


def runs_on(fert: Fertilizer) -> tuple[list[str], str]:
    """(surfaces where the fertilizer runs as disc and vanes, why not elsewhere): its
    density, size, friction and restitution there are all known."""
    try:
        fert.granule_properties()
    except MaterialError as exc:
        return [], str(exc)
    surfaces = [s for s in fert.friction if all(getattr(fert, q).get(s) is not None
                                               for q in ("friction", "restitution", "rolling_resistance"))]
    if not surfaces:
        return [], (f"{fert.name}: no surface with friction, restitution and rolling resistance all measured; "
                    "set them in the scene under contact: or in a materials file")
    return surfaces, ""


def fertilizer_payload(fert: Fertilizer) -> dict:
    """One fertilizer as plain JSON-ready data (SI units; null = not measured)."""
    surfaces, reason = runs_on(fert)
    payload = {
        "description": fert.description,
        "particle_density_kg_m3": fert.particle_density_kg_m3,
        "bulk_density_kg_m3": fert.bulk_density_kg_m3,
        "repose_angle_deg": fert.repose_angle_deg,
    }
    for quantity in PAIR_QUANTITIES:
        payload[quantity] = {surface: (None if value is None else float(value))
                             for surface, value in getattr(fert, quantity).items()}
    payload["size"] = None if fert.size is None else {"d50_m": fert.size.d50_m, "sd_m": fert.size.sd_m,
                                                       "min_m": fert.size.min_m, "max_m": fert.size.max_m}
    payload["test_conditions"] = dict(fert.test_conditions)
    payload["runs_on"] = surfaces
    payload["cannot_run"] = reason or None
    payload["provenance"] = dict(fert.provenance)
    return payload


def run(args: argparse.Namespace) -> int:
    library = load_library(extra=args.materials)
    if args.json:
        print_json({"fertilizers": {name: fertilizer_payload(f) for name, f in library.fertilizers.items()},
                    "sources": dict(library.sources)})
        return 0
    print(tables(library))
    return 0


def tables(library: MaterialLibrary) -> str:
    """The library as tables for people ('-' = not measured)."""
    fertilizers = list(library.fertilizers.values())
    names = [f.name for f in fertilizers]
    size = [(None, None) if f.size is None else (f.size.d50_m * 1e3, f.size.sd_m * 1e3) for f in fertilizers]
    parts = ["Fertilizers", format_table(
        [(f.name, f.particle_density_kg_m3, f.bulk_density_kg_m3, f.repose_angle_deg, d50, sd,
          ", ".join(runs_on(f)[0]) or "-") for f, (d50, sd) in zip(fertilizers, size)],
        header=("fertilizer", "particle density kg/m3", "bulk density kg/m3", "repose angle deg", "d50 mm",
                "s.d. mm", "runs on"))]
    surfaces = list(dict.fromkeys([*library.surfaces, *(s for f in fertilizers for s in f.friction)]))
    for quantity in PAIR_QUANTITIES:
        rows = [[surface] + [getattr(f, quantity).get(surface) for f in fertilizers] for surface in surfaces]
        parts += ["", _PAIR_TITLES[quantity] + "; '-' = not measured", format_table(rows, header=["surface"] + names)]
    blocked = [(f.name, runs_on(f)[1]) for f in fertilizers if not runs_on(f)[0]]
    if blocked:
        parts += ["", "Cannot run as they stand", format_table(blocked, header=("fertilizer", "why"))]
    parts += ["", "Surfaces", format_table(list(library.surfaces.items()), header=("surface", "description")),
              "", "Where each number comes from: spreadgym materials --json (provenance, sources); docs/validation.md"]
    return "\n".join(parts)
