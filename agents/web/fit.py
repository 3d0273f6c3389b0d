"""The fit page's work: a tray test fitted as `spreadgym fit` fits it, and the advice `spreadgym advise` gives,
one at a time (in the server's fit worker, `agents.web.workers`: `fit_task` and `advise_task` are what it calls).

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


class TrayTestRequest(BaseModel):
    """What a request about a tray test gives: the machine, the test's settings and the tray file as text."""

    model_config = ConfigDict(extra="forbid")
    scene: str = Field(default="paper", max_length=200, description="shipped scene name")
    yaml: Optional[str] = Field(default=None, description="an uploaded scene's YAML text (instead of a name)")
    set: dict[str, Any] = Field(default_factory=dict, description="--set KEY=VALUE: the test's settings")
    trays: str = Field(description="the tray test CSV: columns x_m, mass_g[, pass]")


class FitRequest(TrayTestRequest):
    """`POST /api/fit`: the flags of `spreadgym fit`, the tray file as text."""

    fit: list[str] = Field(description="--fit KEY=LO:HI items")
    model: str = "auto"
    granules: Optional[int] = None
    seed: Optional[int] = None


class AdviseRequest(TrayTestRequest):
    """`POST /api/advise`: the flags of `spreadgym advise`, the tray file as text."""

    width: float = Field(description="--width: the working width wanted, m")
    fit: Optional[list[str]] = Field(default=None, description="--fit KEY=LO:HI items (default: advise's)")
    budget: Optional[int] = None
    granules: Optional[int] = None
    fit_granules: Optional[int] = None
    seed: Optional[int] = None


def _in_range(name: str, value: Optional[int], low: int, high: int, default: int) -> int:
    """`value` (or `default` where not given), refused naming `name` outside [low, high]."""
    if value is not None and not low <= value <= high:
        raise SpreadgymError(f"{name}: {value} is out of range; allowed: in [{low}, {high}]")
    return default if value is None else value


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
    granules = _in_range("granules", request.granules, 1, 1_000_000, FIT_GRANULES)
    _in_range("seed", request.seed, 0, 2**32 - 1, 0)
    scene = scene_of(SimulateRequest(scene=request.scene, yaml=request.yaml, set=request.set))
    seed = scene.sim.seed if request.seed is None else request.seed
    scene = scene_with(scene, {"sim.seed": seed})
    scene_with(scene, {"sim.granules": granules})  # the landing-point budget of one evaluation, named
    space = parse_fit_specs(request.fit, scene, fixed=request.set)
    test = parse_trays(request.trays, scene.pattern.tray_width_m, "uploaded trays")
    return scene, space, test, granules, seed


def advise_inputs(request: AdviseRequest) -> tuple:
    """(scene, test, fit specs, budget, granules, fit granules) of a request, every input checked as `spreadgym
    advise` checks it (in the server, before the advice waits its turn; again in the worker)."""
    from spreadgym.agents.advise.run import ADVICE_BUDGET, ADVICE_GRANULES, DEFAULT_FIT, check_width
    from spreadgym.agents.chart.spec import MAX_BUDGET
    from spreadgym.fit.run import FIT_GRANULES
    from spreadgym.fit.space import parse_fit_specs
    from spreadgym.fit.trays import parse_trays

    budget = _in_range("budget", request.budget, 4, MAX_BUDGET, ADVICE_BUDGET)
    granules = _in_range("granules", request.granules, 1, 1_000_000, ADVICE_GRANULES)
    fit_granules = _in_range("fit_granules", request.fit_granules, 1, 1_000_000, FIT_GRANULES)
    _in_range("seed", request.seed, 0, 2**32 - 1, 0)
    scene = scene_of(SimulateRequest(scene=request.scene, yaml=request.yaml, set=request.set))
    check_width(request.width, scene)
    specs = request.fit or list(DEFAULT_FIT)
    parse_fit_specs(specs, scene, fixed=request.set)
    test = parse_trays(request.trays, scene.pattern.tray_width_m, "uploaded trays")
    return scene, test, specs, budget, granules, fit_granules


def _plot(test, prediction) -> dict:
    """The fit's pictures' data: the measured trays and their own CV curve, the fitted pattern and CV curve
    with their bands."""
    return {"measured_x_m": test.x_m.tolist(), "measured_g": (1e3 * test.mass_kg).tolist(),
            "measured_pass": test.lane.tolist(), "center_m": prediction.center_m.tolist(),
            "fitted_g": prediction.mass_g.tolist(), "low_g": prediction.mass_low_g.tolist(),
            "high_g": prediction.mass_high_g.tolist(), "widths_m": prediction.widths_m.tolist(),
            "cv_percent": prediction.cv_percent.tolist(), "cv_low_percent": prediction.cv_low_percent.tolist(),
            "cv_high_percent": prediction.cv_high_percent.tolist(),
            "measured_cv_percent": None if prediction.measured.cv_percent is None else
            prediction.measured.cv_percent.tolist()}


def fit_task(args: dict, _check: Callable[[], None]) -> str:
    """The worker's `POST /api/fit`: `spreadgym fit --json`'s answer, with the fitted scene's
    YAML text and the pictures' data (the measured trays' own CV curve beside the fitted one)."""
    from spreadgym.fit.outputs import payload, predict, scene_yaml
    from spreadgym.fit.run import fit_tray_test

    scene, space, test, granules, seed = fit_inputs(FitRequest(**args))
    fit = fit_tray_test(scene, space, test, model=args["model"], granules=granules, seed=seed)
    prediction = predict(fit)
    data = json.loads(json_text(payload(fit, prediction, None)))
    return json.dumps({"fit": data, "scene_yaml_text": scene_yaml(fit),
                       "plot": json.loads(json_text(_plot(test, prediction))),
                       "threshold_percent": scene.pattern.cv_threshold_percent})


def advise_task(args: dict, _check: Callable[[], None]) -> str:
    """The worker's `POST /api/advise`: `spreadgym advise --json`'s answer, with the fit's pictures' data."""
    from spreadgym.agents.advise.run import advice_payload, advise
    from spreadgym.fit.outputs import payload, predict

    request = AdviseRequest(**args)
    scene, test, specs, budget, granules, fit_granules = advise_inputs(request)
    advice = advise(scene, test, request.width, fit=specs, budget=budget, granules=granules,
                    fit_granules=fit_granules, seed=request.seed, fixed=request.set)
    prediction = predict(advice.fit)
    data = json.loads(json_text(advice_payload(advice, payload(advice.fit, prediction, None))))
    return json.dumps({"advice": data, "plot": json.loads(json_text(_plot(test, prediction))),
                       "threshold_percent": scene.pattern.cv_threshold_percent})
