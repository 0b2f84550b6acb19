"""Helpers shared by the test tiers."""

import subprocess
import time
from typing import NamedTuple


def wait_until(predicate, timeout_s=5.0, interval_s=0.01):
    """Poll ``predicate`` until true or the timeout; return its last value."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(interval_s)


class ReaderGone(NamedTuple):
    """What a command did when the reader of its output went away after one line."""

    first_line: str
    status: int
    stderr: str


def first_line_then_reader_gone(process: subprocess.Popen, timeout_s: float) -> ReaderGone:
    """
    Read ``process``'s first line, then close its stdout as ``| head -1`` does; wait for it.

    ``process`` has stdout and stderr as text pipes. Return the line, the exit status and
    what it wrote on stderr. A process still running when the test is done is killed.
    """
    try:
        first_line = process.stdout.readline()
        process.stdout.close()
        status = process.wait(timeout=timeout_s)
        return ReaderGone(first_line, status, process.stderr.read())
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
