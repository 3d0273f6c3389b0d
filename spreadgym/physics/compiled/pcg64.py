"""numpy's default bit generator (PCG64) stepped in compiled code, the same outputs.

Kernels that draw random numbers (the release-angle copies' von Mises angles, the
Sobol scrambles) take generators' states as plain integers instead of numpy
`Generator` objects: numba boxes a Generator through ctypes under the GIL on every
call, and a batch of runs on threads pays that dozens of times per run. The state
words follow numpy's PCG64: the 128-bit LCG s = s M + inc mod 2^128 with the XSL-RR
output rotr64(high(s) ^ low(s), s >> 122), seeded from a SeedSequence as numpy seeds it,
and 32-bit draws that use both halves of a 64-bit output, low half first. Tested
against `bit_generator.random_raw`, `Generator.random` and `Generator.integers`.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from spreadgym.physics.compiled.options import INLINED, KERNEL

HIGH, LOW, INC_HIGH, INC_LOW, HAS_HALF, HALF = range(6)
"""The words of a state (uint64 (6,)): the LCG state and increment (high and low 64
bits), and whether a 32-bit half of the last output is kept for the next 32-bit draw."""
MULTIPLIER_HIGH = np.uint64(0x2360ED051FC65DA4)  # the 128-bit LCG multiplier (numpy's, O'Neill's)
MULTIPLIER_LOW = np.uint64(0x4385DF649FCCF645)


def seeded(seeds: Sequence, spawned: bool = False) -> np.ndarray:
    """(R, 6) uint64 states of `np.random.default_rng(seed)` for each seed, or (`spawned`)
    of that generator's first `spawn(1)` child."""
    words = np.array([np.random.SeedSequence(seed, spawn_key=(0,) if spawned else ()).generate_state(4, np.uint64)
                      for seed in seeds], dtype=np.uint64).reshape(-1, 4)
    return _set_seed(words)


@KERNEL
def _set_seed(words):
    """numpy's `pcg64_set_seed` of each row (state high, low, sequence high, low)."""
    states = np.zeros((words.shape[0], 6), dtype=np.uint64)
    one = np.uint64(1)
    for r in range(words.shape[0]):
        s = states[r]
        s[INC_HIGH] = (words[r, 2] << one) | (words[r, 3] >> np.uint64(63))
        s[INC_LOW] = (words[r, 3] << one) | one
        _step(s)
        low = s[LOW] + words[r, 1]
        s[HIGH] = s[HIGH] + words[r, 0] + (one if low < s[LOW] else np.uint64(0))
        s[LOW] = low
        _step(s)
    return states


@INLINED
def _mul_high(a, b):
    """The high 64 bits of the 128-bit product of the uint64s a and b."""
    mask, half = np.uint64(0xFFFFFFFF), np.uint64(32)
    a_lo, a_hi, b_lo, b_hi = a & mask, a >> half, b & mask, b >> half
    lo_lo, hi_lo, lo_hi = a_lo * b_lo, a_hi * b_lo, a_lo * b_hi
    middle = (lo_lo >> half) + (hi_lo & mask) + lo_hi
    return a_hi * b_hi + (hi_lo >> half) + (middle >> half)


@INLINED
def _step(state):
    """s = s M + inc mod 2^128, in place."""
    hi, lo = state[HIGH], state[LOW]
    product_lo = lo * MULTIPLIER_LOW
    product_hi = _mul_high(lo, MULTIPLIER_LOW) + lo * MULTIPLIER_HIGH + hi * MULTIPLIER_LOW
    lo = product_lo + state[INC_LOW]
    state[HIGH] = product_hi + state[INC_HIGH] + (np.uint64(1) if lo < product_lo else np.uint64(0))
    state[LOW] = lo


@INLINED
def next64(state):
    """The next 64-bit output (`bit_generator.random_raw`), stepping `state` in place."""
    _step(state)
    value, rot = state[HIGH] ^ state[LOW], state[HIGH] >> np.uint64(58)
    return (value >> rot) | (value << ((np.uint64(64) - rot) & np.uint64(63)))


@INLINED
def next_double(state):
    """numpy's `random()`: the next output's top 53 bits over 2^53."""
    return float(next64(state) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@INLINED
def next32(state):
    """numpy's next 32-bit draw: the low half of a fresh output, then its high half."""
    if state[HAS_HALF]:
        state[HAS_HALF] = np.uint64(0)
        return state[HALF]
    value = next64(state)
    state[HAS_HALF], state[HALF] = np.uint64(1), value >> np.uint64(32)
    return value & np.uint64(0xFFFFFFFF)


@INLINED
def next_bit(state):
    """`integers(0, 2, dtype=np.uint32)`: Lemire's bounded draw for two values, the top
    bit of a 32-bit draw (never rejected)."""
    return next32(state) >> np.uint64(31)
