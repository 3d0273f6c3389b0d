"""The GPU schedule model (spreadgym.studies.gpu_schedule) on cases worked by hand, and
the pass counts it reads from the CPU kernel."""

import numpy as np

from spreadgym.studies import gpu_schedule


def test_one_granule_per_thread_holds_each_block_until_its_slowest_granule():
    passes = np.array([5.0, 1.0, 1.0, 1.0, 2.0, 2.0])
    # blocks of 2: longest 5, 1, 2; one place (2 resident threads): 5 + 1 + 2
    assert gpu_schedule.one_per_thread(passes, resident=2, block=2) == 8.0
    # two places: 5 | 1 then 2 -> 3: the kernel ends at 5
    assert gpu_schedule.one_per_thread(passes, resident=4, block=2) == 5.0


def test_the_queue_gives_each_granule_to_the_first_free_thread():
    passes = np.array([5.0, 1.0, 1.0, 1.0, 2.0, 2.0])
    # two threads: 5 | 1, 1 (2), 1 (3), 2 (5), 2 -> the first free at 5: 7
    assert gpu_schedule.queued(passes, resident=2) == 7.0
    # the longest handed out last: 2 | 2, 1 (3), 1 (3), 1 (4), 5 (3 + 5): 8
    assert gpu_schedule.queued(passes[::-1].copy(), resident=2) == 8.0
    assert gpu_schedule.queued(passes, resident=6) == 5.0  # as many threads as granules: the longest one


def test_the_pass_counts_are_the_kernels_own():
    """Two designs: one count per granule, each at least one pass, the arrays aligned."""
    passes, start, design, params = gpu_schedule.pass_counts(designs=2)
    assert passes.shape == (design.size,) == (start.shape[0],) and params.shape[0] == 2
    assert passes.min() >= 1 and np.all(passes == np.round(passes))
    assert set(design.tolist()) == {0, 1}
