"""
A witness of the machine's ptys: how late a byte written to a pty reaches its reader.

The integration tier talks to its simulators over ptys, and a pty hands its bytes over on a
kernel worker. On the 2-core virtual machine that worker lags now and then: a pty of its
own, probed every 10 ms beside the integration tier's three workers, once took 0.84 s to
hand over one byte, and in one run of the tier a read of a babbling line was held 6.7 s
while, in another worker, the soak's simulator saw no request for 6.8 s. The threads of
those processes were not held up meanwhile (a thread that ticked every 5 ms in each worker
saw no gap over 0.26 s); the bytes were.

A test whose assertion judges time on a pty (a reply later than its margin counts as slow
or lost) runs its body through :func:`run_unless_a_pty_lagged`: the body runs again, at most
twice, only when it failed while the witness saw a byte arrive, or its own thread wake,
later than the margin (a long pause of the test's process counts too: the simulators are
threads of it). The assertions are the same on every run, and a failure without such a lag,
or with a witness that stopped early, fails at once.
"""

import os
import pty
import select
import threading
import time
import tty
from typing import Callable, TypeVar
import warnings

PROBE_PERIOD_S = 0.01
Result = TypeVar('Result')


class PtyLagged(UserWarning):
    """A test ran again because a pty lagged past its margin while it failed."""


class PtyWitness:
    """
    A thread that writes a byte to a pty of its own every 10 ms and times its arrival.

    ``longest_s`` is the longest lag seen: of a byte, or of the thread's own wake-up after
    its 10 ms (a process or a thread held up delays the simulators' replies as much).
    """

    def __init__(self, period_s: float = PROBE_PERIOD_S):
        self.period_s = period_s
        self.longest_s = 0.0  # the longest lag seen, in flight or of a wake-up
        self.probes = 0
        self._sent_at_s = None  # when the byte in flight was written
        self.error = None  # what stopped the thread early: its figures are then no evidence
        self._lock = threading.Lock()
        self._stop_r, self._stop_w = os.pipe()
        self._thread = threading.Thread(target=self._run, name='pty-witness', daemon=True)

    def __enter__(self) -> 'PtyWitness':
        self._thread.start()
        return self

    def __exit__(self, *exc_info) -> None:
        os.write(self._stop_w, b'.')
        self._thread.join()
        with self._lock:
            if self._sent_at_s is not None and self.error is None:  # a byte on its way is late
                self.longest_s = max(self.longest_s, time.monotonic() - self._sent_at_s)
        os.close(self._stop_r)
        os.close(self._stop_w)

    def _run(self) -> None:
        try:
            self._probe_until_stopped()
        except Exception as error:  # kept: the figures are then no evidence of a lag
            self.error = error

    def _probe_until_stopped(self) -> None:
        master, slave = pty.openpty()
        tty.setraw(slave)
        try:
            while self._probe(master, slave):
                due_s = time.monotonic() + self.period_s
                ready, _, _ = select.select([self._stop_r], [], [], self.period_s)
                if ready:
                    return
                self._note(time.monotonic() - due_s)  # this thread, held up itself
        finally:
            os.close(master)
            os.close(slave)

    def _probe(self, master: int, slave: int) -> bool:
        """Time one byte from ``master`` to ``slave``; return False when told to stop."""
        with self._lock:
            self._sent_at_s = time.monotonic()
        os.write(master, b'x')
        ready, _, _ = select.select([slave, self._stop_r], [], [])
        if slave not in ready:
            return False  # stopped with the byte in flight: __exit__ counts it
        os.read(slave, 64)
        with self._lock:
            lag_s = time.monotonic() - self._sent_at_s
            self._sent_at_s = None
            self.probes += 1
        self._note(lag_s)
        return True

    def _note(self, lag_s: float) -> None:
        with self._lock:
            self.longest_s = max(self.longest_s, lag_s)


def run_unless_a_pty_lagged(body: Callable[[], Result], margin_s: float,
                            runs: int = 3) -> Result:
    """
    Return ``body()``; run it again only if it failed while a pty lagged past ``margin_s``.

    ``margin_s``: the shortest lag that could change what the body asserts (for a reply
    counted as slow after 1 s and sent 1.5 s late, 0.5 s). A failure is raised with the
    witness's longest lag added to it: at once when the witness saw no lag past the margin
    or stopped early, or after ``runs`` runs that each failed with such a lag.
    """
    for run in range(1, runs + 1):
        witness = PtyWitness()
        with witness:
            try:
                return body()
            except AssertionError as error:
                failure = error
        lag = f'pty witness: the longest lag was {witness.longest_s:.3f} s ' \
            f'({witness.probes} probes; margin {margin_s:g} s), run {run} of {runs}'
        if witness.error is not None:
            failure.add_note(f'pty witness: stopped by {witness.error!r}, no evidence of a lag')
            raise failure
        if witness.longest_s <= margin_s or run == runs:
            failure.add_note(lag)
            raise failure
        warnings.warn(PtyLagged(f'{lag}: ran again after {failure!r:.300}'))
    raise AssertionError('unreachable')  # pragma: no cover
