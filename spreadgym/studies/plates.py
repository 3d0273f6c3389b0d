"""The compiled plate stage against the full model's stepped (pymunk) plate stage.

Paired on the same departures: each seed's granules go once through the compiled
spinner, and its departures then pass the plates by both stages; everything after the
plates (flight, trays, estimate) is the same code. Plain runs (one release angle per
granule), so every granule meets the plates through the stage under test. What differs
is the plate stage alone; the spinner models' own difference is measured on the
converged references (docs/fidelity.md). Settings: the plate scenes of the reference
family (configs/references.yaml).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from spreadgym.config.materials import load_library
from spreadgym.config.scene import scene_with
from spreadgym.physics.selection import SPINNER_MODELS
from spreadgym.spread.pipeline import finish_scene, plan_scene
from spreadgym.studies.references import reference_family

SEEDS = 16
FIRST_SEED = 2000  # shares no granules with the references (replicates from 0)


def plate_settings() -> dict:
    """name -> scene of every plate scene of the reference family."""
    return {name: scene for name, scene in reference_family().items() if scene.deflectors}


def plate_stage_rows(seeds: int = SEEDS, progress: Callable[[str], None] = lambda _: None) -> list[dict]:
    """Per plate setting: the mean CV at the target with each plate stage and their paired
    difference (compiled - pymunk) with its standard error over `seeds` seeds."""
    library = load_library()
    rows = []
    for name, scene in plate_settings().items():
        progress(f"plates: {name}")
        cvs = {"rays": [], "pymunk": []}
        for seed in range(FIRST_SEED, FIRST_SEED + seeds):
            plan = plan_scene(scene_with(scene, {"sim.seed": seed, "sim.angle_copies": 1}), "compiled", library)
            departures = SPINNER_MODELS["compiled"].run_batch(plan.spinner_runs())
            for stage, found in cvs.items():
                found.append(finish_scene(plan, departures, ci=False, deflector=stage).metrics.cv_percent_at_target)
        fast, full = np.array(cvs["rays"]), np.array(cvs["pymunk"])
        diff = fast - full
        rows.append({"setting": name, "granules": scene.sim.granules, "seeds": seeds,
                     "cv_compiled_percent": float(fast.mean()), "cv_pymunk_percent": float(full.mean()),
                     "diff_pp": float(diff.mean()), "diff_se_pp": float(diff.std(ddof=1) / np.sqrt(seeds))})
    return rows


def plates_markdown(rows: list[dict]) -> str:
    lines = ["# The compiled plate stage against the pymunk plate stage (paired, same departures)", "",
             "| setting | granules x seeds | CV compiled plates (%) | CV pymunk plates (%) | diff ± SE (pp) |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['setting']} | {r['granules']} x {r['seeds']} | {r['cv_compiled_percent']:.2f} | "
              f"{r['cv_pymunk_percent']:.2f} | {r['diff_pp']:+.2f} ± {r['diff_se_pp']:.2f} |" for r in rows]
    return "\n".join(lines) + "\n"
