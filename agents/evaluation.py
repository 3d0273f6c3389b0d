"""The fixed evaluation set and the accounting of simulations.

Every method (a trained policy, the published settings, random search, grid search,
CMA-ES) is scored the same way on the same jobs:

* the evaluation set is the paper's three fertilizers x several target swaths
  (`EVAL_FERTILIZERS` x `EVAL_SWATHS_M`), spinner material MC, no forward speed, no
  wind (`evaluation_set`);
* one env step is one simulation, and every step is counted (`SimulationCounter`);
  a `SpreaderTuning` reset runs a tray test too, so it counts as well;
* a method first *decides* on settings for a job (a search spends simulations on it,
  a policy spends none: one forward pass), then the settings are *scored*: the job is
  reset with a fixed scoring seed per job and episode (the same granule samples for
  every method) and stepped once. Searches run on their own granule sample (the
  search seed), so a search cannot tune itself to the noise of the sample it is
  scored on.

A `Row` is one scored episode; `summarise` averages the rows of a method.
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Optional, Sequence

import gymnasium as gym
import numpy as np

from spreadgym.envs.common.actions import Settings
from spreadgym.envs.common.task import Context
from spreadgym.errors import SpreadgymError
from spreadgym.report import format_table

DESIGN_ENV = "spreadgym:SpinnerDesign-v0"
TUNING_ENV = "spreadgym:SpreaderTuning-v0"

# The paper's three fertilizers (the material library's granular products) and the swaths.
EVAL_FERTILIZERS = ("mixture-17-21-17", "compound-10-16-10", "pellet")
EVAL_SWATHS_M = (2.0, 3.0, 4.0, 5.0)
EVAL_SPINNER_MATERIAL = "mc"

# Seeds of the granule samples: job i is searched with SEARCH_SEED + i and scored, in
# episode k, with SCORE_SEED + 1000 k + i (different samples, the same for every method).
SEARCH_SEED = 10_000
SCORE_SEED = 20_000
WORST_CV_PERCENT = 100.0  # the CV a run counts as when nothing landed on the trays


def canonical_env_id(env_id: str) -> str:
    """The form of a spreadgym id that works in any process, for any accepted spelling:
    `spreadgym:spreadgym/NAME-v1` for the v1 tasks, `spreadgym:NAME-v0` for the deprecated
    v0 ones (as saved runs name them). Unknown ids are an error listing the known ones."""
    from spreadgym.envs.registration import ENVS, TASKS

    name = env_id
    for prefix in ("spreadgym:", "spreadgym/"):
        if name.startswith(prefix):
            name = name[len(prefix):]
    if name in TASKS:
        return f"spreadgym:spreadgym/{name}"
    if name in ENVS:
        return f"spreadgym:{name}"
    known = ", ".join([*(f"spreadgym/{n}" for n in TASKS), *(f"spreadgym:{n}" for n in ENVS)])
    raise SpreadgymError(f"unknown environment id {env_id!r}; known: {known}")


def is_tuning(env_id: str) -> bool:
    return "SpreaderTuning" in canonical_env_id(env_id)


@dataclass(frozen=True)
class EvalContext:
    """One job of the evaluation set."""

    index: int
    fertilizer: str
    target_swath_m: float
    spinner_material: str = EVAL_SPINNER_MATERIAL
    forward_speed_m_s: float = 0.0
    wind_m_s: tuple = (0.0, 0.0)

    @property
    def label(self) -> str:
        extra = "" if self.spinner_material == EVAL_SPINNER_MATERIAL else f" on {self.spinner_material}"
        if self.forward_speed_m_s or any(self.wind_m_s):
            extra += f", {self.forward_speed_m_s:g} m/s, wind ({self.wind_m_s[0]:g}, {self.wind_m_s[1]:g})"
        return f"{self.fertilizer} @ {self.target_swath_m:g} m{extra}"

    def as_dict(self) -> dict:
        return {"fertilizer": self.fertilizer, "target_swath_m": float(self.target_swath_m),
                "spinner_material": self.spinner_material, "forward_speed_m_s": float(self.forward_speed_m_s),
                "wind_m_s": [float(self.wind_m_s[0]), float(self.wind_m_s[1])]}

    def options(self) -> dict:
        return {"context": self.as_dict()}

    @property
    def search_seed(self) -> int:
        return SEARCH_SEED + self.index

    def score_seed(self, episode: int = 0) -> int:
        return SCORE_SEED + 1000 * episode + self.index


def evaluation_set(fertilizers: Optional[Sequence[str]] = None,
                   swaths_m: Optional[Sequence[float]] = None, env=None) -> list[EvalContext]:
    """The jobs. An env whose config has an `evaluation` section (every v1 task) gives its
    held-out jobs, restricted to `fertilizers` and `swaths_m` where given (each keeping its
    index in the whole set: its seeds, so its scores, are the same whatever else is picked); otherwise (v0)
    every fertilizer with every target swath (fertilizer-major order), by default the
    paper's three fertilizers at 2, 3, 4 and 5 m."""
    held_out = env.unwrapped.task.evaluation_jobs if env is not None else []
    if held_out:  # a job keeps its index in the whole set, so its seeds do not depend on the others picked
        picked = [(i, job) for i, job in enumerate(held_out) if (not fertilizers or job.fertilizer in fertilizers)
                  and (not swaths_m or any(abs(job.target_swath_m - float(w)) < 1e-9 for w in swaths_m))]
        if not picked:
            raise SpreadgymError("no evaluation job of the env matches --fertilizers/--swaths; its jobs: "
                                 + ", ".join(sorted({f"{j.fertilizer} @ {j.target_swath_m:g} m" for j in held_out})))
        return [EvalContext(i, j.fertilizer, j.target_swath_m, j.spinner_material, j.forward_speed_m_s,
                            tuple(j.wind_m_s)) for i, j in picked]
    ferts = tuple(fertilizers) if fertilizers else EVAL_FERTILIZERS
    swaths = tuple(float(s) for s in swaths_m) if swaths_m else EVAL_SWATHS_M
    jobs = [(f, s) for f in ferts for s in swaths]
    return [EvalContext(i, f, s) for i, (f, s) in enumerate(jobs)]


# -- environments and counting ------------------------------------------------------------

def make_env(env_id: str, env_kwargs: Optional[dict] = None):
    """`gym.make(env_id, **env_kwargs)` wrapped in a `SimulationCounter`.

    Bad kwargs raise the env's `ConfigError` (naming the key)."""
    env_id = canonical_env_id(env_id)
    env = gym.make(env_id, **dict(env_kwargs or {}))
    return SimulationCounter(env, counts_reset=is_tuning(env_id))


class SimulationCounter(gym.Wrapper):
    """Counts simulations: every `step` (and every `reset` of an env whose reset runs a
    tray test, i.e. SpreaderTuning). `simulations` never decreases."""

    def __init__(self, env, counts_reset: bool = False):
        super().__init__(env)
        self.simulations = 0
        self.counts_reset = counts_reset

    def reset(self, **kwargs):
        out = self.env.reset(**kwargs)
        if self.counts_reset:  # a start rule may run several tray tests (info["tray_tests"])
            self.simulations += int(out[1].get("tray_tests", 1))
        return out

    def step(self, action):
        self.simulations += 1
        return self.env.step(action)


def published_action(env) -> np.ndarray:
    """The scene's own settings (the paper: 500 rpm, radial vanes) as a unit action."""
    task = env.unwrapped.task
    return task.settings_map.to_unit(task.settings_map.from_scene(task.base_scene))


# -- rows ---------------------------------------------------------------------------------

@dataclass
class Row:
    """One scored episode of one method on one job."""

    method: str
    context: dict
    settings: dict
    action: list
    cv_percent: Optional[float]
    cv_standard_error_percent: Optional[float]
    effective_swath_m: float
    reward: float
    landed_fraction: float
    search_simulations: int  # spent deciding on the settings (0 for a policy)
    scoring_simulations: int  # spent scoring them (1 per SpinnerDesign episode)
    decide_s: float  # wall time to decide (search, or the policy's forward pass)
    wall_s: float  # decide + score
    episode: int = 0
    sim_seed: Optional[int] = None
    extra: dict = field(default_factory=dict)

    @property
    def simulations(self) -> int:
        return self.search_simulations + self.scoring_simulations

    def as_dict(self) -> dict:
        out = asdict(self)
        out["simulations"] = self.simulations
        extra = out.pop("extra")
        out.update(extra)
        return out


def row_from_info(method: str, info: dict, reward: float, action, **kwargs) -> Row:
    metrics = info["metrics"]
    terms = info.get("reward_terms", {})
    cv = metrics.get("cv_percent_at_target")
    cv_se = metrics.get("cv_standard_error_percent")
    return Row(
        method=method,
        context=dict(info["context"]),
        settings=dict(info["settings"]),
        action=[float(a) for a in np.asarray(action, dtype=float).reshape(-1)],
        cv_percent=None if cv is None else float(cv),
        cv_standard_error_percent=None if cv_se is None else float(cv_se),
        effective_swath_m=float(metrics.get("effective_swath_m") or 0.0),
        reward=float(reward),
        landed_fraction=float(terms.get("landed_fraction", float("nan"))),
        sim_seed=info.get("sim_seed"),
        **kwargs,
    )


def score_action(env, ctx: EvalContext, action, method: str, episode: int = 0,
                 search_simulations: int = 0, decide_s: float = 0.0) -> Row:
    """Reset `ctx` with its scoring seed and step `action` once (SpinnerDesign)."""
    started = time.perf_counter()
    before = env.simulations
    env.reset(seed=ctx.score_seed(episode), options=ctx.options())
    _, reward, _, _, info = env.step(np.asarray(action, dtype=np.float64))
    score_s = time.perf_counter() - started
    return row_from_info(method, info, reward, action, search_simulations=search_simulations,
                         scoring_simulations=env.simulations - before, decide_s=decide_s,
                         wall_s=decide_s + score_s, episode=episode)


def run_policy(env, ctx: EvalContext, act: Callable[[np.ndarray], np.ndarray], method: str,
               episode: int = 0) -> Row:
    """One deterministic episode of a policy on `ctx` (any number of steps).

    For SpinnerDesign this is one forward pass and one (scoring) simulation. For
    SpreaderTuning every step is a tray test the policy needs, so all of them count as
    search simulations except the last, which is the score."""
    started = time.perf_counter()
    before = env.simulations
    obs, info = env.reset(seed=ctx.score_seed(episode), options=ctx.options())
    decide_s = 0.0
    reward, action = 0.0, None
    done = False
    while not done:
        t0 = time.perf_counter()
        action = act(obs)
        decide_s += time.perf_counter() - t0
        obs, reward, terminated, truncated, info = env.step(action)
        done = bool(terminated or truncated)
    used = env.simulations - before
    return row_from_info(method, info, reward, action, search_simulations=used - 1, scoring_simulations=1,
                         decide_s=decide_s, wall_s=time.perf_counter() - started, episode=episode)


# -- summaries and tables -----------------------------------------------------------------

SUMMARY_COLUMNS = (
    ("method", "method"),
    ("jobs", "jobs"),
    ("cv_percent", "CV at target (%)"),
    ("cv_standard_error_percent", "± SE (pp)"),
    ("versus_best", "vs best"),
    ("effective_swath_m", "eff. swath (m)"),
    ("swath_error_m", "swath error (m)"),
    ("reward", "reward"),
    ("search_simulations", "sims to decide / job"),
    ("simulations", "sims in all"),
    ("decide_s", "decide (s / job)"),
    ("wall_s", "wall (s)"),
    ("search_cv_percent", "CV the search believed (%)"),
    ("search_cv_se_percent", "belief ± SE (pp)"),
)
TIE_STANDARD_ERRORS = 2.0  # differences smaller than this many standard errors are ties


def _mean(values: Iterable[Optional[float]]) -> Optional[float]:
    vals = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(vals)) if vals else None


def _mean_se(values: Iterable[Optional[float]]) -> Optional[float]:
    """Standard error of a mean of independent estimates with these standard errors."""
    vals = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(math.sqrt(sum(v * v for v in vals)) / len(vals)) if vals else None


def _job_key(row: Row) -> tuple:
    """A job as a whole: every field of its context (jobs may differ only in wind or speed)."""
    c = row.context
    return (c["fertilizer"], c["target_swath_m"], c.get("spinner_material"), c.get("forward_speed_m_s"),
            tuple(c.get("wind_m_s") or ()))


def summarise(method: str, rows: Sequence[Row], worst_cv: float = WORST_CV_PERCENT) -> dict:
    """Means over the rows of one method. A run where nothing landed counts as CV `worst_cv`.

    The CV's standard error is that of the mean over the rows, from each run's own
    standard error (sampling noise; the jobs themselves are fixed)."""
    jobs = {_job_key(r) for r in rows}
    per_job_search, per_job_decide = {}, {}  # per (job, run): its episodes share one search
    for r in rows:
        key = (_job_key(r), r.extra.get("run", 0))
        per_job_search[key] = max(per_job_search.get(key, 0), r.search_simulations)
        per_job_decide[key] = max(per_job_decide.get(key, 0.0), r.decide_s)
    return {
        "method": method,
        "jobs": len(jobs),
        "episodes": len(rows),
        "cv_percent": _mean(worst_cv if r.cv_percent is None else r.cv_percent for r in rows),
        "cv_standard_error_percent": _mean_se(r.cv_standard_error_percent for r in rows),
        "effective_swath_m": _mean(r.effective_swath_m for r in rows),
        "swath_error_m": _mean(abs(r.effective_swath_m - r.context["target_swath_m"]) for r in rows),
        "reward": _mean(r.reward for r in rows),
        "search_simulations": _mean(per_job_search.values()),
        "simulations": int(sum(per_job_search.values()) + sum(r.scoring_simulations for r in rows)),
        "decide_s": _mean(per_job_decide.values()),
        "wall_s": float(sum(per_job_decide.values())
                        + sum(r.wall_s - r.decide_s for r in rows)),
        # searches: what the search believed of its choice (mean of its re-scores on fresh samples)
        "search_cv_percent": _mean(r.extra.get("search_best_cv_percent") for r in rows if r.episode == 0),
        "search_cv_se_percent": _mean_se(r.extra.get("search_best_cv_se_percent") for r in rows
                                         if r.episode == 0),
        "search_reward": _mean(r.extra.get("search_best_reward") for r in rows if r.episode == 0),
    }


def mark_ties(summaries: Sequence[dict]) -> None:
    """Set `versus_best` on each summary: "best", "tie" (within TIE_STANDARD_ERRORS combined
    standard errors of the lowest CV) or "+x.x pp" (worse by more than that)."""
    scored = [s for s in summaries if s.get("cv_percent") is not None]
    if not scored:
        return
    best = min(scored, key=lambda s: s["cv_percent"])
    for s in summaries:
        if s.get("cv_percent") is None:
            s["versus_best"] = None
        elif s is best:
            s["versus_best"] = "best"
        else:
            gap = s["cv_percent"] - best["cv_percent"]
            se = math.hypot(s.get("cv_standard_error_percent") or 0.0, best.get("cv_standard_error_percent") or 0.0)
            s["versus_best"] = "tie" if gap < TIE_STANDARD_ERRORS * se else f"+{gap:.1f} pp"


def _cell(value: Any, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "-"
        if value == 0:
            return "0"
        if abs(value) >= 100:
            return f"{value:.0f}"
        return f"{value:.{digits}g}"
    return str(value)


def markdown_table(records: Sequence[dict], columns: Sequence[tuple[str, str]]) -> str:
    head = "| " + " | ".join(title for _, title in columns) + " |"
    rule = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(_cell(rec.get(key)) for key, _ in columns) + " |" for rec in records]
    return "\n".join([head, rule, *body])


def text_table(records: Sequence[dict], columns: Sequence[tuple[str, str]]) -> str:
    rows = [[_cell(rec.get(key)) for key, _ in columns] for rec in records]
    return format_table(rows, [title for _, title in columns])


def write_csv(path: Path, records: Sequence[dict], columns: Sequence[tuple[str, str]]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([key for key, _ in columns])
        for rec in records:
            writer.writerow(["" if rec.get(k) is None else rec.get(k) for k, _ in columns])
    return path


ROW_COLUMNS = (
    ("method", "method"),
    ("fertilizer", "fertilizer"),
    ("target_swath_m", "target (m)"),
    ("episode", "episode"),
    ("rpm", "rpm"),
    ("pitch_deg", "pitch (deg)"),
    ("cv_percent", "CV at target (%)"),
    ("cv_standard_error_percent", "± SE (pp)"),
    ("effective_swath_m", "effective swath (m)"),
    ("reward", "reward"),
    ("search_simulations", "sims to decide"),
    ("decide_s", "decide (s)"),
)


def flat_row(row: Row) -> dict:
    """A row for tables: context and settings flattened."""
    pitch = row.settings.get("pitch_deg") or []
    return {
        **row.as_dict(),
        "fertilizer": row.context["fertilizer"],
        "target_swath_m": row.context["target_swath_m"],
        "rpm": row.settings.get("rpm"),
        "pitch_deg": pitch[0] if len(pitch) == 1 else "/".join(f"{p:.1f}" for p in pitch),
    }


# -- pictures -----------------------------------------------------------------------------

def simulate_row(env, row: Row):
    """Re-run a scored row (same job, settings and granule sample) for its pictures."""
    task = env.unwrapped.task
    c, s = row.context, row.settings
    context = Context(c["fertilizer"], c["spinner_material"], float(c["target_swath_m"]),
                      float(c["forward_speed_m_s"]), tuple(c["wind_m_s"]))
    settings = Settings.from_dict(s)
    scene = task.settings_scene(task.context_scene(context), settings, int(row.sim_seed))
    return task.run(scene)


def pattern_grid(results: Sequence[tuple[str, Any]], path: Path, title: str = "") -> Path:
    """Transverse patterns of several runs in one picture (one panel each)."""
    # matplotlib (and viz.plots, which imports it) only when a picture is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from spreadgym.viz.plots import transverse_pattern

    n = len(results)
    cols = min(4, max(1, n))
    rows = int(math.ceil(n / cols))
    fig = Figure(figsize=(3.6 * cols, 2.9 * rows + 0.4), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).reshape(-1)
    for ax, (label, result) in zip(axes, results):
        transverse_pattern(ax, result, legend=False)
        cv = result.metrics.cv_percent_at_target
        cv_text = "-" if cv is None else f"{cv:.1f} %"
        ax.set_title(f"{label}\nCV {cv_text}, swath {result.metrics.effective_swath_m:g} m", fontsize=8)
        ax.xaxis.label.set_fontsize(7)
        ax.yaxis.label.set_fontsize(7)
        ax.tick_params(labelsize=7)
    for ax in axes[n:]:
        ax.set_visible(False)
    if title:
        fig.suptitle(title, fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path
