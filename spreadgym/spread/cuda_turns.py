"""The release-angle copies' turns on a CUDA GPU: one launch for a batch's designs, one thread a run.

The turns (von Mises angles in antithetic pairs, as cosines and sines) were most of the
finish's compiled time on the CPU: 32 768 draws a paper design, about 2 of its 2.4 ms
(docs/performance.md). Each replicate's turns come from its own PCG64 stream, drawn in a
fixed order, so a run's draws are sequential and runs are independent: thread r of the
launch draws run r with the CPU's own `von_mises.turn_run` (numba.cuda compiles it from
its Python source), into the design's block of the flat outputs. The rest of the finish
(the copies' landings, trays, CV) stays on the CPU threads (`finish_kernel.finish_designs`
with `drawn` set), which then needs the outputs on the host: 16 bytes a copy, 1 MiB a
paper design.

Under numba's CUDA simulator the turns are the CPU's to the bit
(tests/spread/test_cuda_turns.py). On a GPU, its cosine and logarithm (libdevice) may
differ from the CPU's in the last bit: the cosines and sines then differ by rounding,
and a rejection step whose test lands within rounding of its bound could go the other
way (its chance is of the order of the rounding itself, 1e-16 a draw). Imported only when
the device is "cuda" (spreadgym.device); compiled at the first launch and cached next to
this file.
"""

from __future__ import annotations

import numpy as np

from spreadgym.physics.compiled.cuda_target import cuda, host_array  # numba's CUDA target, loaded there
from spreadgym.spread.von_mises import turn_run

THREADS_PER_BLOCK = 64  # as the spinner's launch (measured there, not for the turns)


@cuda.jit(cache=True)
def _turn_runs(states, run_design, run_start, run_stop, first, copies, turn_first, kappa, envelope, cos_mu, sin_mu,
               turn_cos, turn_sin):
    """Thread r draws run r (its state states[r], its design run_design[r])."""
    r = cuda.grid(1)
    if r >= run_start.shape[0]:
        return
    d = run_design[r]
    a, b, t0, t1 = first[d], first[d + 1], turn_first[d], turn_first[d + 1]
    turn_run(host_array(states)[r], run_start[r], run_stop[r], host_array(kappa)[a:b], host_array(envelope)[a:b],
             host_array(cos_mu)[a:b], host_array(sin_mu)[a:b], copies[d], host_array(turn_cos)[t0:t1],
             host_array(turn_sin)[t0:t1])


def draw_turns(states: np.ndarray, run_design: np.ndarray, run_start: np.ndarray, run_stop: np.ndarray,
               first: np.ndarray, copies: np.ndarray, turn_first: np.ndarray, kappa: np.ndarray, cos_mu: np.ndarray,
               sin_mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The turns of every run given (one launch): run r draws columns run_start[r]..
    run_stop[r] - 1 of design run_design[r] (granule columns first[d]..first[d + 1] - 1 of
    `kappa`, `cos_mu`, `sin_mu`) from the PCG64 states[r], into rows 1.. of the design's
    (copies[d], granules) block of the flat cosines and sines returned (from turn_first[d];
    rows 0, and blocks of designs without runs here, are left unwritten)."""
    turn_cos, turn_sin = np.empty(int(turn_first[-1])), np.empty(int(turn_first[-1]))
    if run_start.size == 0:
        return turn_cos, turn_sin
    columns = [cuda.to_device(np.ascontiguousarray(a)) for a in (states, run_design, run_start, run_stop, first, copies,
                                                                  turn_first, kappa)]
    envelope = cuda.device_array(kappa.shape, np.float64)
    device_cos, device_sin = (cuda.device_array(turn_cos.shape, np.float64) for _ in range(2))
    blocks = (run_start.size + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    _turn_runs[blocks, THREADS_PER_BLOCK](*columns, envelope, cuda.to_device(np.ascontiguousarray(cos_mu)),
                                          cuda.to_device(np.ascontiguousarray(sin_mu)), device_cos, device_sin)
    device_cos.copy_to_host(turn_cos)
    device_sin.copy_to_host(turn_sin)
    return turn_cos, turn_sin
