"""Hypothesis profiles: `ci` (default, derandomised and small, for make test) and `deep`
(HYPOTHESIS_PROFILE=deep: many more examples, for a long run)."""

import os
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
