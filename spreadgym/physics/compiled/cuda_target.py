"""numba's CUDA target, loaded once for spreadgym's GPU kernel (the spinner's), and its
helper `host_array`.

Imported only when the device is "cuda" (spreadgym.device). numba.cuda compiles a
CPU-jitted function that a GPU kernel calls from its Python source, so the kernel calls
the CPU's own scalar functions, and a change to the physics reaches both devices; under
numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1) a kernel runs as Python, calling those
functions as they are.
"""

from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):  # numba-cuda 0.30 registers np.row_stack (an alias of vstack, gone in numpy 2.5)
    np.row_stack = np.vstack  # as it loads its target: without it no kernel compiles (seen on numpy 2.5.2)

from numba import config, cuda  # noqa: E402 (after the alias above)

if config.ENABLE_CUDASIM:
    def host_array(view):
        """The simulator hands a kernel wrapped arrays; the CPU functions it calls take
        numpy's (the wrapped one's memory)."""
        return view._item._ary
else:
    @cuda.jit(device=True, inline=True)
    def host_array(view):
        """An array argument as the CPU function a kernel calls takes it (itself on a GPU)."""
        return view
