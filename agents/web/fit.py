"""The fit page's work: a tray test fitted as `spreadgym fit` fits it, one fit at a time.

The tray CSV and the scene come as text (the body is capped at 1 MB) and go through the
CLI's own parsers, so a bad one is the CLI's one-line message.
"""

from __future__ import annotations

import json
import threading
from typing import Any, Optional

from pydantic import BaseModel, ConfigDict, Field

from spreadgym.agents.web.pattern import SimulateRequest, json_text, scene_of
from spreadgym.config.base import brief
from spreadgym.errors import SpreadgymError

_FIT_LOCK = threading.Lock()  # a fit uses every core for seconds to minutes


class FitRequest(BaseModel):
    """`POST /api/fit`: the flags of `spreadgym fit`, the tray file as text."""

    model_config = ConfigDict(extra="forbid")
    scene: str = Field(default="paper", max_length=200, description="shipped scene name")
    yaml: Optional[str] = Field(default=None, description="an uploaded scene's YAML text (instead of a name)")
    set: dict[str, Any] = Field(default_factory=dict, description="--set KEY=VALUE: the test's settings")
    trays: str = Field(description="the tray test CSV: columns x_m, mass_g[, pass]")
    fit: list[str] = Field(description="--fit KEY=LO:HI items")
    model: str = "auto"
    granules: Optional[int] = None
    seed: Optional[int] = None


def fit_payload(request: FitRequest) -> str:
    """`spreadgym fit --json`'s answer, with the fitted scene's YAML text and the pictures' data."""
    from spreadgym.config.scene import scene_with
    from spreadgym.fit.outputs import payload, predict, scene_yaml
    from spreadgym.fit.run import FIT_GRANULES, fit_tray_test
    from spreadgym.fit.space import parse_fit_specs
    from spreadgym.fit.trays import parse_trays
    from spreadgym.physics.selection import MODELS

    if request.model not in MODELS:
        raise SpreadgymError(f"model: unknown model {brief(request.model)}; allowed: {', '.join(MODELS)}")
    granules = FIT_GRANULES if request.granules is None else request.granules
    if not 1 <= granules <= 1_000_000:
        raise SpreadgymError(f"granules: {granules} is out of range; allowed: in [1, 1000000]")
    if request.seed is not None and not 0 <= request.seed <= 2**32 - 1:
        raise SpreadgymError(f"seed: {request.seed} is out of range; allowed: in [0, {2**32 - 1}]")
    scene = scene_of(SimulateRequest(scene=request.scene, yaml=request.yaml, set=request.set))
    seed = scene.sim.seed if request.seed is None else request.seed
    scene = scene_with(scene, {"sim.seed": seed})
    space = parse_fit_specs(request.fit, scene)
    test = parse_trays(request.trays, scene.pattern.tray_width_m, "uploaded trays")
    if not _FIT_LOCK.acquire(blocking=False):
        raise SpreadgymError("fit: one is running already; wait for it")
    try:
        fit = fit_tray_test(scene, space, test, model=request.model, granules=granules, seed=seed)
        prediction = predict(fit)
    finally:
        _FIT_LOCK.release()
    data = json.loads(json_text(payload(fit, prediction, None)))
    plot = {"measured_x_m": test.x_m.tolist(), "measured_g": (1e3 * test.mass_kg).tolist(),
            "measured_pass": test.lane.tolist(), "center_m": prediction.center_m.tolist(),
            "fitted_g": prediction.mass_g.tolist(), "low_g": prediction.mass_low_g.tolist(),
            "high_g": prediction.mass_high_g.tolist(), "widths_m": prediction.widths_m.tolist(),
            "cv_percent": prediction.cv_percent.tolist(), "cv_low_percent": prediction.cv_low_percent.tolist(),
            "cv_high_percent": prediction.cv_high_percent.tolist()}
    return json.dumps({"fit": data, "scene_yaml_text": scene_yaml(fit), "plot": json.loads(json_text(plot)),
                       "threshold_percent": scene.pattern.cv_threshold_percent})
