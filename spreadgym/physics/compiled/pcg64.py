"""numpy's default bit generator (PCG64) stepped in compiled code, the same outputs.

Kernels that draw random numbers (the release-angle copies' von Mises angles, the
Sobol scrambles) take generators' states as plain integers instead of numpy
`Generator` objects: numba boxes a Generator through ctypes under the GIL on every
call, and a batch of runs on threads pays that dozens of times per run. The state
words follow numpy's PCG64: the 128-bit LCG s = s M + inc mod 2^128 with the XSL-RR
output rotr64(high(s) ^ low(s), s >> 122), seeded from a SeedSequence as numpy seeds it
(its entropy pool's hash mixing, also compiled: numpy's runs in Python-level steps that
hold the GIL), and 32-bit draws that use both halves of a 64-bit output, low half first.
Tested against `SeedSequence`, `bit_generator.random_raw`, `Generator.random` and
`Generator.integers`.
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
POOL_SIZE = 4  # numpy's SeedSequence pool, 32-bit words
INIT_A, MULT_A, INIT_B, MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED  # its hash constants
MIX_MULT_L, MIX_MULT_R = 0xCA01F9DD, 0x4973F715
WORD = 0xFFFFFFFF


def seeded(seeds: Sequence, spawned: bool = False) -> np.ndarray:
    """(R, 6) uint64 states of `np.random.default_rng(seed)` for each seed (a non-negative
    int or a sequence of them), or (`spawned`) of that generator's first `spawn(1)` child."""
    entropy = [_words(seed) for seed in seeds]
    if spawned:  # the child's spawn key (0,) follows the run entropy, padded to the pool
        entropy = [words + [0] * (POOL_SIZE - len(words)) + [0] for words in entropy]
    lengths = [len(words) for words in entropy]
    width = max(lengths, default=0)
    table = np.array([words + [0] * (width - len(words)) for words in entropy], dtype=np.uint64).reshape(-1, width)
    return _seeded(table, np.array(lengths, dtype=np.int64))


def _words(seed) -> list[int]:
    """numpy's 32-bit entropy words of an int (least significant first; 0 is one word) or
    of a sequence of them (each in turn)."""
    words = []
    for part in (seed,) if isinstance(seed, (int, np.integer)) else seed:
        if not isinstance(part, (int, np.integer)):
            words += _words(part)
            continue
        value = int(part)
        if value < 0:
            raise ValueError(f"seeds must be non-negative, got {value}")
        words.append(value & WORD)
        while value > WORD:
            value >>= 32
            words.append(value & WORD)
    return words


@INLINED
def _hashmix(value, hash_const):
    """numpy's SeedSequence hashmix on 32-bit words held in uint64; returns (value, hash_const)."""
    word = np.uint64(WORD)
    value ^= hash_const
    hash_const = (hash_const * np.uint64(MULT_A)) & word
    value = (value * hash_const) & word
    return value ^ (value >> np.uint64(16)), hash_const


@INLINED
def _mix(x, y):
    word = np.uint64(WORD)
    result = ((np.uint64(MIX_MULT_L) * x) - (np.uint64(MIX_MULT_R) * y)) & word
    return result ^ (result >> np.uint64(16))


@KERNEL
def _seeded(entropy, lengths):
    """PCG64 states from SeedSequence entropy words (rows of `entropy`, the first
    lengths[r] used): the pool mixed and four 64-bit words generated as numpy's
    SeedSequence does, then numpy's `pcg64_set_seed` (state, then increment words)."""
    word = np.uint64(WORD)
    words = np.zeros((entropy.shape[0], 4), dtype=np.uint64)
    pool = np.zeros(POOL_SIZE, dtype=np.uint64)
    for r in range(entropy.shape[0]):
        n = lengths[r]
        hash_const = np.uint64(INIT_A)
        for i in range(POOL_SIZE):
            pool[i], hash_const = _hashmix(entropy[r, i] if i < n else np.uint64(0), hash_const)
        for src in range(POOL_SIZE):
            for dst in range(POOL_SIZE):
                if src != dst:
                    hashed, hash_const = _hashmix(pool[src], hash_const)
                    pool[dst] = _mix(pool[dst], hashed)
        for src in range(POOL_SIZE, n):
            for dst in range(POOL_SIZE):
                hashed, hash_const = _hashmix(entropy[r, src], hash_const)
                pool[dst] = _mix(pool[dst], hashed)
        hash_const = np.uint64(INIT_B)
        for k in range(8):  # 32-bit words, two to each 64-bit word (little end first)
            value = pool[k % POOL_SIZE] ^ hash_const
            hash_const = (hash_const * np.uint64(MULT_B)) & word
            value = (value * hash_const) & word
            value ^= value >> np.uint64(16)
            words[r, k // 2] |= value << np.uint64(32 * (k % 2))
    return _set_seed(words)


@INLINED
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
    mask, half = np.uint64(WORD), np.uint64(32)
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
    return value & np.uint64(WORD)


@INLINED
def next_bit(state):
    """`integers(0, 2, dtype=np.uint32)`: Lemire's bounded draw for two values, the top
    bit of a 32-bit draw (never rejected)."""
    return next32(state) >> np.uint64(31)
