"""Whether each granule leaves its disc rolling or sliding along the vane.

A granule rolling on a vane face leaves it with its contact point at rest on the face,
so its spin over the disc's carries its speed over the disc:
r |s - omega| = |v - omega z x c| (r its radius, m; s its spin, rad/s; v its horizontal
velocity, m/s; c its position from the disc's axis, m; omega the disc's rate, rad/s).
A sliding granule leaves with less spin than that, a granule with locked rotation with
none. Every spinner model reports the departure spin, so the regime is read the same
way from the compiled and the full model.

With free rotation the vane friction acts on the pattern through the regime: a granule
rolls while the friction it needs is within the friction limit (vane friction x normal
force), and any higher friction leaves it as it is. The compiled model holds a rolling
granule's contact point exactly, the full model's stepped contact lets it slip a little,
and the two turn granules from sliding to rolling at different frictions (docs/fit.md).
An interval inside which the vane friction turns granules over therefore places the fit
model's change of regime, not the spreader's friction (`uncertainty.determined`). Other
keys change the regime too (restitution: rebounds that settle into rolling), but there
the compiled model follows the full model's rebounds down to its time step and places
the change alike (docs/fit.md); only the friction's and the rolling resistance's are
counted (REGIME_KEYS).
"""

from __future__ import annotations

import numpy as np

from spreadgym.spread.discs import discs
from spreadgym.spread.pipeline import SimulationResult

REGIME_KEYS = ("contact.vane_friction", "contact.rolling_resistance")
"""The keys that set a roll's limits: the friction that holds it and the resistance that
slows it (with mu_r >= mu_v a granule slides); moving them turns granules over."""
ROLLING_SLIP = 0.01  # a granule leaves rolling when its contact point slips by under 1 % of its speed over the disc
# (the compiled model's rolling granules leave at exactly 0, the full model's at 0.001-0.005: its contact is stepped)


def rolling(result: SimulationResult) -> np.ndarray:
    """(N,) bool: the granule left its disc rolling (False for one the disc kept)."""
    parts = discs(result.scene)
    per_disc = result.granules.count // len(parts)  # every disc throws the same number (pipeline.plan_scene)
    centre = np.repeat(np.asarray([d.centre_m for d in parts], float), per_disc, axis=0)
    omega = np.repeat([d.scene.spinner.omega_rad_s for d in parts], per_disc)
    d = result.departure
    c = d.position_m - centre
    over_disc = d.velocity_m_s - omega[:, None] * np.stack([-c[:, 1], c[:, 0]], axis=1)
    spin_speed = result.granules.radius_m * np.abs(d.spin_rad_s - omega)
    return d.departed & (spin_speed >= (1.0 - ROLLING_SLIP) * np.hypot(over_disc[:, 0], over_disc[:, 1]))


def switched(first: np.ndarray, second: np.ndarray) -> float:
    """Share of the granules (the same ones: common random numbers) whose regime differs
    between two runs' `rolling`."""
    return float(np.mean(first != second)) if first.size else 0.0
