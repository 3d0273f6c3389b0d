"""The compiled spinner on a CUDA GPU: one launch per batch, threads taking granules from a queue.

The kernel calls the CPU kernel's own scalar code, `granule_run.follow` and everything
it calls: numba.cuda compiles a CPU-jitted function that a GPU kernel calls for the GPU
from its Python source, so the physics is defined once and a change to it reaches both
devices. The GPU-specific part is here: how granules are handed to threads, and each
thread's scratch array in its local memory. Results equal the CPU's up to floating-point
contraction (the GPU compiler fuses multiply-adds); under numba's CUDA simulator
(NUMBA_ENABLE_CUDASIM=1) the kernel runs the CPU code itself and the results are the
CPU's bits.

**The schedule.** A granule's run takes from 10 to over 1 000 passes of its event
loop (paper designs: median 32, 99th percentile 96), and the 32 threads of a warp advance
together, so a warp of one granule per thread lasts as long as its slowest granule:
counted on 64 paper designs, the warps' longest runs add up to 2.5 times their mean
runs. Here each thread instead takes the next granule from a queue (an atomic counter)
as it finishes one, over a grid of at most the hardware's threads, and the queue hands
out the granules that start nearest the axis first (they run longest: the start radius
correlates -0.64 with the passes), so the last granules taken are short ones. A schedule
model fed with those counts (studies/gpu_schedule.py) forecasts the kernel about 2.5-3
times faster on large batches, not yet measured on a GPU (docs/performance.md, the CUDA
backend); each granule is computed alone, so the schedule never changes a result.

Imported only when the device is "cuda" (spreadgym.device); numba's CUDA target then
compiles the kernel at the first launch and caches it next to this file. On an H200
(numba-cuda 0.30.4, sm_90) the one-granule-per-thread kernel compiled in 39 s and matched
the CPU on 155 648 granules of 72 designs: the same outcomes, departures within
6e-12 m/s, the same tray masses to the bit (docs/performance.md, the CUDA backend).
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from numba import config, float64

from spreadgym.physics.compiled import face_motion, granule_run
from spreadgym.physics.compiled.cuda_target import cuda, host_array  # numba's CUDA target, loaded there
from spreadgym.physics.compiled.model import longest_first

SCRATCH = (2, face_motion.EVENTS)  # a module constant: numba.cuda sizes local arrays from constants only
THREADS_PER_BLOCK = 64
"""Threads per block: 32 to 256 ran within 13 % of each other on an H200 (docs/performance.md)."""
RESIDENT_THREADS_PER_SM = 2048
"""The queue's grid per multiprocessor: the most threads one holds at once on any GPU
(2048 on Volta, A100 and H100/H200, fewer on others; this kernel's registers allow 320 on
sm_90). Blocks beyond what fits wait, then find the queue empty and end at once."""
SIMULATED_THREADS = 128  # the grid under numba's CUDA simulator (it has no device to ask)


@cuda.jit(cache=True)  # the GPU compile takes minutes (200 s for sm_90 on the two-core machine): once per install
def _run_queue(order, taken, queued, start, radius, design, z0, vz0, P, V, vane_count, out, outcome, no_track):
    """Each thread runs granules order[k]: k taken from the counter taken[0] until none is
    left when `queued`, else k its own index in the grid (one granule per thread)."""
    work = cuda.local.array(SCRATCH, float64)
    if queued:
        k = cuda.atomic.add(taken, 0, 1)
    else:
        k = cuda.grid(1)
    while k < order.shape[0]:
        i = order[k]
        d = design[i]
        outcome[i] = granule_run.follow(start[i, 0], start[i, 1], radius[i], z0[d], vz0[d], host_array(P[d]),
                                        host_array(V[d, :vane_count[d]]), host_array(out[i]), host_array(no_track),
                                        work)
        if queued:
            k = cuda.atomic.add(taken, 0, 1)
        else:
            k = order.shape[0]


def grid_threads() -> int:
    """The grid of the queue: multiprocessors x RESIDENT_THREADS_PER_SM; SIMULATED_THREADS
    under the simulator."""
    if config.ENABLE_CUDASIM:
        return SIMULATED_THREADS
    return int(cuda.get_current_device().MULTIPROCESSOR_COUNT) * RESIDENT_THREADS_PER_SM


def run_all(start, radius, design, z0, vz0, P, V, vane_count, out, outcome, order: Optional[np.ndarray] = None,
            queue: bool = True, threads: Optional[int] = None) -> None:
    """`granule_run.run_all` on the GPU (no tracks): `out` and `outcome` filled in place, the
    granules taken in `order` (default `model.longest_first`) from a queue by `threads`
    (default `grid_threads()`, rounded up to whole blocks), or with `queue` False one per
    thread. None of these changes a result; the device check times them."""
    n = start.shape[0]
    if n == 0:
        return
    if order is None:
        order = longest_first(start, design, P)
    threads = n if not queue else min(n, max(1, grid_threads() if threads is None else threads))
    inputs = [cuda.to_device(np.ascontiguousarray(a)) for a in (order, np.zeros(1, dtype=np.int64))]
    inputs += [np.bool_(queue)]
    inputs += [cuda.to_device(np.ascontiguousarray(a)) for a in (start, radius, design, z0, vz0, P, V, vane_count)]
    device_out = cuda.device_array(out.shape, out.dtype)  # every granule writes all its columns: nothing to copy in
    device_outcome = cuda.device_array(outcome.shape, outcome.dtype)
    blocks = (threads + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    _run_queue[blocks, THREADS_PER_BLOCK](*inputs, device_out, device_outcome, cuda.to_device(np.empty((0, 3))))
    device_out.copy_to_host(out)
    device_outcome.copy_to_host(outcome)
