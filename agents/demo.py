"""The main job (`spreadgym demo`): better spinner settings for a wider swath.

1. Simulate the paper's spinner at its published settings (500 rpm, four radial
   vanes, compound 10-16-10) with the full contact model (pymunk), scored at the
   demo's target swath.
2. Search rpm and vane pitch with CMA-ES on the fast compiled model (SEARCH_MODEL),
   through the SpinnerDesign env (its reward at the target swath), starting from the
   published settings. The search needs hundreds of runs: the cheap model is used
   there, and only there ("model no more than needed").
3. Re-simulate the best settings with the full model, on the same granule sample as
   step 1, and show before/after: table (stdout, CSV, Markdown, JSON) and pictures
   (pattern and CV against bout width, before and after side by side).
4. If a trained policy exists (`runs/policy/model.zip`, or --policy), its settings
   for the same job (one forward pass, no search) are simulated with the full model
   too and shown as a third column. The demo does not need one.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np
from tqdm import tqdm

from spreadgym.agents.baselines import cmaes_search
from spreadgym.agents.evaluation import DESIGN_ENV, EvalContext, make_env, published_action, write_csv
from spreadgym.agents.training import load_policy
from spreadgym.config.scene import load_scene, scene_with
from spreadgym.errors import SpreadgymError
from spreadgym.report import format_table, print_json
from spreadgym.spread.metrics import RunMetrics
from spreadgym.spread.pipeline import run_scene

FULL_MODEL = "pymunk"
SEARCH_MODEL = "compiled"  # the full contact laws per granule; matches pymunk within 0.5 pp (docs/fidelity.md)
FERTILIZER = "compound-10-16-10"
DEFAULT_TARGET_M = 4.5  # the published settings reach 3.5 m (full model); see docs/agents.md
DEFAULT_BUDGET = 200
DEFAULT_GRANULES = 2000
POLICY_PATH = Path("runs/policy/model.zip")
MIN_GRANULES = 10  # fewer land too few granules on the trays for a CV


@dataclass
class Column:
    """One setting of the spinner and what the models say about it."""

    key: str
    title: str
    rpm: float
    pitch_deg: float
    how: str  # how the settings were found
    search_simulations: int = 0
    fast: dict = field(default_factory=dict)  # info["metrics"] of SEARCH_MODEL (search sample)
    full_wall_s: float = 0.0
    result: Any = None  # SimulationResult of the full model (for pictures)

    @property
    def full(self) -> RunMetrics:
        """Metrics of the full model."""
        return self.result.metrics

    def record(self) -> dict:
        return {
            "setting": self.title,
            "how": self.how,
            "rpm": self.rpm,
            "pitch_deg": self.pitch_deg,
            "cv_percent_at_target": self.full.cv_percent_at_target,
            "effective_swath_m": self.full.effective_swath_m,
            "landed_percent": _landed_percent(self.full),
            "model": self.full.model,
            "granules": self.full.granules,
            "full_model_wall_s": self.full_wall_s,
            # the search model's figures (SEARCH_MODEL); the keys keep the name they had when
            # the search ran on the analytic model, for those who read this JSON
            "analytic_cv_percent_at_target": self.fast.get("cv_percent_at_target"),
            "analytic_effective_swath_m": self.fast.get("effective_swath_m"),
            "search_simulations": self.search_simulations,
        }


def _landed_percent(metrics: RunMetrics) -> Optional[float]:
    fraction = metrics.landed_fraction
    return None if fraction is None else 100.0 * fraction


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _full_run(scene, label: str):
    """One run of the full model with a progress bar of the simulated spinner time."""
    started = time.perf_counter()
    with tqdm(desc=label, unit="ms", file=sys.stderr, disable=None, leave=False,
              bar_format="{desc}: {n:.0f} ms of spinner time simulated [{elapsed}]") as bar:
        def progress(t_s: float) -> None:
            bar.n = 1e3 * t_s
            if int(bar.n) % 10 == 0:
                bar.refresh()

        result = run_scene(scene, model=FULL_MODEL, progress=progress, ci=False, tracks=30)
    return result, time.perf_counter() - started


def run_demo(out: Path, target_m: float = DEFAULT_TARGET_M, budget: int = DEFAULT_BUDGET,
             granules: int = DEFAULT_GRANULES, seed: int = 0, policy_path: Optional[Path] = POLICY_PATH,
             policy_required: bool = False) -> dict:
    started = time.perf_counter()
    if budget < 1:
        raise SpreadgymError(f"--budget must be at least 1 simulation, got {budget}")
    if granules < MIN_GRANULES:
        raise SpreadgymError(f"--granules must be at least {MIN_GRANULES}, got {granules}")
    # the job, as a scene (full model) and as an env context (search model)
    base = load_scene("paper", {"pattern.target_swath_m": float(target_m), "sim.granules": int(granules)})
    env = make_env(DESIGN_ENV, {"granules": int(granules), "model": SEARCH_MODEL,
                                "context.target_swath_m": [min(2.0, target_m), max(6.0, target_m)]})
    ctx = EvalContext(0, FERTILIZER, float(target_m))
    smap = env.unwrapped.task.settings_map
    steps = 4 if policy_path is not None and Path(policy_path).is_file() else 3

    # 1. the published settings with the full model
    _say(f"[1/{steps}] the paper's spinner at its published settings ({base.spinner.rpm:g} rpm, "
         f"{base.vanes.count} radial vanes, {FERTILIZER}), full model ({FULL_MODEL}), target swath {target_m:g} m")
    published = Column("published", "published (paper)", float(base.spinner.rpm), 0.0,
                       "the paper's settings")
    published.result, published.full_wall_s = _full_run(base, "full model, published")
    env.reset(seed=ctx.search_seed, options=ctx.options())
    x_pub = published_action(env)
    _, _, _, _, info = env.step(x_pub)
    published.fast = info["metrics"]
    _say(f"      CV {published.full.cv_percent_at_target:.1f} % at {target_m:g} m, "
         f"effective swath {published.full.effective_swath_m:g} m ({published.full_wall_s:.1f} s)")

    # 2. CMA-ES on SEARCH_MODEL
    _say(f"[2/{steps}] CMA-ES over rpm and vane pitch on the fast {SEARCH_MODEL} model, {budget} simulations "
         "(the search uses the cheap model; before/after use the full model)")
    env.reset(seed=ctx.search_seed, options=ctx.options())
    before = env.simulations
    bar = tqdm(total=budget, desc=f"CMA-ES ({SEARCH_MODEL})", unit="sim", file=sys.stderr, disable=None, leave=False)
    best_seen = {"reward": -math.inf, "cv": None}

    def objective(x: np.ndarray) -> float:
        _, reward, _, _, step_info = env.step(x)
        if reward > best_seen["reward"]:
            best_seen["reward"], best_seen["cv"] = reward, step_info["metrics"]["cv_percent_at_target"]
            best_seen["metrics"] = step_info["metrics"]
            bar.set_postfix(best_cv=f"{best_seen['cv']:.1f}%" if best_seen["cv"] is not None else "-", refresh=False)
        bar.update()
        return float(reward)

    t0 = time.perf_counter()
    found = cmaes_search(objective, smap.size, budget, seed=seed, x0=x_pub)
    bar.close()
    search_s = time.perf_counter() - t0
    used = env.simulations - before
    best = smap.to_settings(found.best_x)
    after = Column("cmaes", "CMA-ES best", float(best.rpm), float(best.pitch_deg[0]),
                   f"CMA-ES on the {SEARCH_MODEL} model, {used} simulations", search_simulations=used)
    after.fast = best_seen.get("metrics", {})
    _say(f"      best: {best.rpm:.0f} rpm, pitch {best.pitch_deg[0]:+.1f} deg; {SEARCH_MODEL} model: CV "
         f"{after.fast.get('cv_percent_at_target', float('nan')):.1f} %, swath {after.fast.get('effective_swath_m')} m "
         f"({used} simulations, {search_s:.1f} s)")

    # 3. the best settings with the full model
    _say(f"[3/{steps}] the best settings with the full model ({FULL_MODEL})")
    after_scene = scene_with(base, smap.scene_overrides(best))
    after.result, after.full_wall_s = _full_run(after_scene, "full model, CMA-ES best")
    _say(f"      CV {after.full.cv_percent_at_target:.1f} % at {target_m:g} m, "
         f"effective swath {after.full.effective_swath_m:g} m ({after.full_wall_s:.1f} s)")
    columns = [published, after]

    # 4. optional: a trained policy
    if policy_path is not None and Path(policy_path).is_file():
        column = _policy_column(Path(policy_path), ctx, base, granules, steps, policy_required)
        if column is not None:
            columns.append(column)
    elif policy_required:
        raise SpreadgymError(f"--policy {policy_path}: no such file")

    wall = time.perf_counter() - started
    written = write_demo(out, columns, target_m, budget, granules, wall)
    return {"target_swath_m": float(target_m), "budget": budget, "granules": granules,
            "columns": [c.record() for c in columns], "wall_s": wall, "files": [str(p) for p in written]}


def _policy_column(path: Path, ctx, base, granules: int, steps: int, required: bool) -> Optional[Column]:
    try:
        policy = load_policy(path, flag="--policy")
        kwargs = {k: v for k, v in policy.env_kwargs.items() if k != "granules"}
        env = make_env(policy.env_id, {**kwargs, "granules": int(granules)})
        if "SpinnerDesign" not in policy.env_id:
            raise SpreadgymError(f"{path}: a {policy.env_id} policy, the demo shows SpinnerDesign policies")
        lo, hi = env.unwrapped.task.cfg.context.target_swath_m
        if not lo <= ctx.target_swath_m <= hi:
            raise SpreadgymError(f"{path}: trained for target swaths {lo:g}-{hi:g} m, not {ctx.target_swath_m:g} m")
        obs, _ = env.reset(seed=ctx.search_seed, options=ctx.options())
    except SpreadgymError as exc:
        if required:
            raise
        _say(f"[4/{steps}] trained policy skipped: {exc}")
        return None
    action = policy.act(obs)
    settings = env.unwrapped.task.settings_map.to_settings(np.asarray(action, dtype=float))
    _say(f"[4/{steps}] the trained {policy.algo.upper()} policy ({path}): one forward pass gives "
         f"{settings.rpm:.0f} rpm, pitch {settings.pitch_deg[0]:+.1f} deg; full model ({FULL_MODEL})")
    column = Column("policy", f"{policy.algo.upper()} policy", float(settings.rpm), float(settings.pitch_deg[0]),
                    f"trained {policy.algo.upper()} policy, one forward pass ({path})")
    _, _, _, _, info = env.step(action)
    column.fast = info["metrics"]
    column.result, column.full_wall_s = _full_run(scene_with(base, env.unwrapped.task.settings_map.scene_overrides(
        settings)), "full model, policy")
    _say(f"      CV {column.full.cv_percent_at_target:.1f} % at {ctx.target_swath_m:g} m, "
         f"effective swath {column.full.effective_swath_m:g} m ({column.full_wall_s:.1f} s)")
    return column


# -- output -------------------------------------------------------------------------------

def _fmt(value, fmt: str, none: str = "-") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return none
    return format(value, fmt)


def table_rows(columns: list[Column], target_m: float) -> list[tuple]:
    rows = [
        ("rpm", *[_fmt(c.rpm, ".0f") for c in columns]),
        ("vane pitch (deg, + = tip forward)", *[_fmt(c.pitch_deg, "+.1f") for c in columns]),
        (f"CV at target {target_m:g} m (%)", *[_fmt(c.full.cv_percent_at_target, ".1f") for c in columns]),
        ("effective swath, CV <= 15 % (m)", *[_fmt(c.full.effective_swath_m, "g") for c in columns]),
        ("landed (%)", *[_fmt(_landed_percent(c.full), ".1f") for c in columns]),
        ("model", *[f"{c.full.model} (full)" for c in columns]),
        (f"CV at target, {SEARCH_MODEL} model (%)",
         *[_fmt(c.fast.get("cv_percent_at_target"), ".1f") for c in columns]),
        (f"effective swath, {SEARCH_MODEL} model (m)", *[_fmt(c.fast.get("effective_swath_m"), "g") for c in columns]),
        ("simulations to find the settings", *[str(c.search_simulations) for c in columns]),
        ("found by", *[c.how for c in columns]),
    ]
    return rows


OUTPUTS = ("before_after.csv", "before_after.md", "before_after.json", "before_after.png")


def write_demo(out: Path, columns: list[Column], target_m: float, budget: int, granules: int, wall: float) -> list:
    from spreadgym.viz.plots import write_simulation_plots  # matplotlib: only when writing pictures

    out.mkdir(parents=True, exist_ok=True)
    header = ("quantity", *[c.title for c in columns])
    rows = table_rows(columns, target_m)
    text = format_table(rows, header)
    records = [c.record() for c in columns]
    keys = list(records[0])
    written = [write_csv(out / "before_after.csv", records, [(k, k) for k in keys])]
    md = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    md += ["| " + " | ".join(str(v) for v in row) + " |" for row in rows]
    intro = (f"Paper spinner ({FERTILIZER}), target swath {target_m:g} m, {granules} granules per run; "
             f"search: CMA-ES on the {SEARCH_MODEL} model, budget {budget}; before/after: {FULL_MODEL} model; "
             f"simulations and search took {wall:.0f} s.\n\n")
    (out / "before_after.md").write_text(intro + "\n".join(md) + "\n", encoding="utf-8")
    written.append(out / "before_after.md")
    with open(out / "before_after.json", "w", encoding="utf-8") as handle:
        print_json({"target_swath_m": target_m, "budget": budget, "granules": granules, "wall_s": wall,
                    "columns": records}, handle)
    written.append(out / "before_after.json")
    written.append(side_by_side(out / "before_after.png", columns, target_m))
    for c in columns:
        written.extend(write_simulation_plots(c.result, out / c.key))
    print(f"Paper spinner, {FERTILIZER}, target swath {target_m:g} m ({granules} granules per run)")
    print(text)
    return written


def side_by_side(path: Path, columns: list[Column], target_m: float) -> Path:
    """Pattern (top) and CV against bout width (bottom), one column per setting."""
    # matplotlib (and viz.plots, which imports it) only when a picture is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from spreadgym.viz.plots import cv_vs_bout_width, transverse_pattern

    n = len(columns)
    fig = Figure(figsize=(5.6 * n, 8.4), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, n, squeeze=False)
    for j, c in enumerate(columns):
        transverse_pattern(axes[0, j], c.result)
        cv_vs_bout_width(axes[1, j], c.result)
        cv = c.full.cv_percent_at_target
        axes[0, j].set_title(f"{c.title}: {c.rpm:.0f} rpm, pitch {c.pitch_deg:+.1f} deg\n"
                             f"CV {_fmt(cv, '.1f')} % at {target_m:g} m, effective swath "
                             f"{c.full.effective_swath_m:g} m ({c.full.model})", fontsize=10)
        for ax in axes[:, j]:
            ax.title.set_fontsize(10)
    top = max(ax.get_ylim()[1] for ax in axes[0])
    left = min(ax.get_xlim()[0] for ax in axes[0])
    right = max(ax.get_xlim()[1] for ax in axes[0])
    for ax in axes[0]:
        ax.set_ylim(0, top)
        ax.set_xlim(left, right)
    top = max(ax.get_ylim()[1] for ax in axes[1])
    right = max(ax.get_xlim()[1] for ax in axes[1])
    for ax in axes[1]:
        ax.set_ylim(0, top)
        ax.set_xlim(0, right)
    fig.suptitle(f"Before and after: paper spinner, {FERTILIZER}, target swath {target_m:g} m", fontsize=12)
    fig.savefig(path)
    return path
