"""`spreadgym calibrate`: spring-dashpot contact parameters (paper Eqs. 8-10, Table 3).

Three modes, exactly one per call:
  --mass KG --restitution E --contact-time S   stiffness/damping for these inputs
  --fertilizer NAME --surface NAME [--mass KG]  the library default for a measured pair
                                                (mass defaults to a d50 sphere)
  --paper-table                                 consistency check of the paper's Table 3
"""

from __future__ import annotations

import argparse
import sys
import warnings

from spreadgym.config.materials import load_library
from spreadgym.errors import SpreadgymError
from spreadgym.physics import calibration as cal
from spreadgym.report import format_table, print_json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mass", type=float, metavar="KG", help=f"granule mass, kg, in (0, {MAX_GRANULE_MASS_KG:g}]")
    parser.add_argument("--restitution", type=float, metavar="E", help="restitution, in (0, 1]")
    parser.add_argument("--contact-time", type=float, metavar="S",
                        help=f"contact time, s, in [{cal.CONTACT_TIME_RANGE_S[0]:g}, {cal.CONTACT_TIME_RANGE_S[1]:g}]")
    parser.add_argument("--fertilizer", metavar="NAME", help="library fertilizer (pair mode)")
    parser.add_argument("--surface", metavar="NAME", help="library surface (pair mode)")
    parser.add_argument(
        "--paper-table",
        action="store_true",
        help="check the paper's printed Table 3 stiffness/damping for consistency",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")


MAX_GRANULE_MASS_KG = 1e-2  # a 20 mm sphere of 2000 kg/m3 is 8e-3 kg


def granule_mass(value) -> float:
    """--mass checked: positive and no heavier than a fertilizer granule can be."""
    mass = cal.check_finite(value, "--mass")
    if not 0.0 < mass <= MAX_GRANULE_MASS_KG:
        raise cal.CalibrationError("--mass", mass, f"outside (0, {MAX_GRANULE_MASS_KG:g}] kg: not a fertilizer granule")
    return mass


def _given(args: argparse.Namespace, *names: str) -> list[str]:
    return ["--" + n.replace("_", "-") for n in names if getattr(args, n) is not None]


def _contact_payload(mass: float, result: cal.SpringDashpot) -> dict:
    return {
        "stiffness_n_per_m": result.stiffness_n_per_m,
        "damping_ns_per_m": result.damping_ns_per_m,
        "damping_ratio": result.damping_ratio,
        "critical_time_step_s": cal.critical_time_step(
            mass, result.stiffness_n_per_m, result.damping_ns_per_m
        ),
    }


def _print_contact(payload: dict) -> None:
    units = {
        "mass_kg": "kg",
        "restitution": "-",
        "contact_time_s": "s",
        "stiffness_n_per_m": "N/m",
        "damping_ns_per_m": "N s/m",
        "damping_ratio": "-",
        "critical_time_step_s": "s",
    }
    rows = [(key, value, units.get(key, "")) for key, value in payload.items()]
    print(format_table(rows, header=("quantity", "value", "unit")))


def _paper_table(args: argparse.Namespace) -> int:
    clash = _given(args, "mass", "restitution", "contact_time", "fertilizer", "surface")
    if clash:
        raise SpreadgymError(f"--paper-table: cannot be combined with {', '.join(clash)}")
    rows = cal.paper_table_consistency(load_library())
    if args.json:
        print_json({"rows": [row.as_dict() for row in rows]})
        return 0
    print(
        format_table(
            [
                (
                    r.fertilizer,
                    r.surface,
                    r.restitution,
                    r.contact_time_s * 1e6,
                    r.paper_stiffness_n_per_m,
                    r.paper_damping_ns_per_m,
                    r.mass_from_stiffness_kg * 1e6,
                    r.mass_from_damping_kg * 1e6,
                    r.stiffness_damping_mass_ratio,
                    r.stiffness_mass_over_median,
                    "yes" if r.consistent else "NO",
                )
                for r in rows
            ],
            header=(
                "fertilizer",
                "surface",
                "e",
                "t us",
                "k N/m",
                "c Ns/m",
                "m(k) mg",
                "m(c) mg",
                "m(k)/m(c)",
                "m(k)/median",
                "consistent",
            ),
        )
    )
    if rows:
        print(
            f"median stiffness-implied mass {rows[0].median_mass_kg * 1e6:.1f} mg; "
            f"flagged when m(k) is > {cal.MEDIAN_MASS_FACTOR:g}x from the median or "
            f"m(k)/m(c) is off by > {cal.STIFFNESS_DAMPING_MASS_FACTOR:g}x"
        )
    for r in rows:
        for reason in r.reasons:
            print(f"{r.fertilizer}/{r.surface}: {reason}")
    return 0


def _pair(args: argparse.Namespace) -> int:
    missing = [
        flag
        for flag, value in (("--fertilizer", args.fertilizer), ("--surface", args.surface))
        if value is None
    ]
    if missing:
        raise SpreadgymError(
            f"{missing[0]}: missing; the pair mode needs both --fertilizer and --surface"
        )
    clash = _given(args, "restitution", "contact_time")
    if clash:
        raise SpreadgymError(
            f"{', '.join(clash)}: cannot be combined with --fertilizer/--surface "
            "(the pair's measured values are used)"
        )
    library = load_library()
    fert = library.fertilizer(args.fertilizer)
    library.check_surface(args.surface)
    if args.mass is None:
        mass = cal.sphere_mass(fert.size.d50_m, fert.particle_density_kg_m3)
    else:
        mass = granule_mass(args.mass)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cal.PaperTableWarning)
        result = cal.default_contact(args.fertilizer, args.surface, mass, library)
    flagged = cal.paper_row_flagged(args.fertilizer, args.surface, library)
    payload = {
        "fertilizer": args.fertilizer,
        "surface": args.surface,
        "mass_kg": mass,
        "restitution": fert.pair("restitution", args.surface),
        "contact_time_s": fert.pair("impact_time_s", args.surface),
        **_contact_payload(mass, result),
        "paper_row_flagged": flagged,
    }
    if flagged:
        print(
            f"note: the paper's Table 3 row {args.fertilizer}/{args.surface} is flagged as "
            "inconsistent (see `spreadgym calibrate --paper-table`); its measured e and t "
            "are used as printed",
            file=sys.stderr,
        )
    if args.json:
        print_json(payload)
    else:
        _print_contact(payload)
    return 0


def run(args: argparse.Namespace) -> int:
    if args.paper_table:
        return _paper_table(args)
    if args.fertilizer is not None or args.surface is not None:
        return _pair(args)
    missing = [
        flag
        for flag, value in (
            ("--mass", args.mass),
            ("--restitution", args.restitution),
            ("--contact-time", args.contact_time),
        )
        if value is None
    ]
    if missing:
        raise SpreadgymError(
            f"missing {', '.join(missing)}: give --mass, --restitution and --contact-time, "
            "or --fertilizer and --surface, or --paper-table"
        )
    mass = granule_mass(args.mass)
    e = cal.check_restitution(args.restitution, "--restitution")
    t = cal.check_contact_time(args.contact_time, "--contact-time")
    payload = _contact_payload(mass, cal.spring_dashpot(mass, e, t))
    if args.json:
        print_json(payload)
    else:
        _print_contact({"mass_kg": mass, "restitution": e, "contact_time_s": t, **payload})
    return 0
