"""Synthetic tray tests at known parameters, to check a fit against the truth.

The truth is a simulated single pass (any spinner model; the full model for honest
checks of the compiled one), caught by the scene's trays (`pattern.tray_width_m`,
centred on the axis), scaled to `total_g` grams over the row and multiplied tray by
tray by log-normal catch noise exp(catch_sd z), z ~ N(0, 1): about `catch_sd` relative
s.d. per tray. Simulated passes can be cached on disk (`cache`), keyed by the whole
scene and the model, so a re-fit does not simulate the truth again.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional

import numpy as np

from spreadgym.config.scene import Scene, scene_with
from spreadgym.fit.trays import TrayTest
from spreadgym.spread.pipeline import run_scene

CATCH_SD = 0.05
TOTAL_G = 2000.0  # caught over the row in one pass: a few hundred grams in the fullest trays
TRUTH_SEED = 1_000_003  # sim.seed of the truths: no fit uses it


@dataclass(frozen=True)
class SimulatedPass:
    """One simulated single pass on the scene's trays."""

    center_m: np.ndarray  # (T,) tray centres across the track, m
    replicate_kg: np.ndarray  # (K, T) each independent replicate's tray masses, kg
    width_m: float  # tray width, m

    @property
    def mass_kg(self) -> np.ndarray:
        return self.replicate_kg.sum(axis=0)


def simulated_pass(scene: Scene, model: str = "pymunk", cache: Optional[Path] = None) -> SimulatedPass:
    """`scene` simulated once with `model`; read from / written to `cache`/<hash>.npz when
    given (the hash covers every key of the scene and the model name)."""
    path = None
    if cache is not None:
        digest = hashlib.sha256(f"{model}\n{scene.model_dump_json()}".encode()).hexdigest()[:24]
        path = Path(cache) / f"{digest}.npz"
        if path.exists():
            with np.load(path) as stored:
                return SimulatedPass(stored["center_m"], stored["replicate_kg"], float(stored["width_m"]))
    result = run_scene(scene, model=model, ci=False)
    simulated = SimulatedPass(result.metrics.trays.center_m.copy(), np.asarray(result.replicate_masses_kg, float),
                              float(result.metrics.trays.width_m))
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(".part.npz")
        np.savez(partial, center_m=simulated.center_m, replicate_kg=simulated.replicate_kg, width_m=simulated.width_m)
        partial.replace(path)
    return simulated


def synthetic_tray_test(scene: Scene, truth: Mapping[str, float], model: str = "pymunk", catch_sd: float = CATCH_SD,
                        total_g: float = TOTAL_G, noise_seed: int = 0, granules: Optional[int] = None,
                        sim_seed: int = TRUTH_SEED, cache: Optional[Path] = None) -> TrayTest:
    """A one-pass tray test of `scene` with the keys `truth` set, simulated with `model`
    (`granules` per run, default the scene's; `sim_seed` differs from any fit's seed so
    the fit does not share the truth's granules), noise drawn from `noise_seed`; the
    noiseless pass cached in `cache` when given."""
    overrides = {**truth, "sim.seed": sim_seed}
    if granules is not None:
        overrides["sim.granules"] = granules
    simulated = simulated_pass(scene_with(scene, overrides), model, cache)
    shares = simulated.mass_kg / simulated.mass_kg.sum()
    noise = np.exp(catch_sd * np.random.default_rng(noise_seed).standard_normal(shares.size))
    mass_kg = shares * total_g * 1e-3 * noise
    return TrayTest(simulated.center_m.copy(), mass_kg, np.zeros(shares.size, dtype=np.int64), simulated.width_m,
                    f"synthetic {scene.name} ({model}) at " + ", ".join(f"{k}={v:g}" for k, v in truth.items()))
