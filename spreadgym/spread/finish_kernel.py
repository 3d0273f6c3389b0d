"""The finish of many plain designs in one compiled call: release-angle turns, copies,
trays and the CV estimate of every design, designs side by side on numba's threads.

`finish_designs` runs, for each design, the kernels `pipeline.finish_scene` calls one
by one with numpy and Python between them: `von_mises.antithetic_turns` (the copies'
turns), `rotations.turned_copies` (where each copy lands across the track),
`binning.bin_landings` (the trays), `estimate.bout_cvs` (the CV at the target and the
CV curve) and `departure.means_of` (the departure summary), with the glue between them in
the same arithmetic, so every figure is the same bits (spreadgym.spread.plain_finish
holds the rest and the tests).

The outputs are flat arrays, each design's part at offsets the caller gives: the copies'
sample (`sample_first`), the trays (`tray_first`: room for `tray_room` trays, at least
the row the design fills), the curve (`curve_first`, as much room).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from spreadgym.physics.compiled.options import PARALLEL
from spreadgym.physics.departure import means_of
from spreadgym.spread.binning import OK, bin_landings
from spreadgym.spread.estimate import bout_cvs
from spreadgym.spread.pattern import bout_columns, fold_pair_arrays
from spreadgym.spread.rotations import turned_copies
from spreadgym.spread.von_mises import antithetic_turns

NO_ROOM = 100
"""A status beyond binning's: the design's row needed more trays than the caller made room for."""


@PARALLEL
def finish_designs(skip, first, copies, run_first, run_start, run_stop, states, kappa, cos_mu, sin_mu, held, departed,
                   flown_first, landing, mass, replicate, replicates, sample_first, out_x, out_mass, out_replicate,
                   width, min_half_trays, max_trays, tray_first, tray_room, masses_first, out_pooled,
                   out_per_replicate, target_trays, racetrack, out_status, out_half_trays, out_target, out_curve,
                   position, velocity, spin, time, sign, out_means):
    """Design d's granules are first[d]..first[d + 1] - 1 of the granule columns (`kappa`,
    `cos_mu`, `sin_mu`, `held`: `rotations.TurnLaws`; `departed`, `mass`, `replicate`);
    its departed ones landed at `landing` rows flown_first[d].. (disc frame, m); its
    replicates' PCG64 states are rows run_first[d].. of `states` (each covering granules
    run_start..run_stop - 1 of the design). Fills the design's copies' sample (x across the
    track, mass, replicate), its pooled trays (from tray_first[d]) and (replicates, T) tray
    masses (from masses_first[d]), T = 2 m + 1 (m in out_half_trays, the binning status in
    out_status), its (raw, corrected, s.e.,
    usable) at the target's bout of target_trays[d] trays (out_target[d]) and at every
    curve width of 1..2 r + 1 trays, r the reach of the loaded trays (out_curve rows from
    tray_first[d]; none where nothing landed); and `Departure.means` of its departures
    (`position`, `velocity`, `spin`, `time` granule columns; `sign` the sense of its
    rotation) in out_means[d] (the count as a float). A design with skip[d] set is left
    alone (its outputs unwritten): one whose turns the kernel does not draw (a concentration
    above von_mises.LARGE_KAPPA, where numpy draws a normal angle)."""
    for d in prange(first.size - 1):
        if skip[d]:
            continue
        a, n, k = first[d], first[d + 1] - first[d], copies[d]
        count, speed, speed_sd, spin_mean, angle, time_mean = means_of(
            position[a:a + n], velocity[a:a + n], spin[a:a + n], time[a:a + n], departed[a:a + n], sign[d])
        out_means[d, 0], out_means[d, 1], out_means[d, 2] = count, speed, speed_sd
        out_means[d, 3], out_means[d, 4], out_means[d, 5] = spin_mean, angle, time_mean
        cos = np.empty(k * n)
        sin = np.empty(k * n)
        cos_rows, sin_rows = cos.reshape((k, n)), sin.reshape((k, n))
        cos_rows[0] = 1.0  # copy 0 is the granule itself
        sin_rows[0] = 0.0
        r0, r1 = run_first[d], run_first[d + 1]
        antithetic_turns(states[r0:r1], run_start[r0:r1], run_stop[r0:r1], kappa[a:a + n], cos_mu[a:a + n],
                         sin_mu[a:a + n], cos_rows, sin_rows)
        landed_x, landed_y = np.full(n, np.nan), np.full(n, np.nan)
        every = True
        f = flown_first[d]
        for j in range(n):
            if held[a + j]:  # pulled back by the clip: every copy keeps the granule's angle
                cos_rows[:, j] = 1.0
                sin_rows[:, j] = 0.0
            if departed[a + j]:
                landed_x[j], landed_y[j] = landing[f, 0], landing[f, 1]
                f += 1
            else:
                every = False
        s0, s1 = sample_first[d], sample_first[d + 1]
        rows = np.empty(0 if every else s1 - s0, dtype=np.int64)  # copy-major k N + j of the departed copies
        if not every:
            i = 0
            for c in range(k):
                for j in range(n):
                    if departed[a + j]:
                        rows[i] = c * n + j
                        i += 1
        x = out_x[s0:s1]
        turned_copies(every, rows, cos, sin, landed_x, landed_y, mass[a:a + n], replicate[a:a + n], k, x,
                      out_mass[s0:s1], out_replicate[s0:s1])
        for i in range(x.size):
            x[i] = x[i] + 0.0  # the disc's axis (at 0) added, as the pipeline adds it (-0.0 becomes 0.0)
        status, m, pooled, per_replicate, _ = bin_landings(x, out_mass[s0:s1], out_replicate[s0:s1], replicates[d],
                                                           width[d], min_half_trays[d], max_trays)
        out_half_trays[d] = m
        trays = 2 * m + 1
        out_status[d] = status if status != OK or trays <= tray_room[d] else NO_ROOM
        if out_status[d] != OK:
            continue
        t0 = tray_first[d]
        out_pooled[t0:t0 + trays] = pooled
        m0 = masses_first[d]
        masses = out_per_replicate[m0:m0 + replicates[d] * trays].reshape((replicates[d], trays))
        masses[:] = per_replicate
        target = np.full(1, target_trays[d])
        tray, column = fold_pair_arrays(trays, target, racetrack[d])
        raw, cv, se, usable = bout_cvs(masses, tray, column, target, bout_columns(target, racetrack[d]))
        out_target[d, 0], out_target[d, 1], out_target[d, 2], out_target[d, 3] = raw[0], cv[0], se[0], usable[0]
        reach = -1
        for t in range(trays):
            if pooled[t] > 0.0:
                reach = max(reach, abs(t - m))
        if reach < 0:
            continue
        widths = np.arange(1, 2 * reach + 2)  # `pattern.default_widths_m` in trays
        tray, column = fold_pair_arrays(trays, widths, racetrack[d])
        raw, cv, se, usable = bout_cvs(masses, tray, column, widths, bout_columns(widths, racetrack[d]))
        for w in range(widths.size):
            out_curve[t0 + w, 0], out_curve[t0 + w, 1], out_curve[t0 + w, 2] = raw[w], cv[w], se[w]
            out_curve[t0 + w, 3] = usable[w]
