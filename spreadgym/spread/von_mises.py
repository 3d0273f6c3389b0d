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

from spreadgym.physics.compiled import pcg64
from spreadgym.physics.compiled.options import INLINED, KERNEL

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


@KERNEL
def antithetic_turns(states, starts, stops, kappa, cos_mu, sin_mu, cos_out, sin_out):
    """Fill rows 1.. of `cos_out`, `sin_out` (K, N) with the cosines and sines of von
    Mises(mu_j, kappa_j) angles in antithetic pairs mu + phi, mu - phi, column j of run
    r (columns starts[r]..stops[r] - 1) drawn from the PCG64 states[r] (`pcg64.seeded`;
    stepped in place). Per run the phi are drawn pair by pair, column by column, as
    `rng.vonmises(0, broadcast_to(kappa, (K // 2, columns)))` draws them; rows 1..K//2
    take mu + phi, the remaining K - 1 - K//2 rows mu - phi of the first pairs. Row 0 is
    left alone. Every kappa must be <= LARGE_KAPPA (`fill_turns` sees to it)."""
    if kappa.size != cos_out.shape[1]:  # the columns are read unchecked below
        raise ValueError("antithetic_turns: kappa must have one entry per column of cos_out")
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
