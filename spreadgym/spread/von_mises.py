"""Von Mises angles in antithetic pairs, drawn in compiled code as cosines and sines.

The release-angle copies (`spread.rotations`) need tens of thousands of von Mises
angles per run, each with its own mean and concentration, and then only the cosine and
sine of each. numpy's `Generator.vonmises` pays a broadcast per element and the
trigonometry after it is two more passes. This kernel runs numpy's algorithm (Best and
Fisher's wrapped-Cauchy rejection, with numpy's limits: a uniform angle below kappa =
1e-8, a normal one above 1e6) on the same stream: it steps numpy's PCG64 itself from
the generator's state (`pcg64_next`, the 128-bit LCG with XSL-RR output, the same 64-bit
outputs as `bit_generator.random_raw`) and makes each uniform from one output as numpy
does, (u >> 11) / 2^53, consuming them in the same order. The accepted W of
the rejection step is cos(phi) itself, and sin(phi) = +-sqrt(1 - W^2) with numpy's sign
draw, so no arccos is taken; the mean is added by the angle-sum formulas. With mean 0,
sign(sin) * arccos(cos) is numpy's angle for the same generator, to rounding (tested).

A kernel that takes the generators' states as plain integers instead of generator
objects is called once per run for all its replicates and releases the GIL for all of
it (a batch finishes runs side by side on threads). Above kappa = 1e6 numpy draws a normal (its ziggurat), which this
kernel does not reproduce: such a replicate (a feed spot under 0.1 mm) is drawn by
numpy's `vonmises` itself, its cosines and sines then taken in numpy.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit

from spreadgym.physics.compiled.layout import KERNEL

SMALL_KAPPA = 1e-8  # below: the angle is uniform on (-pi, pi) (numpy's limit)
LARGE_KAPPA = 1e6  # above: the angle is normal with variance 1/kappa (numpy's limit)
TAYLOR_KAPPA = 1e-5  # below: the envelope's s from its second-order expansion (numpy's)
INLINE = njit(cache=True, error_model="numpy", inline="always")  # the kernel's scalar helpers
MASK64 = (1 << 64) - 1
PCG_MULTIPLIER_HIGH = np.uint64(0x2360ED051FC65DA4)  # PCG64's 128-bit LCG multiplier (numpy's, O'Neill's)
PCG_MULTIPLIER_LOW = np.uint64(0x4385DF649FCCF645)


def pcg64_states(seeds: Sequence[Sequence[int]]) -> np.ndarray:
    """(R, 4) uint64: (state high, state low, increment high, increment low) of
    `np.random.default_rng(seed).bit_generator` for each seed (a fresh PCG64)."""
    states = np.empty((len(seeds), 4), dtype=np.uint64)
    for r, seed in enumerate(seeds):
        bits = np.random.default_rng(seed).bit_generator.state["state"]
        state, inc = bits["state"], bits["inc"]
        states[r] = (state >> 64, state & MASK64, inc >> 64, inc & MASK64)
    return states


@INLINE
def _mul_high(a, b):
    """The high 64 bits of the 128-bit product of the uint64s a and b."""
    mask = np.uint64(0xFFFFFFFF)
    a_lo, a_hi, b_lo, b_hi = a & mask, a >> np.uint64(32), b & mask, b >> np.uint64(32)
    lo_lo, hi_lo, lo_hi = a_lo * b_lo, a_hi * b_lo, a_lo * b_hi
    middle = (lo_lo >> np.uint64(32)) + (hi_lo & mask) + lo_hi
    return a_hi * b_hi + (hi_lo >> np.uint64(32)) + (middle >> np.uint64(32))


@INLINE
def pcg64_next(state):
    """Step the PCG64 `state` (uint64 (4,): state high, low, increment high, low) in place
    and return its next 64-bit output, as numpy's PCG64 gives it: s = s M + inc mod 2^128,
    output rotr64(high(s) ^ low(s), s >> 122)."""
    m_hi, m_lo = PCG_MULTIPLIER_HIGH, PCG_MULTIPLIER_LOW
    hi, lo = state[0], state[1]
    new_lo = lo * m_lo
    new_hi = _mul_high(lo, m_lo) + lo * m_hi + hi * m_lo
    lo = new_lo + state[3]
    hi = new_hi + state[2] + (np.uint64(1) if lo < new_lo else np.uint64(0))
    state[0], state[1] = hi, lo
    value, rot = hi ^ lo, hi >> np.uint64(58)
    return (value >> rot) | (value << ((np.uint64(64) - rot) & np.uint64(63)))


@INLINE
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


@INLINE
def _uniform(state):
    """numpy's `random()` from the PCG64 `state`: the next output's top 53 bits over 2^53."""
    return float(pcg64_next(state) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@INLINE
def _draw(state, k, s):
    """(cos phi, sin phi) of one angle phi ~ von Mises(0, k) drawn from the PCG64 `state`
    as numpy draws it (k <= LARGE_KAPPA); s = `_envelope(k)`, computed once per concentration."""
    if k < SMALL_KAPPA:
        angle = math.pi * (2.0 * _uniform(state) - 1.0)
        return math.cos(angle), math.sin(angle)
    while True:
        z = math.cos(math.pi * _uniform(state))
        w = (1.0 + s * z) / (s + z)
        y = k * (s - w)
        v = _uniform(state)
        if y * (2.0 - y) - v >= 0.0 or math.log(y / v) + 1.0 - y >= 0.0:
            break
    sine = math.sqrt(max(1.0 - w * w, 0.0))
    return w, (-sine if _uniform(state) < 0.5 else sine)


@KERNEL
def antithetic_turns(states, starts, stops, kappa, cos_mu, sin_mu, cos_out, sin_out):
    """Fill rows 1.. of `cos_out`, `sin_out` (K, N) with the cosines and sines of von
    Mises(mu_j, kappa_j) angles in antithetic pairs mu + phi, mu - phi, column j of run
    r (columns starts[r]..stops[r] - 1) drawn from the PCG64 states[r] (`pcg64_states`;
    stepped in place). Per run the phi are drawn pair by pair, column by column, as
    `rng.vonmises(0, broadcast_to(kappa, (K // 2, columns)))` draws them; rows 1..K//2
    take mu + phi, the remaining K - 1 - K//2 rows mu - phi of the first pairs. Row 0 is
    left alone. Every kappa must be <= LARGE_KAPPA (`fill_turns` sees to it)."""
    pairs = cos_out.shape[0] // 2
    minus = cos_out.shape[0] - 1 - pairs
    for r in range(starts.size):
        start, stop = starts[r], stops[r]
        envelope = np.empty(stop - start)
        for j in range(start, stop):
            envelope[j - start] = _envelope(kappa[j])
        for i in range(pairs):
            for j in range(start, stop):
                c, s = _draw(states[r], kappa[j], envelope[j - start])
                cm, sm = cos_mu[j], sin_mu[j]
                cos_out[1 + i, j], sin_out[1 + i, j] = cm * c - sm * s, sm * c + cm * s
                if i < minus:
                    cos_out[1 + pairs + i, j], sin_out[1 + pairs + i, j] = cm * c + sm * s, sm * c - cm * s


def fill_turns(seeds: Sequence[Sequence[int]], starts: np.ndarray, stops: np.ndarray, kappa: np.ndarray,
               cos_mu: np.ndarray, sin_mu: np.ndarray, cos_out: np.ndarray, sin_out: np.ndarray) -> None:
    """`antithetic_turns` with run r's angles drawn from `np.random.default_rng(seeds[r])`:
    one kernel call for every run whose concentrations it covers; a run with a
    concentration above LARGE_KAPPA by numpy's own `vonmises`."""
    starts, stops = np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64)
    pairs = cos_out.shape[0] // 2
    numpys = np.array([bool(np.any(kappa[a:b] > LARGE_KAPPA)) for a, b in zip(starts, stops)], dtype=bool)
    kernel = np.flatnonzero(~numpys)
    if kernel.size:
        antithetic_turns(pcg64_states([seeds[r] for r in kernel]), starts[kernel], stops[kernel], kappa, cos_mu,
                         sin_mu, cos_out, sin_out)
    minus = cos_out.shape[0] - 1 - pairs
    for r in np.flatnonzero(numpys):
        a, b = starts[r], stops[r]
        phi = np.random.default_rng(seeds[r]).vonmises(0.0, np.broadcast_to(kappa[a:b], (pairs, b - a)))
        turned = np.concatenate([phi, -phi[:minus]])
        cos_out[1:, a:b] = np.cos(turned) * cos_mu[a:b] - np.sin(turned) * sin_mu[a:b]
        sin_out[1:, a:b] = np.sin(turned) * cos_mu[a:b] + np.cos(turned) * sin_mu[a:b]
