"""Twenty reconnect cycles in a row per drill: unplugged adapter, power cycle, gateway restart."""

from pymodbus_use import marked_params
import pytest
from reconnect_drill import DRILLS, run_drill


@pytest.mark.realtime  # a recovery within 2 s: beside parallel workers and a hog, 3.3 s
@pytest.mark.parametrize('drill', marked_params(DRILLS, lambda drill: drill == 'tcp'))
def test_twenty_cycles_recover_without_restart_and_resend_set_up(drill):
    report = run_drill(drill, cycles=20)
    print(report.line())
    assert report.failures == [], report.line()
    assert len(report.recover_s) == 20
    # backoff_max is 0.5 s in the drill: a recovery takes one backoff period and a poll.
    assert max(report.recover_s) < 2.0, report.line()
    assert max(report.detect_s) < 2.0, report.line()
