"""Von Mises angles in antithetic pairs, drawn in compiled code as cosines and sines.

The release-angle copies (`spread.rotations`) need tens of thousands of von Mises
angles per run, each with its own mean and concentration, and then only the cosine and
sine of each. numpy's `Generator.vonmises` pays a broadcast per element and the
trigonometry after it is two more passes. This kernel runs numpy's algorithm (Best and
Fisher's wrapped-Cauchy rejection, with numpy's limits: a uniform angle below kappa =
1e-8, a normal one above 1e6) on the same stream: it steps numpy's PCG64 itself from
the generator's state (spreadgym.physics.compiled.pcg64), consuming its uniforms in the
same order. The accepted W of the rejection step is cos(phi) itself, and sin(phi) =
+-sqrt(1 - W^2) with numpy's sign draw, so no arccos is taken; the mean is added by the
angle-sum formulas. With mean 0, sign(sin) * arccos(cos) is numpy's angle for the same
generator, to rounding (tested).

The kernel takes the generators' states as plain integers instead of generator objects,
so it is called once per run for all its replicates and releases the GIL for all of it
(a batch finishes runs side by side on threads). Above kappa = 1e6 numpy draws a normal
(its ziggurat), which the kernel does not reproduce: a replicate with such a granule (a
feed spot under about 0.1 mm) is drawn by numpy's `vonmises` itself, its cosines and
sines then taken in numpy.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import prange

from spreadgym.physics.compiled import pcg64
from spreadgym.physics.compiled.options import INLINED, KERNEL, PARALLEL

SMALL_KAPPA = 1e-8  # below: the angle is uniform on (-pi, pi) (numpy's limit)
LARGE_KAPPA = 1e6  # above: the angle is normal with variance 1/kappa (numpy's limit)
TAYLOR_KAPPA = 1e-5  # below: the envelope's s from its second-order expansion (numpy's)


@INLINED
def _envelope(k):
    """The wrapped-Cauchy envelope's s for concentration k, as numpy computes it (NaN
    where k is outside (SMALL_KAPPA, LARGE_KAPPA): `_draw` does not use it there)."""
    if k < SMALL_KAPPA or k > LARGE_KAPPA:
        return math.nan
    if k < TAYLOR_KAPPA:
        return 1.0 / k + k
    r = 1.0 + math.sqrt(1.0 + 4.0 * k * k)
    rho = (r - math.sqrt(2.0 * r)) / (2.0 * k)
    return (1.0 + rho * rho) / (2.0 * rho)


@INLINED
def _draw(state, k, s):
    """(cos phi, sin phi) of one angle phi ~ von Mises(0, k) drawn from the PCG64 `state`
    as numpy draws it (k <= LARGE_KAPPA); s = `_envelope(k)`, computed once per concentration."""
    if k < SMALL_KAPPA:
        angle = math.pi * (2.0 * pcg64.next_double(state) - 1.0)
        return math.cos(angle), math.sin(angle)
    while True:
        z = math.cos(math.pi * pcg64.next_double(state))
        w = (1.0 + s * z) / (s + z)
        y = k * (s - w)
        v = pcg64.next_double(state)
        if y * (2.0 - y) - v >= 0.0 or math.log(y / v) + 1.0 - y >= 0.0:
            break
    sine = math.sqrt(max(1.0 - w * w, 0.0))
    return w, (-sine if pcg64.next_double(state) < 0.5 else sine)


@INLINED
def turn_run(state, start, stop, kappa, envelope, cos_mu, sin_mu, copies, cos_out, sin_out):
    """Rows 1..copies - 1 of columns start..stop - 1 of one design's turns: von Mises(mu_j,
    kappa_j) angles in antithetic pairs mu + phi, mu - phi, drawn from the PCG64 `state`
    (stepped in place) pair by pair, column by column, as `rng.vonmises(0,
    broadcast_to(kappa, (copies // 2, columns)))` draws them; rows 1..copies // 2 take
    mu + phi, the rest mu - phi of the first pairs. `kappa`, `envelope` (filled here for
    these columns), `cos_mu`, `sin_mu` hold the design's N columns, `cos_out`, `sin_out` its
    (copies, N) rows flat (copy-major). Row 0 is left alone; every kappa <= LARGE_KAPPA. The
    CPU's `antithetic_turns`, the plain finish's kernel and `batch_run` (the GPU's) draw with it."""
    n = kappa.size
    pairs = copies // 2
    minus = copies - 1 - pairs
    for j in range(start, stop):
        envelope[j] = _envelope(kappa[j])
    for i in range(pairs):
        for j in range(start, stop):
            c, s = _draw(state, kappa[j], envelope[j])
            cm, sm = cos_mu[j], sin_mu[j]
            plus = (1 + i) * n + j
            cos_out[plus], sin_out[plus] = cm * c - sm * s, sm * c + cm * s
            if i < minus:
                back = (1 + pairs + i) * n + j
                cos_out[back], sin_out[back] = cm * c + sm * s, sm * c - cm * s


@KERNEL
def antithetic_turns(states, starts, stops, kappa, cos_mu, sin_mu, cos_out, sin_out):
    """Fill rows 1.. of `cos_out`, `sin_out` (K, N; C-contiguous) with the cosines and sines
    of the turns of N granules (`turn_run`), run r (columns starts[r]..stops[r] - 1) drawn
    from the PCG64 states[r] (`pcg64.seeded`; stepped in place). Row 0 is left alone."""
    copies, n = cos_out.shape
    if kappa.size != n:  # turn_run's rows are kappa.size long
        raise ValueError("antithetic_turns: kappa must have one entry per column of cos_out")
    envelope = np.empty(n)
    flat_cos, flat_sin = cos_out.reshape(copies * n), sin_out.reshape(copies * n)
    for r in range(starts.size):
        turn_run(states[r], starts[r], stops[r], kappa, envelope, cos_mu, sin_mu, copies, flat_cos, flat_sin)


@INLINED
def batch_run(r, state, run_design, run_start, run_stop, first, copies, turn_first, kappa, envelope, cos_mu, sin_mu,
              turn_cos, turn_sin):
    """Run r of a batch's turns, drawn before the finish (`flat_turns`, `cuda_turns`): columns
    run_start[r]..run_stop[r] - 1 of design d = run_design[r] (granule columns first[d]..
    first[d + 1] - 1 of `kappa`, `cos_mu`, `sin_mu`, and of the `envelope` scratch) from the
    PCG64 `state` (stepped in place), into rows 1.. of the design's (copies[d], granules)
    block of the flat `turn_cos`, `turn_sin` (from turn_first[d]): `turn_run`."""
    d = run_design[r]
    a, b, t0, t1 = first[d], first[d + 1], turn_first[d], turn_first[d + 1]
    turn_run(state, run_start[r], run_stop[r], kappa[a:b], envelope[a:b], cos_mu[a:b], sin_mu[a:b], copies[d],
             turn_cos[t0:t1], turn_sin[t0:t1])


@PARALLEL
def _flat_turns(states, run_design, run_start, run_stop, first, copies, turn_first, kappa, cos_mu, sin_mu, turn_cos,
                turn_sin):
    envelope = np.empty(kappa.size)
    for r in prange(run_start.size):
        batch_run(r, states[r].copy(), run_design, run_start, run_stop, first, copies, turn_first, kappa, envelope,
                  cos_mu, sin_mu, turn_cos, turn_sin)


def flat_turns(states: np.ndarray, run_design: np.ndarray, run_start: np.ndarray, run_stop: np.ndarray,
               first: np.ndarray, copies: np.ndarray, turn_first: np.ndarray, kappa: np.ndarray, cos_mu: np.ndarray,
               sin_mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`cuda_turns.draw_turns` on the CPU, runs side by side on numba's threads (callers hold
    `threads.numba_threads()`): the same arguments, layout and bits, each run from a copy of
    its state (the given states are left as they are); rows 0, and blocks of designs
    without runs, left unwritten. The GPU's reference (the device check, the tests); the
    plain finish draws on the CPU inside its own kernel instead."""
    turn_cos, turn_sin = np.empty(int(turn_first[-1])), np.empty(int(turn_first[-1]))
    _flat_turns(states, run_design, run_start, run_stop, first, copies, turn_first, kappa, cos_mu, sin_mu, turn_cos,
                turn_sin)
    return turn_cos, turn_sin


def fill_turns(seeds: Sequence[Sequence[int]], starts: np.ndarray, stops: np.ndarray, kappa: np.ndarray,
               cos_mu: np.ndarray, sin_mu: np.ndarray, cos_out: np.ndarray, sin_out: np.ndarray) -> None:
    """`antithetic_turns` with run r's angles drawn from `np.random.default_rng(seeds[r])`:
    one kernel call for every run whose concentrations it covers; a run with a
    concentration above LARGE_KAPPA by numpy's own `vonmises`."""
    starts, stops = np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64)
    pairs = cos_out.shape[0] // 2
    numpys = np.zeros(starts.size, dtype=bool)  # the runs numpy draws itself
    big = kappa > LARGE_KAPPA
    if big.any():  # rare: a feed spot under about 0.1 mm
        numpys[:] = [big[a:b].any() for a, b in zip(starts, stops)]
    kernel = np.flatnonzero(~numpys)
    if kernel.size:
        antithetic_turns(pcg64.seeded([seeds[r] for r in kernel]), starts[kernel], stops[kernel], kappa, cos_mu,
                         sin_mu, cos_out, sin_out)
    minus = cos_out.shape[0] - 1 - pairs
    for r in np.flatnonzero(numpys):
        a, b = starts[r], stops[r]
        phi = np.random.default_rng(seeds[r]).vonmises(0.0, np.broadcast_to(kappa[a:b], (pairs, b - a)))
        turned = np.concatenate([phi, -phi[:minus]])
        cos_out[1:, a:b] = np.cos(turned) * cos_mu[a:b] - np.sin(turned) * sin_mu[a:b]
        sin_out[1:, a:b] = np.sin(turned) * cos_mu[a:b] + np.cos(turned) * sin_mu[a:b]
