"""Synthetic tray tests at known parameters, to check a fit against the truth.

The truth is a simulated single pass (any spinner model; the full model for honest
checks of the compiled one), caught by the scene's trays (`pattern.tray_width_m`,
centred on the axis), scaled to `total_g` grams over the row and multiplied tray by
tray by log-normal catch noise exp(catch_sd z), z ~ N(0, 1): about `catch_sd` relative
s.d. per tray.
"""

from __future__ import annotations

from typing import Mapping, Optional

import numpy as np

from spreadgym.config.scene import Scene, scene_with
from spreadgym.fit.trays import TrayTest
from spreadgym.spread.pipeline import run_scene

CATCH_SD = 0.05
TOTAL_G = 2000.0  # caught over the row in one pass: a few hundred grams in the fullest trays


def synthetic_tray_test(scene: Scene, truth: Mapping[str, float], model: str = "pymunk", catch_sd: float = CATCH_SD,
                        total_g: float = TOTAL_G, noise_seed: int = 0, granules: Optional[int] = None,
                        sim_seed: int = 1_000_003) -> TrayTest:
    """A one-pass tray test of `scene` with the keys `truth` set, simulated with `model`
    (`granules` per run, default the scene's; `sim_seed` differs from any fit's seed so
    the fit does not share the truth's granules), noise drawn from `noise_seed`."""
    overrides = {**truth, "sim.seed": sim_seed}
    if granules is not None:
        overrides["sim.granules"] = granules
    result = run_scene(scene_with(scene, overrides), model=model, ci=False)
    trays = result.metrics.trays
    shares = trays.mass_kg / trays.total_kg
    noise = np.exp(catch_sd * np.random.default_rng(noise_seed).standard_normal(shares.size))
    mass_kg = shares * total_g * 1e-3 * noise
    return TrayTest(trays.center_m.copy(), mass_kg, np.zeros(shares.size, dtype=np.int64), trays.width_m,
                    f"synthetic {scene.name} ({model}) at " + ", ".join(f"{k}={v:g}" for k, v in truth.items()))
