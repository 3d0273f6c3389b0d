"""Keeping numba's on-disk kernel caches honest.

numba invalidates a cached kernel when its own source file changes, not when a kernel
it calls from another file does (numba issue #1833, documented in numba's caching
notes): after an edit to, say, free_motion.py, granule_run's cached machine code would
still run the old free motion. So every kernel cache next to the kernel sources is
dropped whenever any of those sources differs from the ones the caches were built from
(a SHA-256 of their bytes, kept beside the caches). A read-only install (nothing to
drop or write) is left alone; so are caches under NUMBA_CACHE_DIR.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

_PHYSICS = Path(__file__).resolve().parents[1]
_SPREAD = _PHYSICS.parent / "spread"
KERNEL_SOURCES = (*sorted((_PHYSICS / "compiled").glob("*.py")), _PHYSICS / "magnus.py", _PHYSICS / "granules.py",
                  _PHYSICS / "departure.py",
                  *(_SPREAD / f"{name}.py" for name in ("flight_kernel", "finish_kernel", "binning", "estimate",
                                                         "pattern", "rotations", "von_mises")))
"""Every file with a cached kernel, CPU or GPU: a kernel calling into another file (the
spinner's phases, the PCG64 steps, the tray CV, the GPU kernel's CPU physics) needs the
whole set watched."""
STAMP_NAME = "kernel-sources.sha256"


def sources_digest(sources) -> str:
    digest = hashlib.sha256()
    for path in sources:
        digest.update(Path(path).name.encode())
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()


def drop_stale_caches(sources=KERNEL_SOURCES) -> bool:
    """Delete the numba caches (*.nbi, *.nbc) of `sources` unless they were built from
    these very sources; returns True when caches were dropped."""
    sources = [Path(p) for p in sources]
    stamp = sources[0].parent / "__pycache__" / STAMP_NAME
    digest = sources_digest(sources)
    try:
        if stamp.is_file() and stamp.read_text(encoding="ascii") == digest:
            return False
        for source in sources:
            for cache in (source.parent / "__pycache__").glob(f"{source.stem}.*.nb[ic]"):
                cache.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest, encoding="ascii")
    except OSError:  # read-only install: numba keeps its caches elsewhere, if at all
        return False
    return True
