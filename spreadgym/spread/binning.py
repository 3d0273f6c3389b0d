"""Granules into trays, compiled: the pooled tray row and each replicate's row in one pass.

`pattern.collect_indexed` and `estimate.replicate_tray_masses` bin every landing point
(tens of thousands per run with release-angle copies). In numpy that is a floor, a
cast, a maximum and two weighted bincounts, each holding the GIL; here it is one kernel
that releases it (spreadgym.spread.batch finishes scenes side by side on threads). The
sums run in the granules' order, as bincount's do, so the masses are bincount's to the bit.
"""

from __future__ import annotations

import math

import numpy as np

from spreadgym.physics.compiled.options import KERNEL

OK, BAD_POSITION, BAD_MASS, TOO_WIDE, BAD_REPLICATE = range(5)
"""What `bin_landings` found: binned, a landing point not finite, a mass not finite or
negative, a row wider than `max_trays`, a replicate index outside 0..replicates-1."""


@KERNEL
def bin_landings(x, mass, replicate, replicates, width, min_half_trays, max_trays):
    """Catch granules landing at x (m across the track) with masses `mass` (kg) in
    replicates `replicate` (0..replicates-1) by trays of `width` (m): tray i covers
    [i w - w/2, i w + w/2), the row runs i = -m..m with m the largest |i| reached and
    at least `min_half_trays`.

    Returns (status, m, pooled (2m+1,), per replicate (replicates, 2m+1), each granule's
    tray 0..2m from the row's left end); anything but status OK returns empty arrays."""
    n = x.size
    index = np.empty(n, dtype=np.int64)
    m = min_half_trays
    for i in range(n):
        if not math.isfinite(x[i]):
            return BAD_POSITION, 0, np.zeros(0), np.zeros((0, 0)), index[:0]
    for i in range(n):
        if not (math.isfinite(mass[i]) and mass[i] >= 0.0):
            return BAD_MASS, 0, np.zeros(0), np.zeros((0, 0)), index[:0]
    for i in range(n):
        scaled = np.floor(x[i] / width + 0.5)  # a float (math.floor gives an int, which overflows)
        if abs(scaled) > max_trays:  # beyond any row allowed (and beyond an int64 for huge x)
            return TOO_WIDE, 0, np.zeros(0), np.zeros((0, 0)), index[:0]
        index[i] = int(scaled)
        m = max(m, abs(index[i]))
        if replicate[i] < 0 or replicate[i] >= replicates:
            return BAD_REPLICATE, 0, np.zeros(0), np.zeros((0, 0)), index[:0]
    count = 2 * m + 1
    if count > max_trays:
        return TOO_WIDE, m, np.zeros(0), np.zeros((0, 0)), index[:0]
    pooled = np.zeros(count)
    per_replicate = np.zeros((replicates, count))
    for i in range(n):
        tray = index[i] + m
        index[i] = tray
        pooled[tray] += mass[i]
        per_replicate[replicate[i], tray] += mass[i]
    return OK, m, pooled, per_replicate, index
