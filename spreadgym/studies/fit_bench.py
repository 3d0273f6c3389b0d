"""How honest is `spreadgym fit`? Synthetic tray tests at known parameters (`make bench`, section fit).

Each test: a scene (paper or field), a fertilizer (compound-10-16-10 or pellet), the
granules sliding (rotation locked) or free to roll, and true vane friction, vane
restitution and (free granules) vane rolling resistance drawn from a scrambled Sobol
sequence; the free granules' fit searches the rolling resistance too (in [0, 0.6]). The truth is simulated with
`truth_model` (the full model, pymunk, by default) at `truth_granules` granules and a
seed no fit uses, caught by 0.5 m trays in one pass with 5 % log-normal catch noise;
the fit (compiled model, its granules drawn with sim.seed = the test's index, so every
test is its own draw of the simulation's error) searches vane friction in [0.2, 0.8]
and vane restitution in [0.2, 0.7]. Scored: whether each 90 % interval holds the truth (coverage, split by
whether the fit called the key identifiable), the vane friction's error, the fit's
wall time.
"""

from __future__ import annotations

import os
import statistics
from concurrent.futures import ProcessPoolExecutor
from itertools import product
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from scipy.stats import beta

from spreadgym.fit.synthetic import CATCH_SD
from spreadgym.physics.analytic.outlet import equivalent_friction

SCENES = ("paper", "field")
FERTILIZERS = ("compound-10-16-10", "pellet")
ROTATIONS = ("locked", "free")
TRUTH_RANGES = {"contact.vane_friction": (0.3, 0.6), "contact.vane_restitution": (0.35, 0.55),
                "contact.rolling_resistance": (0.0, 0.4)}
SEARCH = "contact.vane_friction=0.2:0.8,contact.vane_restitution=0.2:0.7"
ROLLING_SEARCH = "contact.rolling_resistance=0:0.6"  # free granules only: locked ones do not turn
KEYS = ("vane_friction", "vane_restitution", "rolling_resistance")


def search_for(rotation: str) -> list[str]:
    """The --fit specs of a test: vane friction and restitution, and the rolling resistance where granules turn."""
    return [SEARCH, ROLLING_SEARCH] if rotation == "free" else [SEARCH]
FRICTION_TOLERANCE = 0.05
COVERAGE_TARGET = (0.80, 0.98)
TRUTH_CACHE = Path("out/fit-truths")  # gitignored: the truths' simulated passes, keyed by scene and model


def cases(tests: int, seed: int = 0) -> list[dict]:
    """`tests` test cases cycling through scene x fertilizer x rotation, truths from a Sobol sequence."""
    from spreadgym.fit.discrepancy import sobol_points

    combos = list(product(SCENES, FERTILIZERS, ROTATIONS))
    out = []
    for i, truth in enumerate(sobol_points(TRUTH_RANGES, tests, seed)):
        scene, fertilizer, rotation = combos[i % len(combos)]
        if rotation == "locked":  # no rolling resistance without rotation: not a truth to recover
            truth = {k: v for k, v in truth.items() if k != "contact.rolling_resistance"}
        out.append({"test": i, "scene": scene, "fertilizer": fertilizer, "rotation": rotation, "truth": truth})
    return out


def run_case(case: dict, truth_model: str, truth_granules: int, fit_granules: int, threads: Optional[int],
             cache: Optional[Path] = None, catch_sd: float = CATCH_SD) -> dict:
    """One synthetic test (catch noise `catch_sd`, log s.d.), fitted; a flat row of the
    results. The truth's simulated pass is read from / kept in `cache` when given."""
    from spreadgym.config.scene import load_scene, scene_with
    from spreadgym.fit.run import fit_tray_test
    from spreadgym.fit.space import parse_fit_specs
    from spreadgym.fit.synthetic import synthetic_tray_test
    from spreadgym.fit.uncertainty import determined
    from spreadgym.threads import set_threads

    if threads is not None:
        set_threads(threads)
    scene = load_scene(case["scene"], {"fertilizer": case["fertilizer"], "granule.rotation": case["rotation"]})
    fitted = scene_with(scene, {"sim.seed": case["test"]})  # each test its own draw of the fit's granules
    test = synthetic_tray_test(scene, case["truth"], model=truth_model, granules=truth_granules,
                               noise_seed=case["test"], catch_sd=catch_sd, cache=cache)
    fit = fit_tray_test(fitted, parse_fit_specs(search_for(case["rotation"]), scene), test, granules=fit_granules,
                        seed=case["test"])
    row = {key: case[key] for key in ("test", "scene", "fertilizer", "rotation")}
    for j, key in enumerate(fit.space.keys):
        name = key.split(".")[-1]
        value = case["truth"][key]
        row.update({f"{name}_truth": value, f"{name}_estimate": float(fit.estimate[j]),
                    f"{name}_low": float(fit.low[j]), f"{name}_high": float(fit.high[j]),
                    f"{name}_covered": bool(fit.low[j] <= value <= fit.high[j]),
                    f"{name}_identifiable": fit.identifiable[key],
                    f"{name}_simulation_sd": float(fit.simulation_sd[j]), f"{name}_model_sd": float(fit.model_sd[j]),
                    f"{name}_bare_low": float(fit.bare_low[j]), f"{name}_bare_high": float(fit.bare_high[j]),
                    f"{name}_bare_covered": bool(fit.bare_low[j] <= value <= fit.bare_high[j]),
                    f"{name}_regime_switch": float(fit.regime_switch[j]),
                    f"{name}_narrow": determined(fit.space.unit(fit.low)[j], fit.space.unit(fit.high)[j], 0.0),
                    f"{name}_bare_identifiable": determined(fit.space.unit(fit.bare_low)[j],
                                                            fit.space.unit(fit.bare_high)[j],
                                                            fit.bare_regime_switch[j])})
    row.update({"truth_model": truth_model, "discrepancy_points": fit.discrepancy_points, "catch_sd": fit.catch_sd,
                "trays": fit.model.trays, "evaluations": fit.model.evaluations, "fit_wall_s": fit.wall_s})
    return row


def fit_bench_rows(out: Path, tests: int = 40, workers: int = 1, truth_model: str = "pymunk",
                   truth_granules: int = 16384, fit_granules: int = 4096,
                   progress: Optional[Callable[[str], None]] = None,
                   cache: Optional[Path] = TRUTH_CACHE, catch_sd: float = CATCH_SD) -> list[dict]:
    """Run `tests` synthetic tests (catch noise `catch_sd`, log s.d.) on `workers` processes
    (each with cores / workers threads); write `out`/fit.md (the summary against the
    targets); the rows, one per test. The truths' simulated passes are kept in `cache`
    (None: not kept), so a re-fit does not simulate them again."""
    todo = cases(tests)
    threads = max(1, len(os.sched_getaffinity(0)) // workers)
    rows = []
    if workers == 1:
        for case in todo:
            rows.append(run_case(case, truth_model, truth_granules, fit_granules, threads, cache, catch_sd))
            _say(progress, rows[-1])
    else:
        with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
            futures = [pool.submit(run_case, c, truth_model, truth_granules, fit_granules, threads, cache, catch_sd)
                       for c in todo]
            for future in futures:
                rows.append(future.result())
                _say(progress, rows[-1])
    out.mkdir(parents=True, exist_ok=True)
    (out / "fit.md").write_text(fit_markdown(rows, fit_granules, truth_granules, workers, threads, catch_sd),
                                encoding="utf-8")
    return rows


def _say(progress, row: dict) -> None:
    if progress:
        keys = ", ".join(f"{name} {row[f'{name}_truth']} -> {row[f'{name}_estimate']:.3f} "
                         f"[{row[f'{name}_low']:.3f}, {row[f'{name}_high']:.3f}]"
                         for name in KEYS if f"{name}_truth" in row)
        progress(f"fit test {row['test']}: {row['scene']} {row['fertilizer']} {row['rotation']}: {keys}, "
                 f"{row['fit_wall_s']:.0f} s")


def _share(hits: int, n: int) -> str:
    """hits / n as a percentage with its exact 95 % (Clopper-Pearson) interval."""
    if n == 0:
        return "-"
    lo = beta.ppf(0.025, hits, n - hits + 1) if hits > 0 else 0.0
    hi = beta.ppf(0.975, hits + 1, n - hits) if hits < n else 1.0
    return f"{100 * hits / n:.0f} % ({hits}/{n}; 95 % CI {100 * lo:.0f}-{100 * hi:.0f} %)"


def fit_markdown(rows: list[dict], fit_granules: int, truth_granules: int, workers: int, threads: int,
                 catch_sd: float = CATCH_SD) -> str:
    """The summary table of a fit bench against the issue's targets."""
    from spreadgym.fit.uncertainty import REGIME_SWITCH

    lines = ["# Fit bench: synthetic tray tests", "",
             f"{len(rows)} tests; truth: {rows[0]['truth_model'] if rows else '-'} model, {truth_granules} granules, "
             f"{100 * catch_sd:g} % catch noise, 0.5 m trays, one pass; fit: compiled model, {fit_granules} "
             f"granules per evaluation, search {SEARCH} (rolling granules also {ROLLING_SEARCH}); {workers} "
             f"worker(s) x {threads} thread(s).", "",
             "Intervals with the model discrepancy carried (the fit's) and without it (the profile and the "
             "simulation's error only: the fit before the discrepancy was added), on the same tests:", "",
             "| key | intervals | tests | identifiable (sliding / rolling) | 90 % coverage (identifiable) "
             "| coverage (all) |", "|---|---|---|---|---|---|"]
    for name in KEYS:
        fitted = [r for r in rows if f"{name}_truth" in r]
        for label, prefix in (("with discrepancy", name), ("without", f"{name}_bare")):
            ident = [r for r in fitted if r[f"{prefix}_identifiable"]]
            split = " / ".join(str(sum(r["rotation"] == rotation for r in ident)) for rotation in ROTATIONS)
            lines.append(f"| {name} | {label} | {len(fitted)} | {len(ident)} ({split}) | "
                         f"{_share(sum(r[f'{prefix}_covered'] for r in ident), len(ident))} | "
                         f"{_share(sum(r[f'{prefix}_covered'] for r in fitted), len(fitted))} |")
    lines += ["", f"Called not identifiable because the vane friction turns more than {100 * REGIME_SWITCH:.0f} % of "
                  "the granules between sliding and rolling inside the interval, though it covers at most half the "
                  "range (intervals with the discrepancy):", "",
              "| key | tests | covered |", "|---|---|---|"]
    for name in KEYS:
        regime = [r for r in rows if f"{name}_truth" in r and r[f"{name}_narrow"] and not r[f"{name}_identifiable"]]
        lines.append(f"| {name} | {len(regime)} | {_share(sum(r[f'{name}_covered'] for r in regime), len(regime))} |")
    lines += ["", "Median s.d. of the estimate from the model discrepancy (from the simulation's error):", "",
              "| key | sliding (locked) | rolling (free) |", "|---|---|---|"]
    for name in KEYS:
        cells = []
        for rotation in ROTATIONS:
            subset = [r for r in rows if r["rotation"] == rotation and f"{name}_truth" in r]
            cells.append(f"{statistics.median(r[f'{name}_model_sd'] for r in subset):.3f} "
                         f"({statistics.median(r[f'{name}_simulation_sd'] for r in subset):.3f})" if subset else "-")
        lines.append(f"| {name} | {' | '.join(cells)} |")
    lines += ["", "| vane friction within +-0.05 | tests | share |", "|---|---|---|"]
    for label, subset in (("granules sliding (locked)", [r for r in rows if r["rotation"] == "locked"]),
                          ("granules rolling (free)", [r for r in rows if r["rotation"] == "free"]),
                          ("reported identifiable", [r for r in rows if r["vane_friction_identifiable"]])):
        hits = sum(abs(r["vane_friction_estimate"] - r["vane_friction_truth"]) <= FRICTION_TOLERANCE for r in subset)
        lines.append(f"| {label} | {len(subset)} | {_share(hits, len(subset))} |")
    lines += ["", "What a rolling test determines: the equivalent friction min(mu_v, mu_star(mu_r)) of the estimates "
                  "against the truth's (physics/analytic/outlet.py; the outlet angle of a granule far out on a radial "
                  "vane depends on nothing else):", "", "| rolling tests | equivalent friction within +-0.05 | "
                  "median abs error | rolling resistance within +-0.05 |", "|---|---|---|---|"]
    rolling = [r for r in rows if "rolling_resistance_truth" in r]
    if rolling:
        errors = [abs(equivalent_friction(r["vane_friction_estimate"], r["rolling_resistance_estimate"])
                      - equivalent_friction(r["vane_friction_truth"], r["rolling_resistance_truth"])) for r in rolling]
        roll_hits = sum(abs(r["rolling_resistance_estimate"] - r["rolling_resistance_truth"]) <= FRICTION_TOLERANCE
                        for r in rolling)
        lines.append(f"| {len(rolling)} | {_share(sum(e <= FRICTION_TOLERANCE for e in errors), len(rolling))} | "
                     f"{statistics.median(errors):.3f} | {_share(roll_hits, len(rolling))} |")
    lines += ["", "| scene | fits | median wall (s) | max wall (s) | median evaluations |", "|---|---|---|---|---|"]
    for scene in SCENES:
        subset = [r for r in rows if r["scene"] == scene]
        if subset:
            walls = [r["fit_wall_s"] for r in subset]
            lines.append(f"| {scene} | {len(subset)} | {statistics.median(walls):.1f} | {max(walls):.1f} | "
                         f"{statistics.median(r['evaluations'] for r in subset):.0f} |")
    sds = np.array([r["catch_sd"] for r in rows])
    if sds.size:
        lines += ["", f"Estimated catch noise (log s.d.): median {np.median(sds):.3f} (true {catch_sd:g}; the "
                      "simulation's and counting variances are carried separately)."]
    return "\n".join(lines) + "\n"
