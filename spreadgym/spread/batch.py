"""Many scenes in one call, every core at work: `run_batch(scenes)` equals, bit for bit,
`[run_scene(s) for s in scenes]`.

Granules never touch each other, so a batch is (design x disc x granule) independent
problems. The stages:
  1. plan each scene (its discs, model, granule sample and contacts; `pipeline.plan_scene`),
     one after another (small numpy work that holds the GIL);
  2. every disc of every scene through its spinner model at once: the compiled model runs
     all granules in one parallel kernel (`prange` over the flat (design x disc x granule)
     index; a twin machine is simply two discs in that index);
  3. finish the plain designs (one disc, no plates, release-angle copies) together, a few
     compiled calls for all of them (`plain_finish.finish_plain`), and every other scene
     (cone, plates, copies, flight, trays, metrics; `pipeline.finish_scene`) side by side
     in a pool of threads (its compiled kernels release the GIL, so one scene's Python
     overlaps another's kernels).
Every stage computes each scene exactly as `run_scene` does, so no result depends on the
batch or on the thread count (spreadgym.threads decides the count).

The interface holds scenes and returns `SimulationResult`s; where the arrays of stage 2
live is the spinner model's business (`SpinnerModel.batch_runner`), which leaves room for
a device backend.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Optional, Sequence, Union

from spreadgym import heap
from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError
from spreadgym.physics.selection import SPINNER_MODELS
from spreadgym.spread.pipeline import SimulationResult, finish_scene, plan_scene
from spreadgym.spread.plain_finish import finish_plain, is_plain
from spreadgym.threads import thread_map


def run_batch(scenes: Sequence[Scene], model: str = "auto", library: Optional[MaterialLibrary] = None,
              ci: bool = True, first_replicate: Union[int, Sequence[int]] = 0) -> list[SimulationResult]:
    """`run_scene(scene, model, library, ci=ci, first_replicate=first)` of every scene (with
    its own `first_replicate` when a sequence is given), computed together; each result's
    `wall_s` is the batch's wall time over its size."""
    started = time.perf_counter()
    heap.tune()
    scenes = list(scenes)
    for i, scene in enumerate(scenes):
        if not isinstance(scene, Scene):
            raise ConfigError(f"scenes[{i}]", f"expected a Scene, got {type(scene).__name__}")
    firsts = [first_replicate] * len(scenes) if isinstance(first_replicate, int) else list(first_replicate)
    if len(firsts) != len(scenes):
        raise ConfigError("first_replicate", f"{len(firsts)} values for {len(scenes)} scenes")
    if not scenes:
        return []
    library = library or load_library()
    # planning is small numpy work that holds the GIL throughout: threads would only take turns
    plans = [plan_scene(scene, model, library, first) for scene, first in zip(scenes, firsts)]
    departures = [[] for _ in plans]
    for chosen in dict.fromkeys(plan.chosen for plan in plans):  # each model once, in order of first use
        owners = [i for i, plan in enumerate(plans) if plan.chosen == chosen for _ in plan.spinner_runs()]
        runs = [run for plan in plans if plan.chosen == chosen for run in plan.spinner_runs()]
        for owner, departure in zip(owners, SPINNER_MODELS[chosen].run_batch(runs)):
            departures[owner].append(departure)

    plainness = [is_plain(plan) for plan in plans]
    plain = [i for i, yes in enumerate(plainness) if yes]
    others = [i for i, yes in enumerate(plainness) if not yes]
    results: list = [None] * len(plans)
    for i, result in zip(plain, finish_plain([plans[i] for i in plain], [departures[i] for i in plain], ci)):
        results[i] = result
    for i, result in zip(others, thread_map(lambda k: finish_scene(plans[others[k]], departures[others[k]], ci),
                                            len(others))):
        results[i] = result
    wall_s = (time.perf_counter() - started) / len(results)
    for result in results:
        result.metrics = replace(result.metrics, wall_s=wall_s)
    return results

