"""Von Mises angles in antithetic pairs, drawn in compiled code as cosines and sines.

The release-angle copies (`spread.rotations`) need tens of thousands of von Mises
angles per run, each with its own mean and concentration, and then only the cosine and
sine of each. numpy's `Generator.vonmises` pays a broadcast per element and the
trigonometry after it is two more passes. This kernel runs numpy's algorithm (Best and
Fisher's wrapped-Cauchy rejection, with numpy's limits: a uniform angle below kappa =
1e-8, a normal one above 1e6) on the same generator, consuming the same uniforms in the
same order. The accepted W of the rejection step is cos(phi) itself, and sin(phi) =
+-sqrt(1 - W^2) with numpy's sign draw, so no arccos is taken; the mean is added by the
angle-sum formulas. With mean 0, sign(sin) * arccos(cos) is numpy's angle for the same
generator, to rounding (tested).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SMALL_KAPPA = 1e-8  # below: the angle is uniform on (-pi, pi) (numpy's limit)
LARGE_KAPPA = 1e6  # above: the angle is normal with variance 1/kappa (numpy's limit)
TAYLOR_KAPPA = 1e-5  # below: the envelope's s from its second-order expansion (numpy's)


@njit(cache=True, error_model="numpy", inline="always")
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


@njit(cache=True, error_model="numpy", inline="always")
def _draw(rng, k, s):
    """(cos phi, sin phi) of one angle phi ~ von Mises(0, k), drawn as numpy draws it;
    s = `_envelope(k)`, computed once per concentration."""
    if k < SMALL_KAPPA or k > LARGE_KAPPA:
        if k < SMALL_KAPPA:
            angle = math.pi * (2.0 * rng.random() - 1.0)
        else:
            angle = math.sqrt(1.0 / k) * rng.standard_normal()
        return math.cos(angle), math.sin(angle)
    while True:
        z = math.cos(math.pi * rng.random())
        w = (1.0 + s * z) / (s + z)
        y = k * (s - w)
        v = rng.random()
        if y * (2.0 - y) - v >= 0.0 or math.log(y / v) + 1.0 - y >= 0.0:
            break
    sine = math.sqrt(max(1.0 - w * w, 0.0))
    return w, (-sine if rng.random() < 0.5 else sine)


@njit(cache=True, error_model="numpy", nogil=True)
def antithetic_turns(rng, kappa, cos_mu, sin_mu, columns, cos_out, sin_out):
    """Fill rows 1.. of `cos_out`, `sin_out` (K, N) at `columns` with the cosines and
    sines of von Mises(mu_j, kappa_j) angles in antithetic pairs mu + phi, mu - phi.

    `kappa`, `cos_mu`, `sin_mu` are given per column listed (kappa >= 0). The phi are
    drawn pair by pair, column by column, as `rng.vonmises(0, broadcast_to(kappa,
    (K // 2, len(columns))))` draws them; rows 1..K//2 take mu + phi, the remaining
    K - 1 - K//2 rows mu - phi of the first pairs. Row 0 is left alone."""
    pairs = cos_out.shape[0] // 2
    minus = cos_out.shape[0] - 1 - pairs
    envelope = np.empty(columns.size)
    for j in range(columns.size):
        envelope[j] = _envelope(kappa[j])
    for i in range(pairs):
        for j in range(columns.size):
            c, s = _draw(rng, kappa[j], envelope[j])
            col = columns[j]
            cm, sm = cos_mu[j], sin_mu[j]
            cos_out[1 + i, col], sin_out[1 + i, col] = cm * c - sm * s, sm * c + cm * s
            if i < minus:
                cos_out[1 + pairs + i, col], sin_out[1 + pairs + i, col] = cm * c + sm * s, sm * c - cm * s
