"""`spreadgym materials`: list the material library (Tables 1-3 of the seed paper)."""

from __future__ import annotations

import argparse

from spreadgym.config.materials import PAIR_QUANTITIES, Fertilizer, load_library
from spreadgym.report import format_table, print_json

_PAIR_TITLES = {
    "friction": "Static friction coefficient (tilting plane, -)",
    "restitution": "Coefficient of restitution (bounce test, -)",
    "impact_time_s": "Impact (contact) time (high-speed video, s)",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")


def fertilizer_payload(fert: Fertilizer) -> dict:
    """One fertilizer as plain JSON-ready data (SI units; null = not measured)."""
    payload = {
        "description": fert.description,
        "particle_density_kg_m3": fert.particle_density_kg_m3,
        "bulk_density_kg_m3": fert.bulk_density_kg_m3,
        "repose_angle_deg": fert.repose_angle_deg,
    }
    for quantity in PAIR_QUANTITIES:
        payload[quantity] = {
            surface: (None if value is None else float(value))
            for surface, value in getattr(fert, quantity).items()
        }
    payload["size"] = {
        "d50_m": fert.size.d50_m,
        "sd_m": fert.size.sd_m,
        "min_m": fert.size.min_m,
        "max_m": fert.size.max_m,
        "source": fert.size.source,
    }
    payload["test_conditions"] = dict(fert.test_conditions)
    return payload


def run(args: argparse.Namespace) -> int:
    library = load_library()
    if args.json:
        fertilizers = {name: fertilizer_payload(f) for name, f in library.fertilizers.items()}
        print_json({"fertilizers": fertilizers})
        return 0
    names = list(library.fertilizers)
    fertilizers = [library.fertilizers[n] for n in names]
    print("Fertilizers")
    print(
        format_table(
            [
                (
                    f.name,
                    f.particle_density_kg_m3,
                    f.bulk_density_kg_m3,
                    f.repose_angle_deg,
                    f.size.d50_m * 1e3,
                )
                for f in fertilizers
            ],
            header=(
                "fertilizer",
                "particle density kg/m3",
                "bulk density kg/m3",
                "repose angle deg",
                "d50 mm (assumed)",
            ),
        )
    )
    for quantity in PAIR_QUANTITIES:
        print()
        print(_PAIR_TITLES[quantity] + "; '-' = not measured")
        rows = [
            [surface] + [getattr(f, quantity).get(surface) for f in fertilizers]
            for surface in library.surfaces
        ]
        print(format_table(rows, header=["surface"] + names))
    print()
    print("Surfaces")
    print(format_table(list(library.surfaces.items()), header=("surface", "description")))
    return 0
