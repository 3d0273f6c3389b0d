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

from spreadgym.config.materials import load_library
from spreadgym.config.scene import Scene, load_scene
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.geometry import vane_segments
from spreadgym.physics.granules import sample_granules
from spreadgym.physics.numerics import collision_bias_for
from spreadgym.physics.stepped.pymunk_spinner import GRANULES_PER_SPACE, simulate_pymunk
from spreadgym.spread import flight as flight_model


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
    batch_ = sample_granules(scene, library.fertilizer_of(scene))
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
    batch_ = sample_granules(scene, library.fertilizer_of(scene))
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
        def fly(position=position, velocity=velocity, diameter=diameter, n=n):
            return flight_model.fly(position, np.full(n, 0.8), velocity, diameter, 1734.0, scene.flight)

        wall, _ = median_time(fly, repeats)
        rows.append({"granules": n, "wall_s": wall, "granules_per_s": n / wall})
    return rows


def interleaved_rates(series: dict, designs: int, repeats: int) -> tuple[list[dict], dict]:
    """Designs per second of each series: `series` maps (what, batch size, threads) to a
    callable that evaluates `designs` designs. Every block runs each series once, at its own
    thread count (spreadgym.threads), so a shared machine's load falls on all alike; block 0
    warms up (compiles or loads the kernels), the next `repeats` are timed. Returns one row
    per series (median and range) and each series' last result."""
    from spreadgym import threads

    rates: dict = {key: [] for key in series}
    found = {}
    for block in range(repeats + 1):
        for key, run in series.items():
            threads.set_threads(key[2])
            start = time.perf_counter()
            found[key] = run()
            if block:
                rates[key].append(designs / (time.perf_counter() - start))
    threads.set_threads(None)
    rows = [{"what": what, "batch": size, "threads": n, "designs_per_s": statistics.median(r),
             "designs_per_s_low": min(r), "designs_per_s_high": max(r)} for (what, size, n), r in rates.items()]
    return rows, found


def batch_series(batch: int = 64, repeats: int = 5) -> list[dict]:
    """Designs per second of `batch` scenes (paper, field and twin-field in turn, rpm and
    seed varied) run by `run_scene` one by one and by one `run_batch`, at one thread and
    at all of spreadgym.threads' count: median of `repeats` interleaved blocks, and their
    range (see agents/commands/bench.py, section batch). Checks the batch's bits."""
    from spreadgym import threads
    from spreadgym.config.scene import scene_with
    from spreadgym.spread.batch import run_batch
    from spreadgym.spread.pipeline import run_scene

    library = load_library()
    bases = [load_scene(name) for name in ("paper", "field", "twin-field")]
    scenes = [scene_with(bases[i % 3], {"sim.seed": i, "spinner.rpm": 450.0 + 5.0 * i}) for i in range(batch)]
    one_by_one, together = "run_scene, one by one (paper, field, twin-field)", "run_batch (paper, field, twin-field)"
    counts = sorted({1, threads.thread_count()})
    series = {**{(one_by_one, 1, n): lambda: [run_scene(s, library=library, ci=False) for s in scenes] for n in counts},
              **{(together, batch, n): lambda: run_batch(scenes, library=library, ci=False) for n in counts}}
    rows, found = interleaved_rates(series, batch, repeats)
    same = all(np.array_equal(a.replicate_masses_kg, b.replicate_masses_kg)
               for a, b in zip(found[one_by_one, 1, counts[-1]], found[together, batch, counts[-1]]))
    if not same:
        raise AssertionError("run_batch differs from run_scene")
    return rows
