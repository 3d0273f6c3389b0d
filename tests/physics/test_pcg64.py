"""The compiled PCG64 (spreadgym.physics.compiled.pcg64) against numpy's own generator."""

import numpy as np
import pytest

from spreadgym.physics.compiled import pcg64
from spreadgym.physics.compiled.options import KERNEL

SEEDS = [0, (0,), (1, 2, 1), (2**63 + 5, 7, 1), (12345, 0), 2**100, (3, 4, 5, 6, 7, 8)]  # 1 to 6 entropy words
RAW, DOUBLE, BIT = range(3)


@KERNEL
def _draws(state, count, kind):
    """`count` draws of one kind from `state` (stepped in place): raw outputs, doubles or bits."""
    out = np.empty(count, dtype=np.uint64)
    doubles = np.empty(count)
    for i in range(count):
        if kind == RAW:
            out[i] = pcg64.next64(state)
        elif kind == DOUBLE:
            doubles[i] = pcg64.next_double(state)
        else:
            out[i] = pcg64.next_bit(state)
    return out, doubles


def state_words(rng):
    bits = rng.bit_generator.state
    mask = (1 << 64) - 1
    s, inc = bits["state"]["state"], bits["state"]["inc"]
    return np.array([s >> 64, s & mask, inc >> 64, inc & mask, bits["has_uint32"], bits["uinteger"]], dtype=np.uint64)


@pytest.mark.parametrize("seed", SEEDS)
def test_seeding_gives_numpys_state_and_its_spawned_childs(seed):
    assert np.array_equal(pcg64.seeded([seed])[0], state_words(np.random.default_rng(seed)))
    child = np.random.default_rng(seed).spawn(1)[0]
    assert np.array_equal(pcg64.seeded([seed], spawned=True)[0], state_words(child))


@pytest.mark.parametrize("seed", SEEDS)
def test_outputs_doubles_and_bits_are_numpys(seed):
    state = pcg64.seeded([seed])[0]
    rng = np.random.default_rng(seed)
    raw, _ = _draws(state, 5000, RAW)
    assert np.array_equal(raw, rng.bit_generator.random_raw(5000))
    assert np.array_equal(state, state_words(rng))  # left where numpy leaves it
    _, doubles = _draws(state, 777, DOUBLE)
    assert np.array_equal(doubles, rng.random(777))
    bits, _ = _draws(state, 1001, BIT)  # odd: a 32-bit half stays kept, as numpy keeps it
    assert np.array_equal(bits.astype(np.uint32), rng.integers(0, 2, size=1001, dtype=np.uint32))
    assert np.array_equal(state, state_words(rng))


def test_a_negative_seed_is_refused_as_numpy_refuses_it():
    with pytest.raises(ValueError):
        np.random.SeedSequence(-1)
    with pytest.raises(ValueError, match="non-negative"):
        pcg64.seeded([(1, -1)])
