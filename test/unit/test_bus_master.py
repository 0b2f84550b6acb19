"""Unit tests of the bus master with a fake clock and a fake transport (no threads)."""

import re

from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.bus.motor import Motion
from drive_bridge.devices import mcd
from drive_bridge.errors import (
    BadFrame, CommandRefused, DeviceException, LinkDown, NoResponse, TransportError)
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from drive_bridge.transport.base import Transport
from drive_bridge.transport.link import LinkSettings
from fakes import FakeClock, kind, run_for
import pytest

TIMEOUT_S = 0.5
RTT_S = 0.02


class FakeTransport(Transport):
    """Devices by unit: a status word to report, or an error to raise."""

    def __init__(self, clock):
        super().__init__(LinkSettings())
        self.clock = clock
        self._connected = False
        self.link_ok = True
        self.status = {}
        self.failures = {}
        self.write_error = {}
        self.log = []

    @property
    def connected(self):
        return self._connected

    def connect(self):
        if not self.link_ok:
            raise LinkDown('bus offline: /dev/ttyFAKE not found')
        self._connected = True

    def close(self):
        self._connected = False

    def execute(self, unit, transaction):
        self.log.append((self.clock.now, unit, transaction))
        failure = self.failures.get(unit)
        if failure is not None:
            self.clock.now += TIMEOUT_S if isinstance(failure, NoResponse) else RTT_S
            if isinstance(failure, LinkDown):
                self._connected = False
            raise failure
        self.clock.now += RTT_S
        if isinstance(transaction, WriteRegister):
            if unit in self.write_error:
                raise self.write_error[unit]
            return None
        assert transaction == ReadRegisters(2, 6)
        return [self.status.get(unit, 1), 255, 0, 0, (7 << 3) | 1, 1]

    def polls(self, unit):
        return [t for t, u, txn in self.log if u == unit and isinstance(txn, ReadRegisters)]


def make_bus(units, rates=None, timing=None, allow=None, transport_type=None):
    clock = FakeClock()
    transport = (transport_type or FakeTransport)(clock)
    events = []
    specs = [DeviceSpec(f'd{unit}', unit, mcd.McdProfile('mcd500'),
                        poll_rate_hz=(rates or {}).get(unit, 5.0),
                        allow_control=(allow or {}).get(unit, True)) for unit in units]
    bus = BusMaster(transport, specs, timing or BusTiming(), listener=events.append,
                    clock=clock, sleep=clock.sleep)
    return bus, transport, clock, events


def test_each_device_polled_at_its_rate():
    bus, transport, clock, _ = make_bus([1, 2], rates={1: 5.0, 2: 1.0})
    run_for(bus, clock, 10.0)
    assert len(transport.polls(1)) in (50, 51)
    assert len(transport.polls(2)) in (10, 11)


def test_reading_events_carry_decoded_state():
    bus, transport, clock, events = make_bus([1])
    transport.status[1] = 3
    run_for(bus, clock, 0.1)
    assert [kind(e) for e in events] == ['online', 'reading']
    assert events[1].reading.state == 'running'
    assert bus.snapshot('d1').online is True


def test_command_goes_before_waiting_polls_and_is_acknowledged():
    bus, transport, clock, _ = make_bus([1, 2])
    run_for(bus, clock, 0.5)
    clock.now += 1.0  # both devices now have a poll waiting
    future = bus.submit_command('d1', 'start')
    bus.run_once()
    assert transport.log[-1][2] == WriteRegister(1, 1)
    assert future.result(timeout=0) == 'start acknowledged by d1 (address 1)'
    assert bus.snapshot('d1').holds_run


def test_a_command_that_comes_in_the_frame_gap_goes_before_the_poll_that_was_next():
    gap_s = 0.004
    bus, transport, clock, _ = make_bus([1, 2], rates={1: 100.0, 2: 100.0},
                                        timing=BusTiming(frame_gap_s=gap_s))
    run_for(bus, clock, 0.5)
    clock.now += 1.0  # both devices due: the bus is busy
    logged = len(transport.log)
    while len(transport.log) == logged:
        assert bus.run_once() == 0.0  # a poll: the gap starts at its reply's end
    polled_s = transport.log[-1][0]
    wait_s = bus.run_once()  # nothing is chosen while the gap runs
    assert 0 < wait_s <= gap_s and len(transport.log) == logged + 1
    clock.now += wait_s / 2
    future = bus.submit_command('d1', 'start')  # comes in the gap
    run_for(bus, clock, 0.05)
    assert future.result(timeout=0) == 'start acknowledged by d1 (address 1)'
    # The start went right after the poll's reply and the gap: before the poll that was next.
    sent_s, _, request = transport.log[logged + 1]
    assert request == WriteRegister(1, 1)
    assert sent_s - polled_s == pytest.approx(RTT_S + gap_s)
    assert [txn for _, _, txn in transport.log].count(WriteRegister(1, 1)) == 1


def test_dead_device_goes_offline_and_costs_one_timeout_per_backoff():
    timing = BusTiming(retries=2, offline_after=3, backoff_initial_s=1.0, backoff_max_s=8.0)
    bus, transport, clock, events = make_bus([1, 2], timing=timing)
    run_for(bus, clock, 1.0)
    transport.failures[2] = NoResponse('no reply within 0.5 s')
    run_for(bus, clock, 60.0)
    offline = [e for e in events if kind(e) == 'offline']
    assert [e.device for e in offline] == ['d2']
    attempts = [t for t in transport.polls(2) if t > 1.0]
    # 3 attempts to go offline, then probes 1, 2, 4, 8, 8, ... s apart: one timeout each.
    gaps = [b - a for a, b in zip(attempts[3:], attempts[4:])]
    assert len(attempts) < 3 + 12
    assert all(gap >= 1.0 for gap in gaps)
    assert max(gaps) <= 8.0 + TIMEOUT_S + 2 * RTT_S + 0.3


def test_healthy_device_keeps_its_rate_while_another_is_dead():
    bus, transport, clock, _ = make_bus([1, 2], rates={1: 5.0, 2: 5.0})
    transport.failures[2] = NoResponse('no reply')
    run_for(bus, clock, 30.0)
    polls = transport.polls(1)
    longest_gap = max(b - a for a, b in zip(polls, polls[1:]))
    # at most one poll period plus the one retry chain before going offline (3 timeouts)
    assert longest_gap <= 0.2 + 3 * TIMEOUT_S + 0.1
    late = [t for t in polls if t > 5.0]
    late_gap = max(b - a for a, b in zip(late, late[1:]))
    assert late_gap <= 0.2 + TIMEOUT_S + 0.05  # offline: at most one timeout in the way


def test_device_comes_back_online():
    bus, transport, clock, events = make_bus([1])
    transport.failures[1] = NoResponse('no reply')
    run_for(bus, clock, 5.0)
    del transport.failures[1]
    run_for(bus, clock, 10.0)
    kinds = [kind(e) for e in events if kind(e) != 'reading']
    assert kinds == ['offline', 'online']
    assert bus.snapshot('d1').online is True


def test_single_bad_frame_is_retried_not_offline():
    bus, transport, clock, events = make_bus([1])
    run_for(bus, clock, 0.5)
    transport.failures[1] = BadFrame('CRC')
    clock.now += 0.2  # the next poll is due
    for _ in range(3):  # one attempt a step: commands may go between them
        bus.run_once()
    assert bus.snapshot('d1').stats['retries'] == '2'
    assert bus.snapshot('d1').stats['errors_bad_frame'] == '3'


def test_a_retry_that_succeeds_keeps_the_device_online_and_publishes_its_reading():
    bus, transport, clock, events = make_bus([1])
    run_for(bus, clock, 0.5)
    transport.failures[1] = BadFrame('CRC')
    clock.now += 0.2
    bus.run_once()  # the first attempt fails
    del transport.failures[1]
    readings = len([e for e in events if kind(e) == 'reading'])
    bus.run_once()  # the retry gets the reply
    bus.run_once()  # the cycle ends: its reading is decoded
    assert bus.snapshot('d1').online is True and bus.snapshot('d1').stats['retries'] == '1'
    assert len([e for e in events if kind(e) == 'reading']) == readings + 1


def test_lost_link_marks_everything_offline_at_once_and_reconnects():
    bus, transport, clock, events = make_bus([1, 2])
    run_for(bus, clock, 0.5)
    transport.failures[1] = LinkDown('bus offline: /dev/ttyFAKE not found')
    transport.link_ok = False
    run_for(bus, clock, 0.3)
    offline = {e.device for e in events if kind(e) == 'offline'}
    assert offline == {'d1', 'd2'}
    refused = bus.submit_command('d2', 'start')
    with pytest.raises(CommandRefused, match='not found: nothing sent'):
        refused.result(timeout=0)
    del transport.failures[1]
    transport.link_ok = True
    run_for(bus, clock, 12.0)
    assert bus.snapshot('d1').online and bus.snapshot('d2').online
    assert bus.link_error == ''


def test_commands_refused_before_sending():
    bus, transport, clock, _ = make_bus([1, 2, 3], allow={2: False})
    transport.failures[3] = NoResponse('no reply')
    run_for(bus, clock, 3.0)
    writes_before = [x for x in transport.log if isinstance(x[2], WriteRegister)]
    cases = {
        ('d2', 'start'): 'monitor only (allow_control is false): nothing sent',
        ('d3', 'start'): 'is offline',
        ('nope', 'start'): "unknown device 'nope'",
        ('d1', 'coast_stop'): 'no coast_stop command',
    }
    for (name, command), text in cases.items():
        with pytest.raises(CommandRefused, match=re.escape(text)):
            bus.submit_command(name, command).result(timeout=0)
    transport.status[1] = 6
    run_for(bus, clock, 0.5)
    with pytest.raises(CommandRefused, match='tripped .* reset it first'):
        bus.submit_command('d1', 'start').result(timeout=0)
    assert [x for x in transport.log if isinstance(x[2], WriteRegister)] == writes_before


def test_device_refusal_is_reported_in_technician_words():
    bus, transport, clock, _ = make_bus([1])
    run_for(bus, clock, 0.3)
    transport.write_error[1] = DeviceException(9)
    future = bus.submit_command('d1', 'start')
    bus.run_once()
    with pytest.raises(CommandRefused) as error:
        future.result(timeout=0)
    assert str(error.value) == ('rejected by d1: network control disabled (Hand On mode or '
                                'par. 3-2); set the starter to Auto On and par. 3-2 Comms in '
                                'Remote to enable (unsupported command), Modbus error 09')
    assert not bus.snapshot('d1').holds_run


def test_unacknowledged_command_is_not_repeated():
    bus, transport, clock, _ = make_bus([1])
    run_for(bus, clock, 0.3)
    transport.write_error[1] = NoResponse('no reply within 0.5 s')
    future = bus.submit_command('d1', 'start')
    run_for(bus, clock, 0.05)
    with pytest.raises(TransportError, match='may or may not have been executed'):
        future.result(timeout=0)
    writes = [x for x in transport.log if isinstance(x[2], WriteRegister)]
    assert len(writes) == 1
    snapshot = bus.snapshot('d1')
    assert snapshot.holds_run and snapshot.motion is Motion.MAY_RUN  # stop on shutdown


def test_parameter_read_and_write_jobs():
    bus, transport, clock, _ = make_bus([1])
    run_for(bus, clock, 0.3)
    write = bus.write_parameter('d1', 4, 400)
    bus.run_once()
    assert transport.log[-1][2] == WriteRegister(11, 400)
    assert 'acknowledged' in write.result(timeout=0)
    with pytest.raises(CommandRefused, match='out of range'):
        bus.read_parameter('d1', 0).result(timeout=0)


def test_statistics_count_transactions_and_round_trip():
    bus, transport, clock, _ = make_bus([1])
    run_for(bus, clock, 1.0)
    stats = bus.snapshot('d1').stats
    assert int(stats['transactions']) >= 5
    assert stats['rtt_avg_ms'] == '20.0' and stats['errors'] == '0'


def test_an_unexpected_error_on_the_bus_thread_reports_the_bus_offline_and_reopens_it():
    bus, transport, clock, events = make_bus([20])
    run_for(bus, clock, 0.5)
    assert bus.snapshot('d20').online is True
    transport.failures[20] = RuntimeError('termios said no')  # not a TransportError
    with pytest.raises(RuntimeError) as raised:
        for _ in range(100):
            clock.sleep(bus.run_once())
    wait_s = bus._internal_error(raised.value)  # what the bus thread does with it
    assert wait_s > 0 and bus.internal_errors == 1 and not transport.connected
    offline = [event for event in events if kind(event) == 'offline']
    assert offline and 'internal error (RuntimeError: termios said no)' in offline[0].message
    transport.failures.clear()
    run_for(bus, clock, 2.0)
    assert bus.snapshot('d20').online is True  # reopened with backoff, polled again


class ReportingTransport(FakeTransport):
    """A transport that reports each request sent, as the serial engines do."""

    reports_request_sent = True

    def __init__(self, clock):
        super().__init__(clock)
        self.timeline = []  # ('sent', unit, time) and what the listener is given

    def execute(self, unit, transaction):
        self.timeline.append(('sent', unit, self.clock.now))
        self.on_request_sent()
        return super().execute(unit, transaction)


def make_reporting_bus(rates, timing=None):
    """Return (bus, clock, timeline): requests sent and events given, in order, with times."""
    bus, transport, clock, _ = make_bus(list(rates), rates, timing or BusTiming(
        frame_gap_s=0.004), transport_type=ReportingTransport)
    timeline = transport.timeline
    bus.listener = lambda event: timeline.append((kind(event), event.device, clock.now))
    return bus, clock, timeline


def test_on_a_busy_line_events_go_out_while_the_next_request_is_on_the_wire():
    # Both devices as fast as the line allows: a transaction follows every gap.
    bus, clock, timeline = make_reporting_bus({1: 100.0, 2: 100.0})
    run_for(bus, clock, 0.5)
    events = [index for index, entry in enumerate(timeline) if entry[0] != 'sent']
    assert len(events) > 20
    for index in events:  # given out as a request left (same time), never in a gap
        sent = max(i for i in range(index) if timeline[i][0] == 'sent')
        assert timeline[index][2] == timeline[sent][2]
    kinds = [(kind, device) for kind, device, _ in timeline if kind != 'sent']
    assert kinds[:4] == [('online', 'd1'), ('reading', 'd1'), ('online', 'd2'),
                         ('reading', 'd2')]  # in the order they happened
    # d1's first reading went out with the second request on the line (d2's poll).
    first = next(i for i, entry in enumerate(timeline) if entry[:2] == ('reading', 'd1'))
    assert [entry[:2] for entry in timeline[:first] if entry[0] == 'sent'] == \
        [('sent', 1), ('sent', 2)]


def test_on_an_idle_line_events_go_out_before_the_bus_waits_for_the_next_poll():
    bus, clock, timeline = make_reporting_bus({1: 5.0})
    run_for(bus, clock, 1.0)
    sends = [entry for entry in timeline if entry[0] == 'sent']
    readings = [entry for entry in timeline if entry[0] == 'reading']
    assert len(sends) == len(readings) == 5
    for sent, reading in zip(sends, readings):  # its own poll's, 0.2 s before the next one
        assert 0 < reading[2] - sent[2] < 0.1


def test_events_still_queued_go_out_at_shutdown():
    bus, clock, timeline = make_reporting_bus({1: 100.0, 2: 100.0})
    while bus.snapshot('d2').reading is None:  # until d2's first poll has ended
        clock.sleep(bus.run_once())
    assert ('reading', 'd2') not in [entry[:2] for entry in timeline]  # no request since
    bus.shutdown(stop_motors=False)
    assert ('reading', 'd2') in [entry[:2] for entry in timeline]


def test_slow_publishing_neither_counts_as_round_trip_nor_delays_the_next_poll():
    # The listener takes 30 ms an event (a loaded machine publishing): on a busy line that
    # happens while a request is on the wire, on an idle one before the bus waits.
    for rates in ({1: 100.0, 2: 100.0}, {1: 5.0}):
        bus, clock, timeline = make_reporting_bus(rates)
        slow = bus.listener

        def listener(event):
            slow(event)
            clock.sleep(0.03)
        bus.listener = listener
        run_for(bus, clock, 2.0)
        assert bus.snapshot('d1').stats['rtt_max_ms'] == '20.0'
        if rates == {1: 5.0}:
            sends = [entry[2] for entry in timeline if entry[0] == 'sent']
            assert [round(b - a, 6) for a, b in zip(sends, sends[1:])] == [0.2] * (len(sends) - 1)


def test_stop_all_while_the_link_is_down_says_why_each_motor_was_not_stopped():
    bus, transport, clock, _ = make_bus([1, 2])
    run_for(bus, clock, 0.5)
    start = bus.submit_command('d1', 'start')
    run_for(bus, clock, 0.5)
    assert 'acknowledged' in start.result(timeout=0) and bus.snapshot('d1').holds_run
    transport.failures[2] = LinkDown('bus offline: /dev/ttyFAKE not found')
    transport.link_ok = False
    run_for(bus, clock, 0.5)  # the link is lost and cannot be opened again
    assert bus.link_error
    outcomes = bus.stop_all('shutdown')
    assert outcomes == ['d1: NOT STOPPED: bus offline: /dev/ttyFAKE not found']


class SilentDeviceTransport(ReportingTransport):
    """Reports a request sent only to a device that answers (as a step failing before)."""

    def execute(self, unit, transaction):
        if unit in self.failures:
            return FakeTransport.execute(self, unit, transaction)
        return super().execute(unit, transaction)


def test_events_a_step_did_not_carry_out_go_right_after_it():
    bus, transport, clock, _ = make_bus([1, 2], timing=BusTiming(frame_gap_s=0.004),
                                        transport_type=SilentDeviceTransport)
    transport.failures[2] = NoResponse('no reply within 0.5 s')
    delays = []
    bus.listener = lambda event: delays.append(clock.now - event.stamp_s) \
        if kind(event) == 'reading' else None
    run_for(bus, clock, 6.0)
    assert len(delays) > 10
    assert max(delays) <= TIMEOUT_S + 0.01  # one failed attempt, not every retry of it
