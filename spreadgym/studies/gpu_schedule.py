"""How the GPU spinner kernel's schedule should fare, from what the CPU kernel counts.

A granule's run is a loop of event passes whose count varies 100-fold between granules,
and a GPU warp's 32 threads advance together. This model takes every granule's pass
count from the CPU kernel (`granule_run.LOOPS`, the same arithmetic as the GPU's) for
paper designs of varied rpm and seed, assumes every pass costs the same and a thread runs
one pass per unit of time, and gives the kernel's time in those units under three
schedules, for several counts of threads the GPU keeps resident:

- one granule per thread in launch order: blocks of `cuda_spinner.THREADS_PER_BLOCK`
  threads (importing it loads numba's CUDA target, which needs no GPU), a block holding
  its place until its slowest granule ends, the next block taking the place (how a GPU
  hands out blocks);
- a queue in launch order: every resident thread takes the next granule as it ends one;
- a queue longest first: the same, in `model.longest_first` order (the shipped one:
  start radius bins), and for comparison in the order of a full sort by start radius.

It is a model (no memory traffic, no divergence inside a pass, a uniform pass cost), so
its figures are a forecast that a GPU measurement settles (agents/device_check.py,
section "GPU schedules"); the bound column is what no schedule can beat (the work over
the threads, or the longest granule). A fixed pass time ignores that a nearly empty GPU
runs a pass faster than a full one, so the model overstates small batches' times; each
row also gives the warps' longest runs over their mean runs, the gain if the GPU is bound
by the warp instructions it issues.
"""

from __future__ import annotations

import heapq

import numpy as np

RESIDENT = (16_384, 42_240, 65_536, 131_072)
"""Threads a GPU keeps resident. 42 240 is an H200 or H100 SXM (132 SMs) at this kernel's
registers: ptxas 12.9 for sm_90 gives the queue kernel 188 registers a thread (the
one-granule-per-thread kernel 194), no spills, so 10 warps, 320 threads, per SM."""
DESIGNS = (64, 256, 1024)


def pass_counts(designs: int = 64) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(passes, start, design, P) of `designs` paper designs (seed i, rpm 400 + 10 (i mod 64)), the
    CPU kernel's pass count of every granule with the kernel's flat arrays."""
    from spreadgym.config.materials import load_library
    from spreadgym.config.scene import load_scene, scene_with
    from spreadgym.physics.compiled import granule_run
    from spreadgym.physics.compiled.model import kernel_arrays, kernel_inputs, run_kernels
    from spreadgym.spread.pipeline import plan_scene

    library, base = load_library(), load_scene("paper")
    scenes = [scene_with(base, {"sim.seed": i, "spinner.rpm": 400.0 + 10.0 * (i % 64)}) for i in range(designs)]
    batch = [kernel_inputs(*run) for scene in scenes for run in plan_scene(scene, "compiled", library).spinner_runs()]
    passes = np.concatenate([out[:, granule_run.LOOPS] for out, _, _ in run_kernels(batch)])
    arrays, _ = kernel_arrays(batch)
    return passes, arrays[0], arrays[2], arrays[5]


def one_per_thread(passes: np.ndarray, resident: int, block: int) -> float:
    """Kernel time with one granule per thread: each block of `block` threads ends with its
    slowest granule, and the next block takes its place."""
    blocks = np.maximum.reduceat(passes, np.arange(0, passes.size, block))
    places = [0.0] * max(1, resident // block)
    for length in blocks:
        heapq.heapreplace(places, places[0] + length)
    return max(places)


def queued(passes: np.ndarray, resident: int) -> float:
    """Kernel time with `resident` threads taking granules from a queue in the given order."""
    if passes.size <= resident:
        return float(passes.max())
    threads = [float(p) for p in passes[:resident]]
    heapq.heapify(threads)
    for length in passes[resident:]:
        heapq.heapreplace(threads, threads[0] + length)
    return max(threads)


def schedule_rows() -> list[dict]:
    """The model's kernel times (in passes) per batch size and resident thread count,
    tiling the 64 counted designs to larger batches; every row also gives the counts'
    spread: fewest, median, 99th percentile and most, the warps' longest runs summed over their mean
    runs (32 granules in launch order), the correlation of passes with start radius."""
    from spreadgym.physics.compiled.cuda_spinner import THREADS_PER_BLOCK
    from spreadgym.physics.compiled.layout import DISC_RADIUS
    from spreadgym.physics.compiled.model import longest_first

    passes, start, design, params = pass_counts()
    warps = passes[: passes.size // 32 * 32].reshape(-1, 32)
    spread = {"passes_min": float(passes.min()), "passes_median": float(np.median(passes)),
              "passes_p99": float(np.percentile(passes, 99)), "passes_max": float(passes.max()),
              "warp_longest_over_mean": warps.max(1).sum() / warps.mean(1).sum(),
              "corr_passes_start_radius": float(np.corrcoef(passes, np.hypot(start[:, 0], start[:, 1]))[0, 1])}
    rows = []
    for designs in DESIGNS:
        tiles = designs // 64
        work = np.tile(passes, tiles)
        starts, owners = np.tile(start, (tiles, 1)), np.tile(design, tiles)
        order = longest_first(starts, owners, params)
        exact = np.argsort(np.hypot(starts[:, 0], starts[:, 1]) / params[owners, DISC_RADIUS], kind="stable")
        for resident in RESIDENT:
            grid, queue = one_per_thread(work, resident, THREADS_PER_BLOCK), queued(work, resident)
            first = queued(work[order], resident)
            rows.append({"designs": designs, "resident_threads": resident, "one_per_thread": grid,
                         "queue_launch_order": queue, "queue_longest_first": first,
                         "queue_full_sort": queued(work[exact], resident),
                         "bound": max(work.sum() / resident, float(work.max())),
                         "speedup_queue": grid / queue, "speedup_longest_first": grid / first, **spread})
    return rows
