"""
The soak through the node: 20 s, and 60 s with ``-m soak`` (bench/soak_node.py runs longer).

``drive_bridge_node`` in a subprocess on the soak line (faults, outages, trips), random
service calls (several in flight, one per device) and references from an rclpy client,
then SIGTERM; the oracle checks the line's log against the client's record, and every motor
the node may have started is stopped afterwards, except the stop_on_shutdown: false one.
"""

import pytest
from soak_node import LEFT_RUNNING, NodeSoakSettings, run_node_soak


@pytest.mark.timeout(400)
@pytest.mark.parametrize('duration_s', [20.0, pytest.param(60.0, marks=pytest.mark.soak)])
def test_node_soak_meets_the_invariants_and_sigterm_stops_what_it_started(tmp_path, duration_s):
    report = run_node_soak(NodeSoakSettings(duration_s=duration_s, seed=3), str(tmp_path))
    text = '\n'.join(report.lines(most=10))
    print(text)
    assert report.exit_code == 0, report.output[-4000:]
    assert report.unanswered == 0, text
    assert report.violations == [], text
    # It exercised what the invariants are about.
    assert report.commands['start acknowledged'] > 0 and report.commands['stop acknowledged'] > 0
    assert report.offline_notices > 0 and report.trips > 0, text
    # SIGTERM: the node stopped what it had started (the oracle's not_stopped found nothing),
    # and left the stop_on_shutdown: false starter running.
    started = [name for name, outcome in report.final_starts.items()
               if outcome == 'acknowledged']
    assert len(started) >= 3, text
    assert 'shutdown: stop acknowledged by' in report.output
    if report.final_starts.get(LEFT_RUNNING) == 'acknowledged':
        assert report.left_running, text
