"""Benchmarks behind `spreadgym bench` / `make bench` (never run by the tests).

Each benchmark returns rows (dicts) and is timed with medians over repeats, on one
core (the caller pins threads). Quote medians and ratios: shared machines are noisy.
"""

from __future__ import annotations

import math
import statistics
import time
from typing import Callable

import numpy as np
import pymunk
import pymunk.batch as batch

from spreadgym.spread import flight as flight_model
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.granules import sample_granules
from spreadgym.config.materials import load_library
from spreadgym.physics.geometry import vane_segments
from spreadgym.physics.numerics import collision_bias_for
from spreadgym.physics.stepped.pymunk_spinner import GRANULES_PER_SPACE, simulate_pymunk
from spreadgym.config.scene import Scene, load_scene


def median_time(fn: Callable[[], object], repeats: int) -> tuple[float, object]:
    """Median wall time (s) of `fn()` over `repeats` runs, and its last result."""
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def bare_pymunk_loop(scene: Scene, granules, contacts, dt: float, steps: int,
                     per_space: int = GRANULES_PER_SPACE) -> float:
    """What pymunk itself costs: the same spinner and granules, each step a batch
    read, a batch force write and a step, nothing removed, no physics of ours.
    Returns the wall time (s)."""
    inner, outer = vane_segments(scene)
    n = granules.count
    spaces = []
    start_xy = granules.release_in_spinner_frame()
    for k in range(max(1, math.ceil(n / per_space))):
        space = pymunk.Space()
        space.collision_slop, space.collision_bias = 1e-5, collision_bias_for(dt)
        spinner = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        spinner.angular_velocity = scene.spinner.omega_rad_s
        space.add(spinner, *[pymunk.Segment(spinner, tuple(a), tuple(b), 0.5 * scene.vanes.thickness_m)
                             for a, b in zip(inner, outer)])
        for i in range(k, n, max(1, math.ceil(n / per_space))):
            body = pymunk.Body(float(granules.mass_kg[i]), math.inf)
            body.position = tuple(start_xy[i])
            shape = pymunk.Circle(body, float(granules.radius_m[i]))
            shape.filter = pymunk.ShapeFilter(group=1)
            space.add(body, shape)
        spaces.append(space)
    fields = batch.BodyFields.BODY_ID | batch.BodyFields.POSITION | batch.BodyFields.VELOCITY
    read, write = batch.Buffer(), batch.Buffer()
    started = time.perf_counter()
    for _ in range(steps):
        for space in spaces:
            read.clear()
            batch.get_space_bodies(space, fields, read)
            state = np.frombuffer(read.float_buf(), dtype=np.float64).reshape(-1, 4)
            write.set_float_buf(np.zeros(2 * state.shape[0]))
            batch.set_space_bodies(space, batch.BodyFields.FORCE, write)
            space.step(dt)
    return time.perf_counter() - started


def spinner_benchmark(granules: int = 2000, repeats: int = 3) -> list[dict]:
    """The paper scene in the pymunk model against a bare pymunk loop of the same
    spinner, granule count, time step and number of steps."""
    library = load_library()
    scene = load_scene("paper", {"sim.granules": granules})
    contacts = resolve_contacts(scene, library)
    batch_ = sample_granules(scene, library.fertilizer(scene.fertilizer))
    wall, departure = median_time(lambda: simulate_pymunk(scene, batch_, contacts), repeats)
    gone = departure.departed
    t_fall = float(departure.time_s.min())  # the closed-form fall precedes stepping
    steps = int(round((float(departure.time_s.max()) - t_fall) / departure.dt_s)) + 1
    granule_steps = float(np.sum(np.ceil((departure.time_s - t_fall) / departure.dt_s)))
    bare = statistics.median(
        bare_pymunk_loop(scene, batch_, contacts, departure.dt_s, steps) for _ in range(repeats)
    )
    return [{
        "scene": "paper", "granules": granules, "dt_s": departure.dt_s, "steps": steps,
        "departed": int(gone.sum()), "simulate_wall_s": wall, "bare_loop_wall_s": bare,
        "ratio_simulate_to_bare": wall / bare,
        "granule_steps_per_s": granule_steps / wall,
        "bare_granule_steps_per_s": granules * steps / bare,
    }]


def method_speed_benchmark(granules: int = 2000, repeats: int = 3) -> list[dict]:
    """analytic against pymunk on a scene both serve (paper spinner, no drop)."""
    from spreadgym.physics.analytic.spinner import simulate_analytic

    library = load_library()
    scene = load_scene("paper", {"sim.granules": granules, "feed.drop_height_m": 0.0})
    contacts = resolve_contacts(scene, library)
    batch_ = sample_granules(scene, library.fertilizer(scene.fertilizer))
    wall_a, dep_a = median_time(lambda: simulate_analytic(scene, batch_, contacts), repeats)
    wall_p, dep_p = median_time(lambda: simulate_pymunk(scene, batch_, contacts), repeats)
    return [{
        "scene": "paper, drop 0", "granules": granules, "analytic_wall_s": wall_a, "pymunk_wall_s": wall_p,
        "speedup": wall_p / wall_a,
        "speed_difference_percent": 100.0 * (dep_a.speed_m_s[dep_a.departed].mean()
                                             / dep_p.speed_m_s[dep_p.departed].mean() - 1.0),
    }]


def flight_benchmark(counts=(2000, 20000), repeats: int = 5) -> list[dict]:
    """Granules per second of the flight solver on paper-scene launch states."""
    scene = load_scene("paper")
    rng = np.random.default_rng(1)
    rows = []
    for n in counts:
        speed = rng.uniform(5.0, 50.0, n)
        angle = rng.uniform(0.0, 2.0 * math.pi, n)
        lift = np.radians(rng.uniform(-10.0, 30.0, n))
        velocity = np.column_stack([speed * np.cos(lift) * np.cos(angle), speed * np.cos(lift) * np.sin(angle),
                                    speed * np.sin(lift)])
        position = 0.15 * np.column_stack([np.cos(angle), np.sin(angle)])
        diameter = rng.uniform(0.002, 0.004, n)
        wall, _ = median_time(lambda: flight_model.fly(position, np.full(n, 0.8), velocity, diameter, 1734.0,
                                                       scene.flight), repeats)
        rows.append({"granules": n, "wall_s": wall, "granules_per_s": n / wall})
    return rows


def cv_noise_benchmark(counts=(250, 500, 1000, 2000, 4000), seeds: int = 8, scene_name: str = "paper",
                       model: str = "auto") -> list[dict]:
    """Spread of the CV at the target swath over seeds, against the granule count.

    The standard deviation over seeds is the standard error of one run's CV; the
    mean shows the upward bias of a CV from few granules.
    """
    from spreadgym.spread.pipeline import run_scene

    rows = []
    for n in counts:
        cvs, walls = [], []
        for seed in range(seeds):
            result = run_scene(load_scene(scene_name, {"sim.granules": n, "sim.seed": seed}), model=model, ci=False)
            cvs.append(result.metrics["cv_percent_at_target"])
            walls.append(result.metrics["wall_s"])
        cvs = np.array(cvs, dtype=float)
        rows.append({"scene": scene_name, "granules": n, "seeds": seeds, "cv_mean_percent": float(cvs.mean()),
                     "cv_standard_error_percent": float(cvs.std(ddof=1)), "wall_median_s": statistics.median(walls)})
    return rows


def plot_cv_noise(rows: list[dict], path) -> None:
    """CV standard error and mean against granule count (log axis)."""
    from matplotlib.figure import Figure

    n = [r["granules"] for r in rows]
    fig = Figure(figsize=(7, 4.5), dpi=100)
    ax = fig.add_subplot()
    ax.plot(n, [r["cv_standard_error_percent"] for r in rows], "o-", label="standard error of the CV (s.d. over seeds)")
    ax.plot(n, [r["cv_mean_percent"] for r in rows], "s--", label="mean CV over seeds")
    ref = rows[-1]["cv_standard_error_percent"] * (rows[-1]["granules"] / np.array(n)) ** 0.5
    ax.plot(n, ref, ":", color="grey", label=r"$\propto 1/\sqrt{N}$")
    ax.set_xscale("log")
    ax.set_xlabel("granules per run")
    ax.set_ylabel("CV at the target swath (%)")
    ax.set_title(f"Sampling noise of the CV, {rows[0]['scene']} scene ({rows[0]['seeds']} seeds per point)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)


REFERENCE_SCENES = ("paper", "field", "paper-deflectors")


def _auto_dt(scene: Scene) -> float:
    """The pymunk model's automatic step for this scene (smallest granule radius)."""
    from spreadgym.physics.numerics import choose_time_step

    fertilizer = load_library().fertilizer(scene.fertilizer)
    return choose_time_step(scene, 0.5 * min(fertilizer.size.min_m, fertilizer.size.d50_m)).dt_s


def speed_accuracy_benchmark(scenes=REFERENCE_SCENES, counts=(500, 2000), dt_factors=(4.0, 2.0, 1.0),
                             reference_granules: int = 4000, reference_dt_factor: float = 0.5,
                             progress: Callable[[str], None] = lambda _: None) -> list[dict]:
    """Error against a tight reference and wall time per granule, for every method.

    Reference per scene: pymunk at `reference_dt_factor` x its automatic step with
    `reference_granules`. Errors: mean departure speed (%), CV at the target swath
    (percentage points) and effective swath (m). CV errors include the sampling
    noise of a finite run, which is part of what a setting costs or buys.
    """
    from spreadgym.errors import ConfigError
    from spreadgym.spread.pipeline import run_scene

    def run(scene_name, model, granules, dt_factor=None):
        overrides = {"sim.granules": granules, "sim.seed": 1}
        base = load_scene(scene_name, overrides)
        if dt_factor is not None:
            overrides["sim.dt_s"] = dt_factor * _auto_dt(base)
        return run_scene(load_scene(scene_name, overrides), model=model, ci=False).metrics

    rows = []
    for scene_name in scenes:
        progress(f"{scene_name}: reference")
        ref = run(scene_name, "pymunk", reference_granules, reference_dt_factor)
        plans = [("analytic", n, None) for n in (*counts, reference_granules)]
        plans += [("pymunk", n, f) for n in counts for f in dt_factors]
        plans += [("spring-damper", counts[0], None)]
        for model, n, factor in plans:
            progress(f"{scene_name}: {model} {n} granules" + (f", dt x{factor:g}" if factor else ""))
            try:
                m = run(scene_name, model, n, factor)
            except ConfigError as refused:  # a step beyond a stability limit: the guard said no
                rows.append({"scene": scene_name, "method": model, "granules": n, "dt_factor": factor or 1.0,
                             "dt_s": float("nan"), "wall_s": float("nan"), "wall_per_granule_s": float("nan"),
                             "speed_error_percent": float("nan"), "cv_error_pp": float("nan"),
                             "swath_error_m": float("nan"), "note": f"refused: {refused}"})
                continue
            d, r = m["departure"], ref["departure"]
            rows.append({
                "scene": scene_name, "method": m["model"], "granules": n, "dt_factor": factor or 1.0,
                "dt_s": m["dt_s"], "wall_s": m["wall_s"], "wall_per_granule_s": m["wall_s"] / n,
                "speed_error_percent": 100.0 * abs(d["speed_mean_m_s"] / r["speed_mean_m_s"] - 1.0),
                "cv_error_pp": abs((m["cv_percent_at_target"] or 100.0) - (ref["cv_percent_at_target"] or 100.0)),
                "swath_error_m": abs(m["effective_swath_m"] - ref["effective_swath_m"]),
                "note": "",
            })
    return rows


def pareto_mask(cost: np.ndarray, error: np.ndarray) -> np.ndarray:
    """True for points no other point beats on both cost and error (NaN never on the front)."""
    ok = np.isfinite(cost) & np.isfinite(error)
    front = np.zeros(cost.shape, dtype=bool)
    for i in np.flatnonzero(ok):
        beaten = ok & (cost <= cost[i]) & (error <= error[i]) & ((cost < cost[i]) | (error < error[i]))
        front[i] = not beaten.any()
    return front


def plot_speed_accuracy(rows: list[dict], path) -> None:
    """Error against wall time per granule, one panel per scene and metric, Pareto front marked."""
    from matplotlib.figure import Figure

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    metrics = [("speed_error_percent", "departure speed error (%)"), ("cv_error_pp", "CV error (pp)"),
               ("swath_error_m", "effective swath error (m)")]
    styles = {"analytic": ("o", "tab:green"), "pymunk": ("s", "tab:blue"), "spring-damper": ("^", "tab:red")}
    fig = Figure(figsize=(13, 3.6 * len(scenes)), dpi=100)
    axes = fig.subplots(len(scenes), len(metrics), squeeze=False)
    for row_axes, scene in zip(axes, scenes):
        data = [r for r in rows if r["scene"] == scene and np.isfinite(r["wall_s"])]
        cost = np.array([r["wall_per_granule_s"] for r in data])
        for ax, (key, label) in zip(row_axes, metrics):
            err = np.array([r[key] for r in data])
            log_axis = key != "swath_error_m"  # swath errors come in whole trays, zero included
            shown = np.maximum(err, 1e-4) if log_axis else err
            for method, (marker, colour) in styles.items():
                pick = np.array([r["method"] == method for r in data])
                if pick.any():
                    ax.scatter(cost[pick] * 1e3, shown[pick], marker=marker, color=colour, label=method, zorder=3)
            front = pareto_mask(cost, err)
            order = np.argsort(cost[front])
            ax.step(cost[front][order] * 1e3, shown[front][order], where="post", color="k", lw=1, alpha=0.6,
                    label="Pareto front", zorder=2)
            for r, c, e in zip(data, cost, shown):
                ax.annotate(f"{r['granules']}" + (f" x{r['dt_factor']:g}" if r["method"] == "pymunk" else ""),
                            (c * 1e3, e), fontsize=6, xytext=(3, 3), textcoords="offset points")
            ax.set_xscale("log")
            ax.set_yscale("log" if log_axis else "linear")
            ax.set_xlabel("wall time per granule (ms)")
            ax.set_ylabel(label)
            ax.set_title(f"{scene}", fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle("Speed against accuracy (labels: granules, and dt x automatic step for pymunk)")
    fig.tight_layout()
    fig.savefig(path)
