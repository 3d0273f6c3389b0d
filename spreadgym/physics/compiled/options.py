"""The compile options of spreadgym's numba kernels, in a module that imports nothing
else of spreadgym's (so any module may use them without an import cycle), and the check
that keeps their on-disk caches honest, run before any cached kernel loads."""

from __future__ import annotations

from numba import njit

from spreadgym.physics.compiled.kernel_cache import drop_stale_caches

drop_stale_caches()  # before any cached kernel loads: see kernel_cache
KERNEL = njit(cache=True, error_model="numpy", nogil=True)
"""The compile options of every kernel. error_model="numpy": a division by zero gives
inf/nan instead of raising, so no check is compiled into each division; every division
that would not have raised gives the same bits (no fastmath: results stay exact IEEE).
nogil: a kernel lets other Python threads run (spreadgym.spread.batch runs scenes'
stages side by side)."""

PARALLEL = njit(cache=True, error_model="numpy", nogil=True, parallel=True)
"""KERNEL for a loop over independent granules run with numba's threads (`prange`, as
many as spreadgym.threads allows); each iteration is the same scalar code, so the same bits."""

INLINED = njit(cache=True, error_model="numpy", inline="always")
"""KERNEL for what `granule_run.run_one` calls at every pass of its loop (the phases'
steps, the vertical events, the overlap test, the impacts) and for the free phase's
fourth-order step, event values and accelerations: numba inlines them into the loop,
which spares a call that passes the parameter arrays each time. Same operations in the
same order, so the same bits; paper kernel 11.1 -> 9.6 ms, cold compile 19 -> 30 s
(docs/performance.md). Inlining the contact phase's helpers as well made it slower."""

