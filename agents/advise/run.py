"""From a tray test to what to change on the machine (`spreadgym advise`).

1. **Fit** the scene's material keys to the tray test (`spreadgym.fit.run.fit_tray_test`,
   the keys of `--fit`, by default vane friction, vane restitution and drag): the test's
   scene and settings as given.
2. **Search** the settings on the fitted scene at the working width wanted, with the
   robust objective of the spreading chart (`agents.chart.search`: the same `Scorer`, the
   same CMA-ES and re-score rounds, the p90 CV over the variability model's batches). The
   search starts at the best of a screen of the settings box (`SCREEN_POINTS` scrambled
   Sobol points and the tested settings, on the search's batches: the optimum of a cell
   moves between regimes of the settings, fast disc and little pitch or slower disc and
   more, and a search started in the wrong one stays there), and the tested settings are
   re-scored beside the search's leaders in every round (they are the cell's
   "neighbour"); the advice is the
   point nearest the tested settings among those within two standard errors of the best
   (the chart's tie rule, no steady tolerance, the "nearest" preference): settings that
   are not measurably better leave the machine as it was.
3. **Expected CV before and after**: the fitted model at the estimate and at both ends of
   every key's 90 % profile interval (the fit's band, `spreadgym.fit.outputs`), at the
   tested and at the advised settings, all in one batch: the value at the estimate and
   the lowest and highest over the band.
4. **Never worse**: advised settings whose CV at the estimate is not below the tested
   settings' are not advised (the advice is then to keep the settings).

The advised values are rounded as an operator dials them (`config.settings.dialled`) and
evaluated as rounded.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable, Optional, Sequence

import numpy as np
from scipy.stats import qmc

from spreadgym.agents.chart.search import CMA_SEED_RANGE, WARM_SIGMA, Scorer, search
from spreadgym.agents.chart.spec import MAX_WIDTH_M, Cell, ChartSpec, cell_seed
from spreadgym.agents.chart.variability import check_variability
from spreadgym.config.scene import Scene, bout_trays, scene_with
from spreadgym.config.settings import dialled
from spreadgym.errors import SpreadgymError
from spreadgym.fit.run import FIT_GRANULES, FitResult, fit_tray_test
from spreadgym.fit.space import parse_fit_specs
from spreadgym.fit.trays import TrayTest
from spreadgym.report import setting_label, setting_text
from spreadgym.spread.batch import run_batch

DEFAULT_FIT = ("contact.vane_friction=0.2:0.8", "contact.vane_restitution=0.2:0.7",
               "flight.drag_coefficient=0.2:0.9")
"""What a tray test tells about the material: the vane contact and the flight (docs/advise.md)."""
ADVICE_BUDGET = 200  # candidates of the settings search, the chart's default
ADVICE_GRANULES = 2048  # granules per candidate run, the chart's default (the shipped scenes' own)
SCREEN_POINTS = 32  # a scrambled Sobol screen of the settings box before the search, so it starts in the best basin


@dataclass
class Advice:
    """What `advise` found: the fit, the tested and advised settings (scene key -> value, in the key's unit),
    the expected CV at the working width before and after (at the fit's estimate, and its band)."""

    fit: FitResult
    width_m: float
    tested: dict
    advised: dict
    cv_before: tuple[Optional[float], Optional[float], Optional[float]]  # (estimate, low, high), %
    cv_after: tuple[Optional[float], Optional[float], Optional[float]]
    cv_before_se: Optional[float]  # the estimate's standard error (the fitted model's own sampling), pp
    cv_after_se: Optional[float]
    p90_before: Optional[float]  # the robust objective's CV (p90 over the variability model), %
    p90_after: Optional[float]
    search: dict = field(default_factory=dict)
    wall_s: float = 0.0

    @property
    def changes(self) -> dict:
        """{key: {"from": tested, "to": advised}} for every setting the advice changes."""
        return {k: {"from": self.tested[k], "to": v} for k, v in self.advised.items() if v != self.tested[k]}

    @property
    def instruction(self) -> str:
        """One line a driver can follow."""
        return instruction(self.changes, self.width_m, self.cv_before, self.cv_after)


def check_width(width_m: float, scene: Scene) -> float:
    """`--width`: a working width on the scene's tray grid, at least two trays, at most the chart's MAX_WIDTH_M."""
    if not (math.isfinite(width_m) and 0.0 < width_m <= MAX_WIDTH_M):
        raise SpreadgymError(f"--width: {width_m:g} m is out of range; allowed (0, {MAX_WIDTH_M:g}] m")
    try:
        bout_trays(width_m, scene.pattern.tray_width_m)
    except ValueError as exc:
        raise SpreadgymError(f"--width: {exc}") from None
    return float(width_m)


def settings_of(space, units) -> dict:
    """Scene key -> dialled value of unit settings `units` (per-vane pitches as one list under their key)."""
    out: dict = {}
    for axis, value in zip(space.axes, space.values(units).values()):
        value = dialled(axis.name, value)
        if axis.index is None:
            out[axis.key] = value
        else:
            out.setdefault(axis.key, [0.0] * space.vane_count)[axis.index] = value
    return out


def tested_settings(space, scene: Scene) -> dict:
    """Scene key -> the scene's own value of every setting the advice may change (as the scene has it)."""
    out: dict = {}
    for axis, value in zip(space.axes, space.scene_values(scene)):
        if axis.index is None:
            out[axis.key] = float(value)
        else:
            out.setdefault(axis.key, [0.0] * space.vane_count)[axis.index] = float(value)
    return out


def advise(scene: Scene, test: TrayTest, width_m: float, fit: Sequence[str] = DEFAULT_FIT,
           budget: int = ADVICE_BUDGET, granules: int = ADVICE_GRANULES, fit_granules: int = FIT_GRANULES,
           seed: Optional[int] = None, model: str = "auto", fixed: Iterable[str] = (),
           progress: Optional[Callable[[str], None]] = None) -> Advice:
    """The advice for `scene` (the machine and the settings of `test`) at working width `width_m`: fit the keys
    of `fit` (KEY=LO:HI texts), search the settings on the fitted scene (`budget` candidates of `granules`
    granules, the robust objective), and compare. `seed` (default the scene's sim.seed) seeds the fit and the
    search; the same inputs give the same advice bit for bit."""
    started = time.perf_counter()
    say = progress or (lambda text: None)
    width_m = check_width(width_m, scene)
    seed = scene.sim.seed if seed is None else int(seed)
    scene = scene_with(scene, {"sim.seed": seed})
    space = parse_fit_specs(fit, scene, fixed=fixed)
    say(f"fitting {', '.join(space.keys)} to {test.count} trays")
    fitted = fit_tray_test(scene, space, test, model=model, granules=fit_granules, seed=seed)
    at_width = scene_with(fitted.fitted_scene, {"pattern.target_swath_m": width_m})
    spec = ChartSpec(at_width.model_dump(mode="json"), (at_width.fertilizer_name,), (width_m,),
                     at_width.pattern.driving, int(budget), int(granules), seed, verify_model="compiled",
                     variability=check_variability(None), steady_tolerance_pp=0.0, tie_preference="nearest")
    cell = Cell(at_width.fertilizer_name, width_m)  # an inline fertilizer by its name: spec.library() holds it
    scorer_seq, cma_seq, *_ = cell_seed(seed, cell).spawn(5)
    scorer = Scorer(spec, cell, scorer_seq)
    tested_unit = scorer.space.scene_unit(scorer.scene)
    say(f"searching the settings at {width_m:g} m ({SCREEN_POINTS} screened, {budget} candidates)")
    screen = [tested_unit, *(2.0 * qmc.Sobol(scorer.space.size, scramble=True, seed=seed).random(SCREEN_POINTS) - 1.0)]
    costs = [cost for cost, _ in scorer.score_many(screen, scorer.search_draws)]
    start = screen[int(np.argmin(costs))]
    found = search(scorer, start, WARM_SIGMA, tested_unit, int(cma_seq.generate_state(1)[0]) % CMA_SEED_RANGE)
    tested = tested_settings(scorer.space, scene)
    advised = settings_of(scorer.space, found["x"])
    if np.array_equal(found["x"], tested_unit):
        advised = dict(tested)  # the test's own settings tie with the best: nothing to change
    before, after, before_se, after_se = expected_cv(fitted, width_m, [tested, advised])
    if after[0] is None or (before[0] is not None and after[0] >= before[0]):
        advised, after, after_se = dict(tested), before, before_se  # never worse than the test, on the fit
    p90 = scorer.score_many([scorer.space.named_unit(values_of(scorer.space, s)) for s in (tested, advised)],
                            scorer.round_draws(max(found["rounds"], 1)))
    inside = scored_as_tested(scorer.space, scorer.scene, tested)
    return Advice(fitted, width_m, tested, advised, before, after, before_se, after_se,
                  p90[0][1] if inside and p90[0][0] is not None else None, p90[1][1],
                  {"budget": int(budget), "granules": int(granules), "evaluations": found["evaluations"],
                   "rescore_rounds": found["rounds"], "ties": found["ties"], "simulations": scorer.simulations,
                   "model": scorer.model(scorer.space.overrides(found["x"]))},
                  time.perf_counter() - started)


def scored_as_tested(space, scene: Scene, tested: dict) -> bool:
    """Whether the search's point for `scene` is the test itself, so that its p90 is the
    test's: every tested setting inside the box (a unit vector clips one outside onto the
    edge, and the edge was scored instead) and `scene` holding them (a fitted setting moves it)."""
    values = np.asarray(values_of(space, tested))
    return bool(np.all((values >= space.named_low) & (values <= space.named_high))
                and np.array_equal(np.asarray(space.scene_values(scene), dtype=float), values))


def values_of(space, settings: dict) -> list[float]:
    """The axis values (units of the names) of scene-key settings (`tested_settings`, `settings_of`)."""
    return [float(settings[a.key][a.index]) if a.index is not None else float(settings[a.key]) for a in space.axes]


def expected_cv(fit: FitResult, width_m: float, settings: Sequence[dict]) -> tuple:
    """The CV at `width_m` of each of `settings` on the fitted model at the estimate and at the ends of every key's
    profile interval (the fit's band; its granules and seed), in one batch: per setting ((estimate, low, high),
    the estimate's standard error)."""
    units = [fit.space.unit(fit.estimate), *fit.interval_points]
    scenes = [scene_with(fit.model.scene_at(u), {**s, "pattern.target_swath_m": width_m}) for s in settings
              for u in units]
    results = run_batch(scenes, model=fit.model.model, ci=False)
    out_bands, out_se = [], []
    for k in range(len(settings)):
        mine = [r.metrics for r in results[k * len(units):(k + 1) * len(units)]]
        known = [m.cv_percent_at_target for m in mine if m.cv_percent_at_target is not None]
        cv = mine[0].cv_percent_at_target
        out_bands.append((cv, min(known) if known else None, max(known) if known else None))
        out_se.append(mine[0].cv_standard_error_percent)
    return (*out_bands, *out_se)


def _cv_text(band) -> str:
    cv, low, high = band
    if cv is None:
        return "no CV (nothing landed)"
    return f"{cv:.1f} % ({low:.1f}-{high:.1f} %)"


def _label(key: str, index: Optional[int]) -> str:
    return setting_label(key if index is None else f"{key}.{index}")


def change_phrases(changes: dict) -> list[str]:
    """'the disc speed to 860 rpm (from 720 rpm)' for each changed setting (each changed vane of a per-vane pitch)."""
    phrases = []
    for key, change in changes.items():
        pairs = ([(None, change["from"], change["to"])] if not isinstance(change["to"], list) else
                 [(k, a, b) for k, (a, b) in enumerate(zip(change["from"], change["to"])) if a != b])
        for index, old, new in pairs:
            text_key = key if index is None else f"{key}.{index}"
            phrases.append(f"the {_label(key, index)} to {setting_text(text_key, new)} "
                           f"(from {setting_text(text_key, old)})")
    return phrases


def instruction(changes: dict, width_m: float, before, after) -> str:
    """The advice as one line a driver can follow: what to set, and the CV to expect instead of the present one."""
    if not changes:
        return (f"Keep the settings: no setting tried was measurably more even at {width_m:g} m "
                f"(expected CV {_cv_text(before)}).")
    phrases = change_phrases(changes)
    listed = phrases[0] if len(phrases) == 1 else ", ".join(phrases[:-1]) + " and " + phrases[-1]
    return (f"Set {listed}: expected CV at {width_m:g} m {_cv_text(after)} instead of "
            f"{_cv_text(before)}.")


def advice_payload(advice: Advice, fit_payload: dict) -> dict:
    """The JSON of `spreadgym advise` (the contract's keys first), with the fit's JSON under `fit`."""
    (cv_b, lo_b, hi_b), (cv_a, lo_a, hi_a) = advice.cv_before, advice.cv_after
    scene = advice.fit.scene
    return {
        "changes": advice.changes,
        "cv_before_percent": cv_b, "cv_before_percent_low": lo_b, "cv_before_percent_high": hi_b,
        "cv_after_percent": cv_a, "cv_after_percent_low": lo_a, "cv_after_percent_high": hi_a,
        "instruction": advice.instruction,
        "cv_before_standard_error_percent": advice.cv_before_se,
        "cv_after_standard_error_percent": advice.cv_after_se,
        "cv_p90_before_percent": advice.p90_before, "cv_p90_after_percent": advice.p90_after,
        "scene": scene.name, "fertilizer": scene.fertilizer_name, "width_m": advice.width_m,
        "driving": scene.pattern.driving, "tested": advice.tested, "advised": advice.advised,
        "band": "the fitted model at the estimate and at both ends of every fitted key's 90 % profile interval",
        "search": advice.search, "fit": fit_payload, "wall_s": advice.wall_s,
    }
