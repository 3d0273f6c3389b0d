"""The compiled spinner on a CUDA GPU: one thread per granule, one launch per batch.

The kernel calls the CPU kernel's own scalar code, `granule_run.follow` and everything
it calls: numba.cuda compiles a CPU-jitted function that a GPU kernel calls for the GPU
from its Python source, so the physics is defined once and a change to it reaches both
devices. The only GPU-specific part is here: the thread index over the flat
(design x granule) index of `granule_run.run_all` and the granule's scratch array in the
thread's local memory. Results equal the CPU's up to floating-point contraction (the GPU
compiler fuses multiply-adds); under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1)
the kernel runs the CPU code itself and the results are the CPU's bits.

Imported only when the device is "cuda" (spreadgym.device); numba's CUDA target then
compiles the kernel at the first launch and caches it next to this file. On an H200
(numba-cuda 0.30.4, sm_90) it compiled in 39 s and matched the CPU on 155 648 granules of
72 designs: the same outcomes, departures within 6e-12 m/s, the same tray masses to the
bit (docs/performance.md, the CUDA backend).
"""

from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):  # numba-cuda 0.30 registers np.row_stack (an alias of vstack, gone in numpy 2.5)
    np.row_stack = np.vstack  # as it loads its target: without it no kernel compiles (seen on numpy 2.5.2)

from numba import config, cuda, float64  # noqa: E402 (after the alias above)

from spreadgym.physics.compiled import face_motion, granule_run

SCRATCH = (2, face_motion.EVENTS)  # a module constant: numba.cuda sizes local arrays from constants only
THREADS_PER_BLOCK = 64
"""Granules per block: 32 to 256 ran within 10 % of each other on an H200 (docs/performance.md)."""


if config.ENABLE_CUDASIM:
    def _array(view):
        """The simulator runs kernels as Python and hands them wrapped arrays; the CPU
        functions the kernel calls take numpy's (the wrapped one's memory)."""
        return view._item._ary
else:
    @cuda.jit(device=True, inline=True)
    def _array(view):
        return view


@cuda.jit(cache=True)  # the GPU compile takes minutes (200 s for sm_90 on the two-core machine): once per install
def _run_all(start, radius, design, z0, vz0, P, V, vane_count, out, outcome, no_track):
    i = cuda.grid(1)
    if i < start.shape[0]:
        d = design[i]
        work = cuda.local.array(SCRATCH, float64)
        outcome[i] = granule_run.follow(start[i, 0], start[i, 1], radius[i], z0[d], vz0[d], _array(P[d]),
                                        _array(V[d, :vane_count[d]]), _array(out[i]), _array(no_track), work)


def run_all(start, radius, design, z0, vz0, P, V, vane_count, out, outcome) -> None:
    """`granule_run.run_all` on the GPU (no tracks): inputs copied over, `out` and
    `outcome` filled in place."""
    n = start.shape[0]
    if n == 0:
        return
    inputs = [cuda.to_device(np.ascontiguousarray(a)) for a in (start, radius, design, z0, vz0, P, V, vane_count)]
    device_out, device_outcome = cuda.to_device(out), cuda.to_device(outcome)
    blocks = (n + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    _run_all[blocks, THREADS_PER_BLOCK](*inputs, device_out, device_outcome, cuda.to_device(np.empty((0, 3))))
    device_out.copy_to_host(out)
    device_outcome.copy_to_host(outcome)
