"""The compiled flight on a CUDA GPU: `fly_all` as one launch, LANES granules a thread.

Each GPU thread flies granules LANES k .. LANES (k + 1) - 1 with the CPU's own
`flight_kernel.fly_range` (numba.cuda compiles it from its Python source), its lanes'
work arrays in the thread's local memory; so the arithmetic of a granule is the CPU's,
and only the order in which granules reach lanes differs, which no granule's landing
depends on. The GPU compiler fuses multiply-adds where the CPU rounds twice, so landing
points may differ from the CPU's in the last bits; under numba's CUDA simulator they are
the CPU's to the bit (tests/spread/test_cuda_flight.py). Imported only when the device
is "cuda" (spreadgym.device); compiled at the first launch and cached next to this file.
"""

from __future__ import annotations

import numpy as np
from numba import float64, int64

from spreadgym.physics.compiled.cuda_target import cuda, host_array  # numba's CUDA target, loaded there
from spreadgym.spread.flight_kernel import (
    LANES,
    WORK_INTS,
    WORK_LANES,
    WORK_LIFTS,
    WORK_STAGES,
    WORK_VECTORS,
    fly_range,
)

THREADS_PER_BLOCK = 64  # as the spinner's launch (measured there, not for the flight)


@cuda.jit(cache=True)
def _fly_lanes(position, height, velocity, par, table, lift, wind_x, wind_y, g, dt, atol, rtol, out_xy, out_t,
               failed):
    """Thread k flies granules LANES k .. LANES (k + 1) - 1 (those that exist), adding its
    granules that failed to land to failed[0]."""
    first = cuda.grid(1) * LANES
    n = position.shape[0]
    if first >= n:
        return
    vectors = cuda.local.array(WORK_VECTORS, float64)
    stages = cuda.local.array(WORK_STAGES, float64)
    lanes = cuda.local.array(WORK_LANES, float64)
    lf = cuda.local.array(WORK_LIFTS, float64)
    ints = cuda.local.array(WORK_INTS, int64)
    lost = fly_range(first, min(first + LANES, n), host_array(position), host_array(height), host_array(velocity),
                     host_array(par), host_array(table), lift, wind_x, wind_y, g, dt, atol, rtol, host_array(out_xy),
                     host_array(out_t), vectors, stages, lanes, lf, ints)
    if lost:
        cuda.atomic.add(failed, 0, lost)


def fly_all(position, height, velocity, par, table, lift, wind_x, wind_y, g, dt, atol, rtol, out_xy, out_t) -> int:
    """`flight_kernel.fly_all` on the GPU: the same arguments, out_xy and out_t filled in
    place (every granule writes its row), the count of granules that failed to land returned."""
    n = position.shape[0]
    if n == 0:
        return 0
    inputs = [cuda.to_device(np.ascontiguousarray(a)) for a in (position, height, velocity, par, table)]
    device_xy = cuda.device_array(out_xy.shape, out_xy.dtype)
    device_t = cuda.device_array(out_t.shape, out_t.dtype)
    failed = cuda.to_device(np.zeros(1, dtype=np.int64))
    threads = (n + LANES - 1) // LANES
    blocks = (threads + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    _fly_lanes[blocks, THREADS_PER_BLOCK](*inputs, bool(lift), float(wind_x), float(wind_y), float(g), float(dt),
                                          float(atol), float(rtol), device_xy, device_t, failed)
    device_xy.copy_to_host(out_xy)
    device_t.copy_to_host(out_t)
    return int(failed.copy_to_host()[0])
