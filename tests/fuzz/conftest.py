"""Hypothesis profiles: `ci` (default, derandomised and small, for make test) and `deep`
(HYPOTHESIS_PROFILE=deep: many more examples, for a long run)."""

import os
import resource
import signal
from contextlib import contextmanager

from hypothesis import HealthCheck, settings

settings.register_profile("ci", max_examples=30, derandomize=True, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("deep", max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@contextmanager
def time_limit(seconds: int):
    """Fail (instead of hanging) when the body runs longer than `seconds`."""
    def expire(signum, frame):
        raise TimeoutError(f"no result within {seconds} s: a hang")
    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@contextmanager
def bounded(seconds: int, memory_bytes: int = 2**30):
    """`time_limit(seconds)`, and fail when the process's peak memory grew by `memory_bytes` or more."""
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with time_limit(seconds):
        yield
    grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024  # ru_maxrss is in KiB
    assert grown < memory_bytes, f"the peak memory grew by {grown / 2**20:.0f} MiB"
