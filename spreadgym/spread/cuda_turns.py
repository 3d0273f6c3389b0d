"""The release-angle copies' turns on a CUDA GPU: one launch for a batch's designs, one thread a run.

The turns (von Mises angles in antithetic pairs, as cosines and sines) were most of the
finish's compiled time on the CPU: 32 768 draws a paper design, 1.84 of the finish
kernel's 2.64 ms at one thread (docs/performance.md). Each replicate's turns come from
its own PCG64 stream, drawn in a fixed order, so a run's draws are sequential and runs
are independent: thread r of the
launch draws run r with the CPU's own `von_mises.batch_run` (numba.cuda compiles it from
its Python source), into the design's block of the flat outputs; `von_mises.flat_turns`
is the same call on the CPU. The rest of the finish
(the copies' landings, trays, CV) stays on the CPU threads (`finish_kernel.finish_designs`
with `drawn` set), which then needs the outputs on the host: 16 bytes a copy, 1 MiB a
paper design.

Under numba's CUDA simulator the turns are the CPU's to the bit
(tests/spread/test_cuda_turns.py). On a GPU the compiler fuses multiply-adds (as in the
envelope's W and the angle sums) and the cosine and logarithm are libdevice's, so most
cosines and sines differ from the CPU's by rounding; and where a rejection test lands
within rounding of its bound (a chance of the order of 1e-16 a draw) it can go the other
way, which changes the uniforms the run consumes and so the rest of that replicate's
turns (a statistically equal draw, not the CPU's). Imported only when the device is
"cuda" (spreadgym.device); compiled at the first launch and cached next to this file.
"""

from __future__ import annotations

import numpy as np
from numba import uint64

from spreadgym.physics.compiled import pcg64
from spreadgym.physics.compiled.cuda_target import cuda, host_array  # numba's CUDA target, loaded there
from spreadgym.spread.von_mises import batch_run

THREADS_PER_BLOCK = 64  # as the spinner's launch (measured there, not for the turns)
STATE_WORDS = pcg64.STATE_WORDS  # a module constant: numba.cuda sizes local arrays from constants only


@cuda.jit(cache=True)
def _turn_runs(states, run_design, run_start, run_stop, first, copies, turn_first, kappa, envelope, cos_mu, sin_mu,
               turn_cos, turn_sin):
    """Thread r draws run r (`von_mises.batch_run`) from its state states[r], copied to the
    thread's local memory, where each draw steps it."""
    r = cuda.grid(1)
    if r >= run_start.shape[0]:
        return
    state = cuda.local.array(STATE_WORDS, uint64)
    for w in range(STATE_WORDS):
        state[w] = states[r, w]
    batch_run(r, state, host_array(run_design), host_array(run_start), host_array(run_stop), host_array(first),
              host_array(copies), host_array(turn_first), host_array(kappa), host_array(envelope), host_array(cos_mu),
              host_array(sin_mu), host_array(turn_cos), host_array(turn_sin))


def draw_turns(states: np.ndarray, run_design: np.ndarray, run_start: np.ndarray, run_stop: np.ndarray,
               first: np.ndarray, copies: np.ndarray, turn_first: np.ndarray, kappa: np.ndarray, cos_mu: np.ndarray,
               sin_mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The turns of every run given (one launch): run r draws columns run_start[r]..
    run_stop[r] - 1 of design run_design[r] (granule columns first[d]..first[d + 1] - 1 of
    `kappa`, `cos_mu`, `sin_mu`) from the PCG64 states[r] (the host's left as they are),
    into rows 1.. of the design's (copies[d], granules) block of the flat cosines and sines
    returned (from turn_first[d]; rows 0, and blocks of designs without runs here, are left
    unwritten)."""
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
