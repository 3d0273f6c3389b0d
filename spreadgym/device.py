"""Where the compiled spinner kernel runs: the CPU (default) or a CUDA GPU.

The device is, first found: the one `using` holds on this thread (an environment's
`device` keyword), what `set_device` was given (the CLI's `--device`), the environment
variable SPREADGYM_DEVICE, else "cpu". On "cuda" the spinner stage of a run or a batch
is one kernel launch over all its granules (`physics.compiled.cuda_spinner`: the CPU
kernel's own scalar functions compiled by numba.cuda); the finish (flights, the copies'
turns, trays, CV) stays on the CPU threads (`spreadgym.threads`), where it was measured
to run faster than on a GPU (docs/performance.md, "What stays on the CPU"). A process
drives the GPU from the thread that runs its batch; worker processes (the vector env's
`workers`) each drive it for their own batches, with their shares of the threads, so
threads and devices never multiply.

numba's CUDA target is optional (`pip install spreadgym[cuda]` adds NVIDIA's
numba-cuda); nothing here imports it unless "cuda" is asked for. Asking for it where no
GPU is found is a one-line error.
"""

from __future__ import annotations

import os
import threading
from contextlib import contextmanager
from typing import Iterator, Optional

from spreadgym.errors import ConfigError

ENV_VAR = "SPREADGYM_DEVICE"
DEVICES = ("cpu", "cuda")
_chosen: Optional[str] = None
_held = threading.local()


def set_device(name: Optional[str]) -> None:
    """Use `name` from now on in this process (None: back to the default); "cuda" is
    checked at once, so a machine without a GPU fails here with one line."""
    global _chosen
    _chosen = None if name is None else checked(name, "--device")


def current() -> str:
    """The device a compiled spinner stage runs on now."""
    held = getattr(_held, "name", None)
    if held is not None:
        return held
    if _chosen is not None:
        return _chosen
    name = os.environ.get(ENV_VAR, "").strip()
    return checked(name, ENV_VAR) if name else "cpu"


@contextmanager
def using(name: Optional[str]) -> Iterator[str]:
    """Run the block on device `name` (None: the process's device) on this thread."""
    before = getattr(_held, "name", None)
    _held.name = None if name is None else checked(name, "device")
    try:
        yield current()
    finally:
        _held.name = before


def cuda_available() -> bool:
    """Whether numba finds a CUDA GPU (or runs its simulator, NUMBA_ENABLE_CUDASIM=1)."""
    try:
        from numba import cuda
    except ImportError:
        return False
    try:
        return bool(cuda.is_available())
    except Exception:  # a broken driver or toolkit: no usable GPU
        return False


def checked(name, key: str) -> str:
    """`name` if it is a device this process can use, else a one-line ConfigError naming `key`."""
    if name not in DEVICES:
        raise ConfigError(key, f"unknown device {name!r}; allowed: {', '.join(DEVICES)}")
    if name == "cuda" and not cuda_available():
        raise ConfigError(key, "cuda: no CUDA GPU found here (numba.cuda sees none); the CUDA backend needs an "
                               "NVIDIA GPU with its driver and `pip install spreadgym[cuda]`; use cpu")
    return name
