"""One fit, end to end: estimate, intervals, identifiability, the fitted scene."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Optional, Union

import numpy as np

from spreadgym.config.scene import MAX_GRANULE_COPIES, Scene, granule_copies, scene_with
from spreadgym.errors import SpreadgymError
from spreadgym.fit import optimise, uncertainty
from spreadgym.fit.discrepancy import Discrepancy, stored_discrepancy
from spreadgym.fit.likelihood import PatternModel, check_covered, residuals
from spreadgym.fit.regime import REGIME_KEYS
from spreadgym.fit.space import FitSpace
from spreadgym.fit.trays import TrayTest
from spreadgym.physics.selection import choose_model

FIT_GRANULES = 4096  # granules per evaluation (x sim.angle_copies landing samples)
FIT_REPLICATES = 16  # independent replicates per evaluation: the jackknife of the simulation's error (15 d.o.f.)
RECENTRES = 1  # profiles redone at most once from a lower point they found
TYPICAL_EVALUATIONS = "100-250"  # per fitted key, measured on the bench's fits (178-463 for two keys)
AT_BOUND = 1e-3  # unit cube: an estimate this close to a search bound is on it
RECENTRE_RISE = 0.1  # cost units: a lower point by less is the objective's granular jitter


@dataclass
class FitResult:
    """A fitted tray test; values in each key's own unit."""

    scene: Scene  # the scene as given (settings of the test)
    space: FitSpace
    model: PatternModel
    estimate: np.ndarray  # (d,)
    low: np.ndarray  # (d,) 90 % profile interval
    high: np.ndarray
    interval_points: list[np.ndarray]  # the profile ends (unit cube), 2 per key: the band's corners
    open_ends: list[tuple[bool, bool]]  # the interval reached the search bound (low, high)
    at_bound: list[bool]  # the estimate itself lies on a search bound (the optimum may lie beyond it)
    identifiable: dict[str, bool]
    correlation: np.ndarray  # (d, d)
    weakest: dict[str, float]  # unit-cube direction the test determines least
    weakest_eigenvalue: float
    catch_sd: float  # estimated catch noise (log s.d.)
    simulation_sd: np.ndarray  # (d,) the estimate's s.d. from the simulation's Monte Carlo error, key units
    model_sd: np.ndarray  # (d,) its s.d. from the fit model's discrepancy from the full model, key units
    bare_low: np.ndarray  # (d,) the 90 % interval without the model's discrepancy (to measure what it adds)
    bare_high: np.ndarray
    regime_switch: np.ndarray  # (d,) share of the granules the roll's limits turn between sliding and rolling
    # inside each interval (uncertainty.regime_switches)
    bare_regime_switch: np.ndarray  # (d,) the same inside the intervals without the model's discrepancy
    discrepancy_points: int  # calibration points behind model_sd (0: none carried)
    log_scale: float  # a: fitted mass = exp(a) x simulated mass
    cost: float  # sum of squared standardised residuals at the estimate
    threshold: float  # its rise bounding the 90 % intervals
    wall_s: float

    @property
    def fitted_scene(self) -> Scene:
        """The scene as given with the estimates set (its own sim keys)."""
        return scene_with(self.scene, dict(zip(self.space.keys, map(float, self.estimate))))

    @property
    def evaluation_scene(self) -> Scene:
        """The fitted scene as the fit simulated it (its granules and seed)."""
        return self.model.scene_at(self.space.unit(self.estimate))


def work_text(scene: Scene, granules: Optional[int] = FIT_GRANULES) -> str:
    """The work of a fit, said before it starts: landing points per evaluation, the
    evaluations a fit takes, and the batch that bounds its memory."""
    evaluation = scene_with(scene, {} if granules is None else {"sim.granules": granules})
    points = granule_copies(evaluation)
    batch = max(1, MAX_GRANULE_COPIES // points)
    return (f"{evaluation.sim.granules} granules x {points // evaluation.sim.granules} landing points each per "
            f"evaluation, about {TYPICAL_EVALUATIONS} evaluations per key, at most {batch} evaluation(s) "
            f"({batch * points} landing points) at a time")


def fit_tray_test(scene: Scene, space: FitSpace, test: TrayTest, model: str = "auto",
                  granules: Optional[int] = FIT_GRANULES, seed: int = 0,
                  discrepancy: Union[Discrepancy, None, str] = "stored") -> FitResult:
    """Fit the keys of `space` to `test`; the evaluations use `granules` granules (None: the
    scene's) and the scene's sim.seed for every point (common random numbers); `seed` draws
    the Sobol start design. `discrepancy`: the fit model's measured difference from the full
    model carried into the intervals; "stored": the one stored for the scene when the fit
    runs the compiled model (none for the full model or an uncalibrated scene); None: none."""
    started = time.perf_counter()
    if isinstance(discrepancy, str):
        if discrepancy != "stored":
            raise SpreadgymError(f"discrepancy: {discrepancy!r} is not a Discrepancy, None or 'stored'")
        discrepancy = stored_discrepancy(scene) if choose_model(scene, model)[0] == "compiled" else None
    evaluation = scene_with(scene, {"sim.replicates": FIT_REPLICATES, **({} if granules is None else
                                                                         {"sim.granules": granules})})
    pattern_model = PatternModel(evaluation, space, test, model)
    if pattern_model.trays < space.dims + 3:
        raise SpreadgymError(f"--trays: {pattern_model.trays} trays caught anything; fitting {space.dims} key(s) "
                             f"needs at least {space.dims + 3}")
    objective, best = optimise.fit(pattern_model, seed)
    level = uncertainty.threshold(pattern_model.trays, space.dims)
    for attempt in range(RECENTRES + 1):
        jac = uncertainty.jacobian(objective, best)
        info = jac.T @ jac
        intervals = [uncertainty.profile_interval(objective, best, j, level, info) for j in range(space.dims)]
        lowest = min((i.lowest for i in intervals), key=lambda m: m.cost)
        if lowest.cost >= best.cost - RECENTRE_RISE or attempt == RECENTRES:
            break  # the last pass keeps its centre: the estimate and its intervals stay one fit
        best = optimise.minimise(objective, [lowest.unit])  # a profile found a lower point: start again there
    check_covered(pattern_model.predict([best.unit])[0], test, "at the estimate")
    sim_sd = uncertainty.simulation_sd(objective, best, jac)
    replicates = pattern_model.predict([best.unit])[0].replicate_kg.shape[0]
    model_sd, calibration_points = np.zeros(space.dims), 0
    if discrepancy is not None:
        delta, variance = discrepancy.on_trays(pattern_model.local_x_m,
                                               scene.pattern.tray_width_m)
        model_sd, calibration_points = uncertainty.model_sd(objective, best, jac, delta, variance), discrepancy.points
    low, high = zip(*(uncertainty.widened(best.unit[j], i.low, i.high,
                                          [(sim_sd[j], replicates - 1), (model_sd[j], calibration_points)])
                      for j, i in enumerate(intervals)))
    bare_low, bare_high = zip(*(uncertainty.widened(best.unit[j], i.low, i.high, [(sim_sd[j], replicates - 1)])
                                for j, i in enumerate(intervals)))
    regime = [space.keys.index(key) for key in REGIME_KEYS if key in space.keys]
    switch = uncertainty.regime_switches(objective, intervals, low, high, regime)
    bare_switch = uncertainty.regime_switches(objective, intervals, bare_low, bare_high, regime)
    points = [p for i in intervals for p in (i.low_point, i.high_point)]
    open_ends = [(bool(i.low_open or lo == 0.0), bool(i.high_open or hi == 1.0))
                 for i, lo, hi in zip(intervals, low, high)]
    at_bound = [bool(u <= AT_BOUND or u >= 1.0 - AT_BOUND) for u in best.unit]
    identifiable = {key: uncertainty.determined(lo, hi, s) and not edge
                    for key, lo, hi, s, edge in zip(space.keys, low, high, switch, at_bound)}
    direction, eigenvalue = uncertainty.weakest_direction(info)
    _, log_scale = residuals(pattern_model.log_mass, pattern_model.predict([best.unit])[0], objective.sigma)
    return FitResult(
        scene=scene, space=space, model=pattern_model, estimate=space.values(best.unit),
        low=space.values(np.array(low)), high=space.values(np.array(high)), interval_points=points,
        open_ends=open_ends, at_bound=at_bound, identifiable=identifiable, correlation=uncertainty.correlations(info),
        weakest={k: float(v) for k, v in zip(space.keys, direction)}, weakest_eigenvalue=float(eigenvalue),
        catch_sd=objective.sigma, simulation_sd=sim_sd * (space.high - space.low),
        model_sd=model_sd * (space.high - space.low), bare_low=space.values(np.array(bare_low)),
        bare_high=space.values(np.array(bare_high)), regime_switch=switch, bare_regime_switch=bare_switch,
        discrepancy_points=calibration_points, log_scale=log_scale, cost=best.cost, threshold=level,
        wall_s=time.perf_counter() - started)
