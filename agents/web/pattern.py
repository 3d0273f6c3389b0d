"""The pattern page's work: a scene from a shipped name or uploaded YAML with `--set`
overrides, run as `spreadgym simulate` runs it, and the data of its pictures.

Every input goes through the CLI's own checks (scene loader, override parser, precision
and run limits), so a bad one is the CLI's one-line message naming the key. The
simulations run in the server's worker process (`agents.web.workers`): `simulate_task`
and `pattern_task` are what it calls, `check_request` what the server checks first.
"""

from __future__ import annotations

import io
import json
import math
from typing import Any, Callable, Optional

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field

from spreadgym.cli.simulate import MAX_RUNS_LIMIT
from spreadgym.config.base import brief
from spreadgym.config.overrides import parse_assignment
from spreadgym.config.resources import YamlLimitError, available, parse_yaml
from spreadgym.config.scene import Scene, load_scene, scene_from_dict, scene_with
from spreadgym.config.settings import SettingsSpace
from spreadgym.errors import ConfigError, SpreadgymError
from spreadgym.report import print_json, swath_text, with_error
from spreadgym.spread.precision import (
    REFERENCE_MAX_RUNS,
    REFERENCE_PRECISION_PP,
    SIMULATE_MAX_RUNS,
    SIMULATE_PRECISION_PP,
    check_precision,
    simulate_precisely,
)

TRACKS = 30  # granule paths kept for the plan view, as `simulate --plot`
RAYS = 80  # departure rays drawn
LANDINGS = 1500  # landing points sent for the scatter
PRECISE = {"precision": REFERENCE_PRECISION_PP, "max_runs": REFERENCE_MAX_RUNS}  # the page's "precise" button


class SimulateRequest(BaseModel):
    """`POST /api/simulate` and `/api/pattern`: the flags of `spreadgym simulate`."""

    model_config = ConfigDict(extra="forbid")
    scene: str = Field(default="paper", max_length=200, description="shipped scene name")
    yaml: Optional[str] = Field(default=None, description="an uploaded scene's YAML text (instead of a name)")
    set: dict[str, Any] = Field(default_factory=dict, description="--set KEY=VALUE; a string value is parsed as YAML")
    model: str = "auto"
    precision: float = SIMULATE_PRECISION_PP
    max_runs: int = SIMULATE_MAX_RUNS


def scene_from_yaml_text(text: str) -> dict:
    """An uploaded scene's mapping: YAML read as data with the loader's limits."""
    try:
        raw = parse_yaml(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or type(exc).__name__
        prefix = "YAML" if isinstance(exc, YamlLimitError) else "not valid YAML"
        raise ConfigError("uploaded scene", f"{prefix}{where}: {problem}") from None
    if not isinstance(raw, dict):
        raise ConfigError("uploaded scene", "does not hold a mapping")
    return raw


def overrides(assignments: dict[str, Any]) -> dict[str, Any]:
    """`--set` pairs: a string value parsed as YAML as on the command line, other JSON values as they are."""
    return dict(parse_assignment(f"{key}={value}") if isinstance(value, str) else (key, value)
                for key, value in assignments.items())


def scene_of(request: SimulateRequest) -> Scene:
    """The validated scene of a request: a shipped name (never a path) or uploaded YAML, overridden."""
    sets = overrides(request.set)
    if request.yaml is not None:
        scene = scene_from_dict(scene_from_yaml_text(request.yaml))
        return scene_with(scene, sets) if sets else scene
    names = available("scenes")
    if request.scene not in names:
        raise ConfigError("scenes", f"unknown name {brief(request.scene)}; available: {', '.join(names)}")
    return load_scene(request.scene, sets)


def check_flags(request: SimulateRequest) -> None:
    """--model, --precision and --max-runs as the CLI checks them."""
    from spreadgym.physics.selection import MODELS

    if request.model not in MODELS:
        raise SpreadgymError(f"model: unknown model {brief(request.model)}; allowed: {', '.join(MODELS)}")
    check_precision(request.precision, "precision")
    if not 2 <= request.max_runs <= MAX_RUNS_LIMIT:
        raise SpreadgymError(f"max_runs: {request.max_runs} is out of range; allowed [2, {MAX_RUNS_LIMIT}]")


def check_request(request: SimulateRequest) -> Scene:
    """The request's scene, every flag checked as the CLI checks it (before the work waits its turn)."""
    check_flags(request)
    return scene_of(request)


def simulate(request: SimulateRequest, tracks: int = 0, check: Optional[Callable[[], None]] = None):
    """(scene, PreciseEstimate) of a request, as `spreadgym simulate` computes it; `check()`
    is called after every run (it raises to stop the work)."""
    scene = check_request(request)
    return scene, simulate_precisely(scene, request.precision, request.max_runs, model=request.model, tracks=tracks,
                                     progress=None if check is None else lambda _done, _cap: check())


def simulate_task(args: dict, check: Callable[[], None]) -> str:
    """The worker's `POST /api/simulate`: `spreadgym simulate --json`'s text."""
    _scene, precise = simulate(SimulateRequest(**args), check=check)
    return json_text(precise.to_json())


def pattern_task(args: dict, check: Callable[[], None]) -> str:
    """The worker's `POST /api/pattern`."""
    return pattern_payload(SimulateRequest(**args), check)


def json_text(payload: dict) -> str:
    """`payload` as `spreadgym simulate --json` prints it."""
    out = io.StringIO()
    print_json(payload, out)
    return out.getvalue()


def controls(scene: Scene) -> list[dict]:
    """Sliders of the scene's adjustable settings (the settings box the envs and charts use,
    the drop point always) and of the working width."""
    radius = scene.spinner.radius_m
    feed = scene.feed
    space = SettingsSpace(scene, deflectors=False, feed_radius_m=feed.radius_range_m or (0.0, round(0.9 * radius, 3)),
                          feed_angle_deg=feed.angle_range_deg or (-180.0, 180.0))
    labels = {"spinner.rpm": ("disc speed", "rpm", 10.0), "vanes.pitch_deg": ("vane pitch", "deg", 0.5),
              "feed.radius_m": ("drop point radius", "m", 0.001), "feed.angle_deg": ("drop point angle", "deg", 1.0)}
    pitches = scene.vanes.per_vane("pitch_deg")
    out = []
    for axis in space.axes:
        label, unit, step = labels[axis.key]
        value = _current(scene, axis.key) if axis.index is None else pitches[axis.index]
        if axis.index is not None:
            label = f"vane {axis.index + 1} pitch"
        out.append({"key": axis.key, "index": axis.index, "label": label, "unit": unit, "step": step,
                    "min": min(axis.named_low, value), "max": max(axis.named_high, value), "value": value})
    for i, plate in enumerate(scene.deflectors):  # the plate's own range, else 45 deg either way
        low, high = plate.angle_range_deg or (plate.angle_deg - 45.0, plate.angle_deg + 45.0)
        out.append({"key": f"deflectors.{i}.angle_deg", "index": None, "label": f"plate {i + 1} angle", "unit": "deg",
                    "step": 1.0, "min": min(low, plate.angle_deg), "max": max(high, plate.angle_deg),
                    "value": plate.angle_deg})
    p = scene.pattern
    top = min(100.0, max(24.0, 3.0 * p.target_swath_m))
    out.append({"key": "pattern.target_swath_m", "index": None, "label": "working width", "unit": "m",
                "step": p.tray_width_m, "min": 2 * p.tray_width_m, "max": math.floor(top / p.tray_width_m)
                * p.tray_width_m, "value": p.target_swath_m})
    return out


def _current(scene: Scene, key: str) -> float:
    node: Any = scene
    for part in key.split("."):
        node = node[int(part)] if part.isdigit() else getattr(node, part)
    return float(node)


def scene_info(scene: Scene) -> dict:
    """What the page needs to lay out a scene's controls: the fertilizers offered are those that can run on it
    (their surface pairs measured or set by the scene: what `spreadgym chart --fertilizers all` takes)."""
    from spreadgym.agents.chart.spec import resolve_fertilizers
    from spreadgym.config.materials import load_library

    runnable, _left_out = resolve_fertilizers("all", scene, load_library())
    return {"name": scene.name, "description": scene.description, "fertilizer": scene.fertilizer_name,
            "fertilizers": sorted(set(runnable) | {scene.fertilizer_name}), "controls": controls(scene),
            "tray_width_m": scene.pattern.tray_width_m}


def _xy(points) -> list:
    return np.round(np.asarray(points, dtype=float), 4).T.tolist()


def plot_data(scene: Scene, precise) -> dict:
    """The pictures' data: plan view (disc, vanes, plates, feed, paths, rays; the first disc's
    frame, as `simulate --plot` draws it), landings,
    single-pass and overlapped tray pattern, CV against width."""
    from spreadgym.physics.geometry import vane_segments
    from spreadgym.spread import pattern
    from spreadgym.viz.plots import RAY_BEYOND_DISC_M, departure_rays, first_disc, overlapped_field

    result = precise.as_result()
    dep = result.departure
    centre, own, own_tracks = first_disc(result)  # a twin machine: its first disc, in that disc's frame
    plates = [np.asarray(plate.endpoints()) - centre for plate in scene.deflectors]
    reach = scene.spinner.radius_m + RAY_BEYOND_DISC_M
    if plates:
        reach = max(reach, max(max(math.hypot(*end) for end in plate) for plate in plates) + 0.15)
    departed = np.flatnonzero(result.launch.departed[:own])
    shown = departed[np.unique(np.linspace(0, departed.size - 1, min(RAYS, departed.size)).round().astype(int))] \
        if departed.size else departed
    inner, outer = vane_segments(scene)
    feed = scene.feed
    plan = {
        "disc_radius_m": scene.spinner.radius_m, "twin": scene.twin is not None,  # the first disc, as simulate --plot
        "vanes": [_xy([a, b]) for a, b in zip(inner, outer)],
        "feed_m": [feed.radius_m * math.cos(feed.angle_rad), feed.radius_m * math.sin(feed.angle_rad)],
        "tracks": [_xy(np.asarray(path) - centre) for path in dep.tracks[:min(TRACKS, own_tracks)]],
        "rays": [_xy(path) for path in departure_rays(result, shown, reach, centre)],
        "plates": [_xy(plate) for plate in plates],
        "reach_m": reach,
    }
    landing = result.landing.position_m
    keep = np.unique(np.linspace(0, len(landing) - 1, min(LANDINGS, len(landing))).round().astype(int)) \
        if len(landing) else np.zeros(0, dtype=int)
    trays, p = result.trays, scene.pattern
    tray_data: dict = {"center_m": trays.center_m.tolist(), "width_m": trays.width_m}
    if trays.total_kg > 0:
        mean = float(np.mean(pattern.bout_pattern(trays, p.target_swath_m, p.driving)))
        n = pattern.bout_tray_count(p.target_swath_m, trays.width_m)
        half = max(trays.count // 2, math.ceil(1.5 * n))
        k = np.arange(-half, half + 1)
        field = overlapped_field(trays, p.target_swath_m, p.driving, k)
        tray_data.update({"single_percent": np.round(100 * trays.mass_kg / mean, 3).tolist(),
                          "overlap_x_m": (k * trays.width_m).tolist(),
                          "overlap_percent": np.round(100 * field / mean, 3).tolist()})
    return {"plan": plan, "landing": _xy(landing[keep]) if len(keep) else [[], []], "trays": tray_data}


def warm_up(_args: dict, check: Callable[[], None]) -> None:
    """One small run of the default scene, so the compiled model is loaded before the first page."""
    simulate(SimulateRequest(set={"sim.granules": 256}, max_runs=2), tracks=TRACKS, check=check)


def pattern_payload(request: SimulateRequest, check: Optional[Callable[[], None]] = None) -> str:
    """`POST /api/pattern`: the simulate JSON ("metrics"), the CV as the CLI prints it and the pictures' data."""
    scene, precise = simulate(request, tracks=TRACKS, check=check)
    metrics = json.loads(json_text(precise.to_json()))
    cv, se = metrics["cv_percent_at_target"], metrics["cv_standard_error_percent"]
    cv_text = "nothing landed" if cv is None else with_error(cv, se, "%")
    return json.dumps({"metrics": metrics, "cv_text": cv_text, "swath_text": swath_text(metrics),
                       "plot": plot_data(scene, precise)})
