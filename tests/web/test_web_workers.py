"""The server's worker lanes (agents.web.workers) on their own: answers, one-line errors,
a request that leaves or passes its time stopped, a grown worker replaced."""

import asyncio
import time

import pytest

from spreadgym.agents.web.workers import Lane, Left, TimeLimit
from spreadgym.errors import SpreadgymError

SIMULATE = "spreadgym.agents.web.pattern:simulate_task"
SMALL = {"scene": "paper", "set": {"sim.granules": 64}, "max_runs": 2}
LONG = {"scene": "paper", "set": {"sim.granules": 20000}, "precision": 0.001, "max_runs": 4096}


async def stay() -> bool:
    return False


def run(coroutine):
    return asyncio.run(coroutine)


def test_answers_errors_and_a_grown_worker_replaced():
    async def scenario():
        lane = Lane("test", 120.0, 4, grow_limit_bytes=0)  # every job "grows": the worker is replaced after it
        try:
            text = await lane.run(SIMULATE, SMALL, stay)
            first = lane._worker
            assert first is None or not first.process.is_alive()  # retired after its job
            with pytest.raises(SpreadgymError, match="spinner.rpm"):
                await lane.run(SIMULATE, {**SMALL, "set": {"spinner.rpm": -1}}, stay)
            return text
        finally:
            lane.shutdown()

    assert '"cv_percent_at_target"' in run(scenario())


def test_a_request_that_leaves_or_runs_out_of_time_is_stopped():
    async def scenario():
        lane = Lane("test", 2.0, 4)
        try:
            started = time.monotonic()
            with pytest.raises(TimeLimit, match="time limit of 2 s"):
                await lane.run(SIMULATE, LONG, stay)
            assert time.monotonic() - started < 60  # the worker's start (its imports) counts against the limit too
            lane.time_limit_s = 600.0
            leave_at = time.monotonic() + 1.0

            async def leaves() -> bool:
                return time.monotonic() > leave_at

            with pytest.raises(Left):
                await lane.run(SIMULATE, LONG, leaves)
            assert await lane.run(SIMULATE, SMALL, stay)  # the lane goes on (a new worker where one was killed)
        finally:
            lane.shutdown()

    run(scenario())
