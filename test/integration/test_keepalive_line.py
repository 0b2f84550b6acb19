"""
The keepalive rule against the real scheduler: the largest gap between two control words.

A running FC 51 and one neighbour on the soak's virtual line (the real transport and line
discipline, the real BusMaster, a virtual clock). The neighbour's replies follow a pattern;
the drive's ``comms_timeout`` is what the rule advises (the gap and the margin), with par.
8-04 = 5 (stop and trip). The control words the simulated drive received, not the bridge's
view, must never be further apart than the rule's gap, and the drive must not trip.
"""

from typing import Optional

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config, keepalive_gaps
from drive_bridge.sim.devices import make_device
from drive_bridge.sim.faults import FaultPlan
import pytest
from soak_harness.line import RecordingServer, VirtualClock, VirtualLine

FEEDER, NEIGHBOUR = 1, 3
TIMEOUT_S = 0.3
STOP_AND_TRIP = 5


class PatternServer(RecordingServer):
    """A line whose replies from one unit follow a fixed pattern of faults (None: answer)."""

    def __init__(self, devices, clock, pattern):
        super().__init__(devices, clock=clock)
        self.pattern, self.count = pattern, 0

    def _draw_fault(self, frame, usable) -> Optional[str]:
        if frame.unit != NEIGHBOUR:
            return None
        fault = self.pattern[self.count % len(self.pattern)]
        self.count += 1
        return fault


def run_line(pattern, neighbour_model: str, feeder_hz: float, neighbour_hz: float,
             seconds: float = 40.0):
    """Return (the rule's gap, the largest gap the drive saw, the drive tripped)."""
    clock = VirtualClock()
    now = clock()
    neighbour_kind = 'drive' if neighbour_model == 'fc51' else 'mcd'
    devices = {FEEDER: (make_device('fc51', now, ramp_up_s=0.5, ramp_down_s=0.5), 'drive'),
               NEIGHBOUR: (make_device(neighbour_model, now), neighbour_kind)}
    server = PatternServer(devices, clock, pattern)
    server.faults.set_plan(FaultPlan(0.0, ('no_reply',), 1, master_timeout_s=TIMEOUT_S))
    bus = {'protocol': 'modbus_rtu', 'port': '/dev/null', 'baudrate': 19200, 'parity': 'N',
           'timeout': TIMEOUT_S, 'devices': ['feeder', 'other']}
    values = {'feeder': {'family': 'fc', 'model': 'fc51', 'address': FEEDER,
                         'poll_rate': feeder_hz, 'comms_timeout': 600.0,
                         'comms_timeout_function': STOP_AND_TRIP},
              'other': {'family': 'fc' if neighbour_kind == 'drive' else 'mcd',
                        'model': neighbour_model, 'address': NEIGHBOUR,
                        'poll_rate': neighbour_hz}}
    gap = keepalive_gaps(build_config(bus, values))['feeder']
    values['feeder']['comms_timeout'] = gap.advised_s
    config = build_config(bus, values)
    master = BusMaster(VirtualLine(config.link, server, clock),
                       [device.make_spec() for device in config.devices], config.timing,
                       clock=clock, sleep=clock.sleep)
    end_s = clock() + 3.0
    while clock() < end_s:
        master.run_step(max_wait_s=0.005)
    master.submit_command('feeder', 'start')
    end_s = clock() + seconds
    while clock() < end_s:
        master.run_step(max_wait_s=0.005)
    writes = [frame.time_s for frame in server.frames
              if frame.unit == FEEDER and frame.control is not None]
    assert len(writes) > 10, 'the drive got no keepalive'
    largest_s = max(later - earlier for earlier, later in zip(writes, writes[1:]))
    return gap, largest_s, server.devices[FEEDER].model.tripped


@pytest.mark.parametrize('pattern, neighbour_model, feeder_hz, neighbour_hz', [
    ((None,), 'fc51', 5.0, 5.0),  # a line that works
    (('no_reply', 'no_reply', None), 'fc51', 5.0, 5.0),  # answered at the last retry: online
    (('no_reply', 'no_reply', None), 'mcd500', 5.0, 20.0),
    (('no_reply',), 'fc51', 5.0, 5.0),  # silent: offline, then probed
    (('no_reply', 'no_reply', None), 'fc51', 0.5, 50.0),  # a slow drive, a fast neighbour
], ids=['working', 'flaky_fc51', 'flaky_mcd', 'silent', 'slow_drive'])
def test_the_drive_never_waits_longer_than_the_rule_says(pattern, neighbour_model, feeder_hz,
                                                         neighbour_hz):
    gap, largest_s, tripped = run_line(pattern, neighbour_model, feeder_hz, neighbour_hz)
    print(f'rule {gap.gap_s:.2f} s ({gap.explain()}), measured {largest_s:.2f} s')
    assert largest_s <= gap.gap_s, gap.explain()
    assert not tripped
