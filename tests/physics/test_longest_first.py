"""The GPU queue's order (physics.compiled.model.longest_first): numpy's stable sort of the
start radius bins, whatever the thread count, on edge cases and a random batch."""

import numpy as np
import pytest

from spreadgym import threads
from spreadgym.physics.compiled.layout import DISC_RADIUS, P_SIZE
from spreadgym.physics.compiled.model import SORT_PARTS, START_BINS, longest_first


def _params(radii):
    P = np.zeros((len(radii), P_SIZE))
    P[:, DISC_RADIUS] = radii
    return P


def _numpy_order(start, design, P):
    reach = np.hypot(start[:, 0], start[:, 1]) / P[design, DISC_RADIUS]
    return np.argsort(np.clip((reach * START_BINS).astype(np.int64), 0, START_BINS - 1), kind="stable")


@pytest.mark.parametrize("count", [0, 1, 5, SORT_PARTS - 1, SORT_PARTS + 3, 10_000])
def test_the_order_is_the_stable_sort_of_the_bins(count):
    rng = np.random.default_rng(count)
    P = _params([0.15, 0.3, 0.2])
    design = rng.integers(0, 3, count)
    start = rng.uniform(-0.4, 0.4, (count, 2))  # some beyond their disc's rim: the last bin
    if count >= 5:
        start[:3] = [[0.0, 0.0], [0.15, 0.0], [0.0, -0.3]]  # the axis, exactly the rim of disc 0, beyond
        design[:3] = 0
    order = longest_first(start, design, P)
    assert order.dtype == np.int64 and np.array_equal(order, _numpy_order(start, design, P))


def test_the_thread_count_does_not_change_the_order():
    rng = np.random.default_rng(7)
    start, design, P = rng.uniform(-0.15, 0.15, (5000, 2)), rng.integers(0, 2, 5000), _params([0.15, 0.15])
    found = []
    for count in (1, 2):
        threads.set_threads(count)
        try:
            found.append(longest_first(start, design, P))
        finally:
            threads.set_threads(None)
    assert np.array_equal(found[0], found[1])
