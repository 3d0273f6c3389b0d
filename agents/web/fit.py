"""The fit page's work: a tray test fitted as `spreadgym fit` fits it, one fit at a time
(in the server's fit worker, `agents.web.workers`: `fit_task` is what it calls).

The tray CSV and the scene come as text (the body is capped at 1 MB) and go through the
CLI's own parsers, so a bad one is the CLI's one-line message.
"""

from __future__ import annotations

import json
from typing import Any, Callable, Optional

from pydantic import BaseModel, ConfigDict, Field

from spreadgym.agents.web.pattern import SimulateRequest, json_text, scene_of
from spreadgym.config.base import brief
from spreadgym.errors import SpreadgymError


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


def fit_inputs(request: FitRequest):
    """(scene, space, test, granules, seed) of a request, every input checked as `spreadgym
    fit` checks it (in the server, before the fit waits its turn; again in the worker)."""
    from spreadgym.config.scene import scene_with
    from spreadgym.fit.run import FIT_GRANULES
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
    scene_with(scene, {"sim.granules": granules})  # the landing-point budget of one evaluation, named
    space = parse_fit_specs(request.fit, scene, fixed=request.set)
    test = parse_trays(request.trays, scene.pattern.tray_width_m, "uploaded trays")
    return scene, space, test, granules, seed


def fit_task(args: dict, _check: Callable[[], None]) -> str:
    """The worker's `POST /api/fit`: `spreadgym fit --json`'s answer, with the fitted scene's
    YAML text and the pictures' data (the measured trays' own CV curve beside the fitted one)."""
    from spreadgym.fit.outputs import payload, predict, scene_yaml
    from spreadgym.fit.run import fit_tray_test

    scene, space, test, granules, seed = fit_inputs(FitRequest(**args))
    fit = fit_tray_test(scene, space, test, model=args["model"], granules=granules, seed=seed)
    prediction = predict(fit)
    data = json.loads(json_text(payload(fit, prediction, None)))
    plot = {"measured_x_m": test.x_m.tolist(), "measured_g": (1e3 * test.mass_kg).tolist(),
            "measured_pass": test.lane.tolist(), "center_m": prediction.center_m.tolist(),
            "fitted_g": prediction.mass_g.tolist(), "low_g": prediction.mass_low_g.tolist(),
            "high_g": prediction.mass_high_g.tolist(), "widths_m": prediction.widths_m.tolist(),
            "cv_percent": prediction.cv_percent.tolist(), "cv_low_percent": prediction.cv_low_percent.tolist(),
            "cv_high_percent": prediction.cv_high_percent.tolist(),
            "measured_cv_percent": None if prediction.measured.cv_percent is None else
            prediction.measured.cv_percent.tolist()}
    return json.dumps({"fit": data, "scene_yaml_text": scene_yaml(fit), "plot": json.loads(json_text(plot)),
                       "threshold_percent": scene.pattern.cv_threshold_percent})
