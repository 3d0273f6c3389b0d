"""spreadgym against published measurements (`make bench`, section validation; docs/validation.md).

1. Outlet angles (villette2010 in configs/materials.yaml): equivalent friction
   coefficients (EFC) of ammonium nitrate, NPK and KCl, each inverted from the outlet
   angles of particles leaving a flat disc with radial vanes at 800 rpm through a
   sliding-particle model. The paper's disc geometry was not available to us, so the
   measurement is carried to our calibration disc (`CALIBRATION_DISC`) the way it was
   made: the outlet angle of a point sliding with friction EFC from the feed radius to
   the rim (`outlet.point_slider_outlet_angle_deg`), beside its geometry-free asymptote.
   The simulated angle is the mean angle of the departed granules' velocity from the
   tangent (machine frame), on the compiled and on the full model.
2. Away from the calibration case: the same comparison over disc radii, feed radii and
   speeds (`SWEEP`): how far each calibrated granule still behaves as one coefficient.
3. Terminal velocities (hula2017): the flight model's terminal speed of the library's
   granules against the measured critical velocities.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from spreadgym.config.materials import load_library
from spreadgym.config.scene import Flight, load_scene
from spreadgym.physics.analytic import outlet
from spreadgym.physics.departure import Departure
from spreadgym.physics.selection import SPINNER_MODELS
from spreadgym.spread.flight import terminal_speed_m_s
from spreadgym.spread.pipeline import plan_scene

MEASURED_EFC = {"ammonium-nitrate": 0.13, "npk": 0.14, "potassium-chloride": 0.44}
"""villette2010 (abstract): flat disc with radial vanes at 800 rpm."""
MEASURED_TERMINAL_M_S = {"urea": 8.53, "calcium-ammonium-nitrate": 12.43}
"""hula2017 (abstract): mean critical velocity in a vertical upward airstream."""
CALIBRATION_DISC = ("field", {"spinner.rpm": 800.0, "feed.radius_m": 0.08, "feed.spread_m": 0.005,
                              "feed.drop_height_m": 0.0})
"""The field scene's flat 600 mm steel disc with four radial vanes from 60 mm, fed 80 mm
from the axis (a feed near the centre, as in outlet-angle tests), at 800 rpm."""
COMPARED = ("ammonium-nitrate", "npk", "potassium-chloride", "compound-10-16-10")
"""The compound is the seed study's NPK with its own measured (tilting-plane) friction."""
TARGET_DEG = 1.0
SWEEP = [  # (disc radius m, inner end of the vanes m, feed radius m, rpm)
    (0.15, 0.025, 0.043, 800.0), (0.225, 0.045, 0.06, 800.0), (0.3, 0.06, 0.12, 800.0),
    (0.3, 0.06, 0.08, 500.0), (0.3, 0.06, 0.08, 1000.0), (0.15, 0.025, 0.043, 1100.0),
]


def outlet_angles_deg(departure: Departure) -> np.ndarray:
    """Angle (deg) of each departed granule's velocity from the tangent at its position."""
    p, v = departure.position_m[departure.departed], departure.velocity_m_s[departure.departed]
    r = np.hypot(p[:, 0], p[:, 1])
    radial = (p[:, 0] * v[:, 0] + p[:, 1] * v[:, 1]) / r
    tangential = (p[:, 0] * v[:, 1] - p[:, 1] * v[:, 0]) / r
    return np.degrees(np.arctan2(radial, np.abs(tangential)))


def disc_scene(fertilizer: str, radius_m: float = 0.3, inner_m: float = 0.06, feed_m: float = 0.08,
               rpm: float = 800.0, granules: int = 2048):
    """The outlet-angle disc (`CALIBRATION_DISC` with the geometry given) for `fertilizer`."""
    name, overrides = CALIBRATION_DISC
    return load_scene(name, {**overrides, "fertilizer": fertilizer, "spinner.radius_m": radius_m,
                             "vanes.inner_radius_m": inner_m, "feed.radius_m": feed_m, "spinner.rpm": rpm,
                             "sim.granules": granules})


def simulated_angle_deg(scene, model: str) -> tuple[float, float]:
    """(mean, standard error) of the outlet angle of `scene`'s granules on `model`."""
    run, granules, contacts = plan_scene(scene, model, load_library(), 0).spinner_runs()[0]
    angles = outlet_angles_deg(SPINNER_MODELS[model].run(run, granules, contacts))
    return float(angles.mean()), float(angles.std(ddof=1) / math.sqrt(angles.size))


def measured_angle_deg(efc: float, scene) -> float:
    """The measured EFC carried to `scene`'s disc: the sliding point's outlet angle."""
    return outlet.point_slider_outlet_angle_deg(efc, abs(scene.spinner.omega_rad_s), scene.feed.radius_m,
                                                scene.spinner.radius_m)


def _efc(fertilizer: str) -> float:
    """The published EFC a fertilizer is compared with (the compound: villette2010's NPK)."""
    return MEASURED_EFC.get(fertilizer, MEASURED_EFC["npk"])


def outlet_rows(models=("compiled", "pymunk"), granules: dict[str, int] | None = None,
                progress: Callable[[str], None] = lambda _: None) -> list[dict]:
    """One row per compared fertilizer on the calibration disc."""
    granules = granules or {"compiled": 4096, "pymunk": 1024}
    rows = []
    for fertilizer in COMPARED:
        fert = load_library().fertilizer(fertilizer)
        efc = _efc(fertilizer)
        row = {"fertilizer": fertilizer, "efc": efc, "vane_friction": fert.pair("friction", "steel"),
               "rolling_resistance": fert.pair("rolling_resistance", "steel"),
               "model_efc": outlet.equivalent_friction(fert.pair("friction", "steel"),
                                                       fert.pair("rolling_resistance", "steel")),
               "asymptote_deg": outlet.outlet_angle_deg(efc, math.inf, kappa=math.inf)}
        for model in models:
            scene = disc_scene(fertilizer, granules=granules[model])
            progress(f"validation: {fertilizer} on {model}")
            mean, se = simulated_angle_deg(scene, model)
            row["measured_deg"] = measured_angle_deg(efc, scene)
            row[f"{model}_deg"], row[f"{model}_se_deg"] = mean, se
            row[f"{model}_diff_deg"] = mean - row["measured_deg"]
        rows.append(row)
    return rows


def sweep_rows(model: str = "compiled", granules: int = 2048,
               progress: Callable[[str], None] = lambda _: None) -> list[dict]:
    """Simulated minus measured outlet angle away from the calibration disc (`SWEEP`)."""
    rows = []
    for radius, inner, feed, rpm in SWEEP:
        for fertilizer in COMPARED:
            scene = disc_scene(fertilizer, radius, inner, feed, rpm, granules)
            progress(f"validation sweep: {fertilizer} R {radius} feed {feed} {rpm:g} rpm")
            mean, se = simulated_angle_deg(scene, model)
            measured = measured_angle_deg(_efc(fertilizer), scene)
            rows.append({"fertilizer": fertilizer, "radius_m": radius, "feed_m": feed, "rpm": rpm,
                         "measured_deg": measured, "simulated_deg": mean, "se_deg": se, "diff_deg": mean - measured})
    return rows


def terminal_rows() -> list[dict]:
    """The flight model's terminal speed of each library granule with a measured critical velocity."""
    library, flight = load_library(), Flight()
    rows = []
    for name, measured in MEASURED_TERMINAL_M_S.items():
        fert = library.fertilizer(name)
        row = {"fertilizer": name, "measured_m_s": measured, "simulated_m_s": None, "diff_percent": None,
               "d50_mm": None, "density_kg_m3": fert.particle_density_kg_m3}
        if fert.size is not None and fert.particle_density_kg_m3 is not None:
            speed = float(terminal_speed_m_s(np.array([fert.size.d50_m]), fert.particle_density_kg_m3, flight)[0])
            row.update(simulated_m_s=speed, diff_percent=100.0 * (speed / measured - 1.0), d50_mm=fert.size.d50_m * 1e3)
        rows.append(row)
    return rows


def write_validation(out: Path, progress: Optional[Callable[[str], None]] = None) -> list[dict]:
    """Run the three comparisons; write out/validation-sweep.csv and -terminal.csv; the
    outlet-angle rows (`make bench` writes them as validation.csv)."""
    say = progress or (lambda _: None)
    outlet = outlet_rows(progress=say)
    out.mkdir(parents=True, exist_ok=True)
    for name, rows in (("sweep", sweep_rows(progress=say)), ("terminal", terminal_rows())):
        with open(out / f"validation-{name}.csv", "w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return outlet
