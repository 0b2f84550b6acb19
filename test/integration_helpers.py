"""Helpers shared by the test tiers."""

import time


def wait_until(predicate, timeout_s=5.0, interval_s=0.01):
    """Poll ``predicate`` until true or the timeout; return its last value."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(interval_s)
