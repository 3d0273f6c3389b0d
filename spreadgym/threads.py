"""How many threads spreadgym's parallel stages use: one policy for the library and the CLI.

The count is, first found: what `set_threads` was given (the CLI's `--threads N`); the
environment variable SPREADGYM_THREADS; inside a Ray task or actor, the CPUs Ray gave
it; otherwise the cores this process may run on (`os.sched_getaffinity`). numba's
parallel kernels (`prange` over granules) and the batch's thread pool
(spreadgym.spread.batch) both use that count, one stage after the other, so the two
never multiply; nor do a Ray worker's threads and its neighbours'. Results never depend
on it (every granule's arithmetic is the same on any thread).
"""

from __future__ import annotations

import ctypes
import functools
import itertools
import os
import re
import sys
import threading
from contextlib import contextmanager
from importlib import metadata
from typing import Callable, Iterator, Optional, TypeVar

from spreadgym.errors import ConfigError

ENV_VAR = "SPREADGYM_THREADS"
MAX_THREADS = 4096  # far above any machine's cores: more only costs memory and start-up
T = TypeVar("T")
_chosen: Optional[int] = None
_LAUNCH = threading.Lock()


def set_threads(count: Optional[int]) -> None:
    """Use `count` threads from now on in this process (None: back to the default)."""
    global _chosen
    _chosen = None if count is None else _checked(count, "--threads")


def thread_count() -> int:
    """The threads a parallel stage may use now (>= 1)."""
    if _chosen is not None:
        return _chosen
    if os.environ.get(ENV_VAR, "").strip():
        return _checked(os.environ[ENV_VAR].strip(), ENV_VAR)
    return _ray_task_cpus() or len(os.sched_getaffinity(0))


@contextmanager
def numba_threads() -> Iterator[int]:
    """Hold while a numba parallel kernel runs; yields its thread count, `thread_count()`
    at most numba's pool (NUMBA_NUM_THREADS). numba's count is per calling thread, so it
    is set at each launch. Unless NUMBA_THREADING_LAYER says otherwise, numba takes a
    fork-safe layer: GNU OpenMP's kills a forked child (multiprocessing's default start,
    gymnasium's async vector env). That is oneTBB where pip's `tbb` is installed (its
    work-stealing evens out granules of unequal cost and a thread that wakes late;
    `_findable_tbb`), else numba's workqueue, which allows one launch at a time per
    process, hence the lock."""
    import numba

    with _LAUNCH:
        if "NUMBA_THREADING_LAYER" not in os.environ:
            _findable_tbb()
            numba.config.THREADING_LAYER = "forksafe"
        count = min(thread_count(), numba.config.NUMBA_NUM_THREADS)
        numba.set_num_threads(count)
        yield count


def tbb_library() -> Optional[str]:
    """The path of pip's oneTBB library (`libtbb.so.N` among the `tbb` wheel's files, which
    pip puts in the environment's lib folder, where the loader does not look); None where
    that wheel is not installed."""
    try:
        files = metadata.files("tbb") or []
    except metadata.PackageNotFoundError:
        return None
    return next((str(file.locate()) for file in files if re.fullmatch(r"libtbb\.so\.\d+", file.name)), None)


@functools.lru_cache(maxsize=None)
def _findable_tbb() -> None:
    """Load `tbb_library()` once, so that numba's TBB layer, which needs the library by
    name, finds it. Where there is none (or it does not load) numba takes its workqueue,
    with the same results (every granule and every design is computed alone, whichever thread)."""
    path = tbb_library()
    if path is not None:
        try:
            ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
        except OSError:
            pass  # the workqueue, as without the wheel


def shares(processes: int, count: Optional[int] = None) -> list[int]:
    """`count` threads (None: `thread_count()`) shared out over `processes` processes, so
    that the two never multiply: near-equal whole numbers adding up to the count, the first
    ones one more where it does not divide, and at least one each (more processes than
    threads: one each)."""
    count = thread_count() if count is None else count
    return [max(1, count // processes + (p < count % processes)) for p in range(processes)]


def thread_map(work: Callable[[int], T], count: int) -> list[T]:
    """[work(0), ..., work(count - 1)] on up to `thread_count()` threads, the calling one
    among them. For work whose heavy parts release the GIL (compiled kernels, large numpy
    operations), so that items overlap. Each thread takes the next item from a shared
    counter, with no future or wake-up per item (an executor's per-item hand-back to a
    waiting caller cost a 64-run finish stage 4-15 % on two cores, measured). The first
    error raised by any item is raised here once every thread has stopped."""
    results: list = [None] * count
    errors: list[BaseException] = []
    items = itertools.count()  # next() on it is atomic under the GIL

    def worker() -> None:
        for i in iter(items.__next__, None):
            if i >= count or errors:
                return
            try:
                results[i] = work(i)
            except BaseException as error:  # noqa: BLE001 (handed to the caller below)
                errors.append(error)
                return

    helpers = [threading.Thread(target=worker, daemon=True) for _ in range(min(thread_count(), count) - 1)]
    for helper in helpers:
        helper.start()
    worker()
    for helper in helpers:
        helper.join()
    if errors:
        raise errors[0]
    return results


def _checked(value, name: str) -> int:
    try:
        count = int(value)
    except (TypeError, ValueError):
        count = 0
    if isinstance(value, bool) or count < 1 or str(count) != str(value).strip():
        raise ConfigError(name, f"expected a whole number of threads >= 1, got {value!r}")
    if count > MAX_THREADS:
        raise ConfigError(name, f"{count} threads is out of range; allowed: 1 to {MAX_THREADS}")
    return count


def _ray_task_cpus() -> int:
    """The CPUs Ray assigned to the running task or actor; 0 outside one (Ray is never imported here)."""
    ray = sys.modules.get("ray")
    if ray is None or not ray.is_initialized():
        return 0
    try:
        cpus = ray.get_runtime_context().get_assigned_resources().get("CPU", 0.0)
    except Exception:  # the driver, or a Ray without the call: not a task
        return 0
    return max(1, int(cpus)) if cpus else 0
