"""The typed figures of one simulated run; `to_json()` is `spreadgym simulate --json`.

Masses in kg, widths in m, CVs in % (None where nothing landed or no estimate
exists), wall time in s. The tray row is held once (`trays`) and the landed mass is
read off it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from spreadgym.spread.pattern import Trays


@dataclass(frozen=True)
class RunMetrics:
    model: str  # spinner model that ran
    model_reason: str  # why it was chosen
    dt_s: Optional[float]  # time step of a stepped model; None for closed forms
    granules: int  # simulated on the spinner
    angle_copies: int  # release angles per simulated granule in the pattern (spread.rotations)
    angle_copies_reason: str  # why that many
    outcomes: dict[str, int]  # granule count per outcome on the spinner
    departure: dict[str, Optional[float]]  # means at the disc edge (see pipeline.departure_summary)
    target_swath_m: float
    driving: str
    tray_width_m: float
    cv_threshold_percent: float
    cv_percent_at_target: Optional[float]  # bias-corrected CV at the target swath
    cv_standard_error_percent: Optional[float]
    cv_raw_percent: Optional[float]  # plain CV of the pooled pattern
    cv_ci_percent: Optional[list[float]]  # 95 % interval, when asked for
    effective_swath_m: float  # largest bout width with CV <= threshold (0 if none)
    curve_bout_width_m: np.ndarray  # bout widths of the CV curve
    curve_cv_percent: np.ndarray  # corrected CV at each width (NaN where unknown)
    trays: Trays  # the single pass caught on the row of trays
    released_kg: float
    retained_kg: float  # mass that never left the spinner
    intercepted_kg: float = 0.0  # twin discs: mass thrown onto the other disc, not in the pattern
    notes: list[str] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def landed_kg(self) -> float:
        return self.trays.total_kg

    @property
    def landed_fraction(self) -> Optional[float]:
        """Landed over released mass, None when nothing was released."""
        return self.landed_kg / self.released_kg if self.released_kg > 0 else None

    def to_json(self) -> dict:
        """The JSON object of `spreadgym simulate --json` (arrays stay numpy; the writer converts)."""
        return {
            "model": self.model,
            "model_reason": self.model_reason,
            "dt_s": self.dt_s,
            "granules": self.granules,
            "angle_copies": self.angle_copies,
            "angle_copies_reason": self.angle_copies_reason,
            "outcomes": self.outcomes,
            "departure": self.departure,
            "target_swath_m": self.target_swath_m,
            "driving": self.driving,
            "tray_width_m": self.tray_width_m,
            "cv_threshold_percent": self.cv_threshold_percent,
            "cv_percent_at_target": self.cv_percent_at_target,
            "cv_standard_error_percent": self.cv_standard_error_percent,
            "cv_raw_percent": self.cv_raw_percent,
            "cv_ci_percent": self.cv_ci_percent,
            "effective_swath_m": self.effective_swath_m,
            "cv_curve": {"bout_width_m": self.curve_bout_width_m, "cv_percent": self.curve_cv_percent},
            "trays": {"center_m": self.trays.center_m, "mass_kg": self.trays.mass_kg},
            "mass": {"released_kg": self.released_kg, "landed_kg": self.landed_kg, "retained_kg": self.retained_kg,
                     "intercepted_kg": self.intercepted_kg},
            "notes": self.notes,
            "wall_s": self.wall_s,
        }
