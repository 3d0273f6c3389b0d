"""The C heap set for spreadgym's pattern of memory use (glibc only): `tune()`.

A simulation allocates and frees arrays of 0.1-20 MB per design (granule states, release-
angle copies, landings, tray samples). glibc serves an allocation above its mmap
threshold with fresh pages from the kernel, zero-filled on first touch, and returns freed
heap memory above its trim threshold; both thresholds start at 128 KiB and
rise only as large blocks happen to be freed. So a fresh process, or one whose largest
arrays so far were smaller, pays page faults on most of its arrays, and threads fault into
one address space one at a time. `tune()` sets the mmap threshold to 32 MiB (glibc's
ceiling on 64-bit) and the trim threshold to 64 MiB, so those arrays come from memory the
process keeps. Measured (docs/performance.md): a CMA-ES generation of 6 designs in a fresh
process on 2 threads 1.55-1.66x -> 1.67-1.75x the one-by-one rate; the 64-env vector
env's page faults 3-8x fewer at the same peak memory. Results do not depend on it.

The process keeps up to 64 MiB of freed memory per malloc arena instead of returning it.
Anyone who sets glibc's malloc themselves (MALLOC_MMAP_THRESHOLD_, MALLOC_TRIM_THRESHOLD_,
MALLOC_TOP_PAD_, or malloc tunables in GLIBC_TUNABLES) keeps their settings: `tune()` then
does nothing, as it does on other C libraries.
"""

from __future__ import annotations

import ctypes
import os
import threading
from typing import Optional

MMAP_THRESHOLD_BYTES = 32 * 2**20  # glibc refuses more on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX)
TRIM_THRESHOLD_BYTES = 64 * 2**20
USER_SETTINGS = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_")
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's malloc.h
_tuned: Optional[bool] = None  # decided on the first call
_lock = threading.Lock()


def tune() -> bool:
    """Set glibc's mmap and trim thresholds, on the process's first call (see the module's
    docstring); True when they were set."""
    global _tuned
    if _tuned is None:
        with _lock:
            if _tuned is None:
                _tuned = _ours_to_set() and _set_thresholds()
    return _tuned


def _ours_to_set() -> bool:
    """glibc, and the user has not set its malloc."""
    if not is_glibc() or any(os.environ.get(name) for name in USER_SETTINGS):
        return False
    return "glibc.malloc." not in os.environ.get("GLIBC_TUNABLES", "")


def is_glibc() -> bool:
    """Whether the C library is glibc (whose thresholds `tune` sets)."""
    try:
        return bool(os.confstr("CS_GNU_LIBC_VERSION"))  # other C libraries raise or answer None
    except (AttributeError, ValueError, OSError):  # AttributeError: no confstr (Windows)
        return False


def _set_thresholds() -> bool:
    libc = ctypes.CDLL(None)
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and \
        bool(libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
