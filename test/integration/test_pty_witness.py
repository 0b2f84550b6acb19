"""The pty witness of the timing tests (test/pty_witness.py): it sees lags, reruns on them only."""

import time

from integration_helpers import wait_until
import pty_witness
from pty_witness import PtyLagged, PtyWitness, run_unless_a_pty_lagged
import pytest


def test_the_witness_sees_its_thread_held_up():
    with PtyWitness() as witness:
        assert wait_until(lambda: witness.probes >= 5, 10.0)
        started = time.monotonic()
        sum(range(15_000_000))  # one C call: no other thread of this process runs meanwhile
        held_s = time.monotonic() - started
        probes = witness.probes
        assert wait_until(lambda: witness.probes >= probes + 2, 10.0)
    assert witness.longest_s >= held_s / 2, (held_s, witness.longest_s)


class FakeWitness:
    """A witness whose longest lag the test sets."""

    lag_s = 0.0

    def __init__(self):
        self.longest_s = FakeWitness.lag_s
        self.probes = 1
        self.error = None

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        pass


@pytest.fixture
def lag_of_the_witness(monkeypatch):
    """Put the fake witness in place; return how to set its lag (restored after the test)."""
    monkeypatch.setattr(pty_witness, 'PtyWitness', FakeWitness)
    return lambda seconds: monkeypatch.setattr(FakeWitness, 'lag_s', seconds)


def test_a_body_that_passes_runs_once_and_gives_its_result(lag_of_the_witness):
    runs = []
    assert run_unless_a_pty_lagged(lambda: runs.append(1) or 'done', margin_s=0.5) == 'done'
    assert runs == [1]


def failing(runs: list, failure: Exception):
    """Return a body that notes its run in ``runs`` and raises ``failure``."""
    def body():
        runs.append(1)
        raise failure
    return body


def test_a_failure_without_a_lag_past_the_margin_fails_at_once_and_says_so(lag_of_the_witness):
    lag_of_the_witness(0.5)
    runs = []
    with pytest.raises(AssertionError, match='counted 9 against 8') as failure:
        run_unless_a_pty_lagged(failing(runs, AssertionError('counted 9 against 8')),
                                margin_s=0.5)
    assert runs == [1]
    assert 'the longest lag was 0.500 s' in failure.value.__notes__[0]


def test_a_failure_with_a_lag_runs_again_and_a_later_pass_counts(lag_of_the_witness):
    lag_of_the_witness(0.7)
    runs = []

    def body():
        runs.append(1)
        assert len(runs) == 2, 'lagged'
        return len(runs)
    with pytest.warns(PtyLagged, match='0.700 s'):
        assert run_unless_a_pty_lagged(body, margin_s=0.5) == 2


def test_three_failures_each_with_a_lag_fail(lag_of_the_witness):
    lag_of_the_witness(2.0)
    runs = []
    with pytest.warns(PtyLagged), pytest.raises(AssertionError, match='always') as failure:
        run_unless_a_pty_lagged(failing(runs, AssertionError('always')), margin_s=0.5)
    assert runs == [1, 1, 1] and 'run 3 of 3' in failure.value.__notes__[0]


def test_an_error_that_is_not_an_assertion_is_never_run_again(lag_of_the_witness):
    lag_of_the_witness(9.0)
    runs = []
    with pytest.raises(OSError):
        run_unless_a_pty_lagged(failing(runs, OSError('the pty is gone')), margin_s=0.5)
    assert runs == [1]


def test_a_witness_that_stopped_early_is_no_evidence(monkeypatch):
    def broken_probe(self, master, slave):
        self._sent_at_s = time.monotonic()
        raise OSError('EIO')
    monkeypatch.setattr(PtyWitness, '_probe', broken_probe)
    runs = []

    def slow_failure():
        runs.append(1)
        time.sleep(0.6)
        raise AssertionError('counted 9 against 8')
    with pytest.raises(AssertionError) as failure:
        run_unless_a_pty_lagged(slow_failure, margin_s=0.5)
    assert runs == [1] and 'no evidence' in failure.value.__notes__[0]
