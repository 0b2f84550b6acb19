"""
Late replies on real ptys and TCP: a reply counts only when it answers its own request.

A scripted device (test/late_line.py) answers after the master's timeout, holds a reply
until the next request, or puts another unit's frame on the line. Whatever it does, the
transports of every wire (Modbus RTU on a pty and over TCP, AP ASCII, the FC protocol) return
the answer to the request just sent or fail; they never return another request's values,
and every frame they discard is counted against the unit it names (issue 40).
"""

from contextlib import contextmanager
from dataclasses import replace

from drive_bridge.bus.events import DeviceOffline, ReadingEvent
from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices.mcd import McdProfile
from drive_bridge.errors import AmbiguousReply, BadFrame, NoResponse, TransportError
from drive_bridge.protocol import ap_ascii, rtu
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.requests import AsciiCommand, ReadRegisters, WriteRegister
from drive_bridge.sim.faults import FaultPlan
from drive_bridge.sim.mcd_device import make_mcd_server
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from integration_helpers import wait_until
from late_line import (
    answer_of, ascii_requests, fc_requests, registers_of, rtu_requests, ScriptedDeviceLine)
import pytest

TIMEOUT_S = 0.15
ACK = bytes([ap_ascii.ACK])


@contextmanager
def scripted(script, decode=rtu_requests, tcp=False, **settings):
    """Yield (connected transport, line) with a device answering by ``script(line, i, req)``."""
    holder = {}
    line = ScriptedDeviceLine(decode, lambda index, request: script(holder['line'], index,
                                                                    request), tcp=tcp)
    holder['line'] = line
    values = {'timeout_s': TIMEOUT_S, 'parity': 'N'}
    values.update(settings)
    if tcp:
        values.update(protocol='rtu_over_tcp', tcp_port=line.tcp_port)
    else:
        values.update(port=line.path)
    transport = make_transport(LinkSettings(**values))
    transport.connect()
    try:
        yield transport, line
    finally:
        transport.close()
        line.close()


def outcome(transport, unit, request):
    """Return what ``execute`` returned, or the TransportError it raised."""
    try:
        return transport.execute(unit, request)
    except TransportError as error:
        return error


def late_units(transport):
    return [frame.unit for frame in transport.last_report.late]


def values_of(request: ReadRegisters):
    return [1000 + request.address + i for i in range(request.count)]


# -- Modbus RTU ---------------------------------------------------------------------------
def test_a_steady_lag_never_returns_another_reads_values_and_each_late_reply_is_counted():
    """Every reply comes 20 ms after the timeout: 20 reads of distinct blocks all fail."""
    def lagging(line, index, request):
        return [(TIMEOUT_S + 0.02, answer_of(request))]
    counted = 0
    with scripted(lagging) as (transport, line):
        for block in range(20):
            result = outcome(transport, 20, ReadRegisters(10 * block, 3))
            assert isinstance(result, NoResponse), f'read {block} returned {result}'
            counted += late_units(transport).count(20)
    assert counted == 20  # each late reply read, discarded and counted in its quarantine


def hold_first(replies_after_s):
    """
    Return a script that holds the replies to all requests but the last.

    They go out when the last request comes, then its own answer ``replies_after_s[-1]``
    later: a device or gateway that holds replies.
    """
    held = []

    def script(line, index, request):
        if index < len(replies_after_s) - 1:
            held.append(answer_of(request))
            return []
        return [(0.0, b''.join(held)), (replies_after_s[-1], answer_of(request))]
    return script


@pytest.mark.parametrize('after_s', [0.0, 0.001, 0.005, 0.02])
def test_a_held_reply_then_ours_is_ours_or_an_error_never_stale(after_s):
    with scripted(hold_first([None, after_s])) as (transport, line):
        assert isinstance(outcome(transport, 20, ReadRegisters(2, 6)), NoResponse)
        second = ReadRegisters(10, 6)
        result = outcome(transport, 20, second)
    assert result == values_of(second) or isinstance(result, BadFrame), result
    assert result != values_of(ReadRegisters(2, 6))


def test_three_replies_at_once_are_ours_or_an_error_never_stale():
    with scripted(hold_first([None, None, 0.002])) as (transport, line):
        assert isinstance(outcome(transport, 20, ReadRegisters(2, 6)), NoResponse)
        assert isinstance(outcome(transport, 20, ReadRegisters(30, 6)), NoResponse)
        result = outcome(transport, 20, ReadRegisters(10, 6))
    assert isinstance(result, BadFrame), result  # ambiguous, or one corrupt frame


def test_another_units_frame_ahead_of_the_write_echo_is_counted_and_the_write_done():
    late = registers_of(rtu.read_registers_request(21, 2, 3))

    def echoing(line, index, request):  # the adapter's echo, after a frame already on the line
        return [(0.0, late + request.encode()), (0.01, answer_of(request))]
    with scripted(echoing, local_echo=True) as (transport, line):
        assert transport.execute(20, WriteRegister(1, 1)) is None
        assert late_units(transport) == [21]


def test_of_two_identical_writes_the_one_whose_echo_came_with_a_held_one_is_unanswered():
    with scripted(hold_first([None, 0.005])) as (transport, line):
        assert isinstance(outcome(transport, 20, WriteRegister(1, 1)), NoResponse)
        result = outcome(transport, 20, WriteRegister(1, 1))
    assert isinstance(result, AmbiguousReply), result


def test_a_late_reply_of_another_unit_leaves_ours_taken_and_is_counted_against_it():
    def script(line, index, request):
        if index == 0:
            return [(TIMEOUT_S + 0.3, answer_of(request))]  # after its own guard
        return [(0.02, answer_of(request))]
    with scripted(script, reply_guard_s=0.05) as (transport, line):
        assert isinstance(outcome(transport, 21, ReadRegisters(2, 3)), NoResponse)
        # the late reply of 21 comes 0.3 s after the timeout, in one of these transactions
        results = [outcome(transport, 20, ReadRegisters(10 * i, 3)) for i in range(1, 6)]
    assert all(result == values_of(ReadRegisters(10 * i, 3)) or isinstance(result, BadFrame)
               for i, result in zip(range(1, 6), results)), results
    assert any(isinstance(result, list) for result in results)


# -- RTU over TCP -------------------------------------------------------------------------
def test_rtu_over_tcp_a_late_reply_between_transactions_is_never_the_next_answer():
    """It arrives 50 ms before the next request: discarded, counted, the line quarantined."""
    def script(line, index, request):
        if index == 0:
            return [(TIMEOUT_S + 0.05, answer_of(request))]
        return [(0.01, answer_of(request))]
    with scripted(script, tcp=True, reply_guard_s=0.01) as (transport, line):
        assert isinstance(outcome(transport, 20, ReadRegisters(2, 6)), NoResponse)
        assert wait_until(lambda: line.written, 2.0)  # on the socket before the next request
        second = ReadRegisters(10, 6)
        assert transport.execute(20, second) == values_of(second)
        assert late_units(transport) == [20]


def test_rtu_over_tcp_a_held_reply_with_ours_is_an_error_never_stale():
    with scripted(hold_first([None, 0.005]), tcp=True) as (transport, line):
        assert isinstance(outcome(transport, 20, ReadRegisters(2, 6)), NoResponse)
        result = outcome(transport, 20, ReadRegisters(10, 6))
    assert isinstance(result, BadFrame), result


def test_rtu_over_tcp_another_units_late_frame_does_not_lose_ours():
    late = registers_of(rtu.read_registers_request(21, 2, 3))

    def script(line, index, request):
        return [(0.005, late), (0.05, answer_of(request))]
    with scripted(script, tcp=True) as (transport, line):
        request = ReadRegisters(10, 6)
        assert transport.execute(20, request) == values_of(request)
        assert late_units(transport) == [21]


# -- AP ASCII: replies name no unit ---------------------------------------------------------
def ascii_script(late_b10_s):
    """Return a starter that ACKs all: B10's ACK held (None) or ``late_b10_s`` late."""
    def script(line, index, fragment):
        if fragment.kind == 'message' and fragment.code == 'B10':
            if late_b10_s is None:
                line.held += ACK
                return []
            return [(late_b10_s, ACK)]
        return [(0.01, ACK)]
    return script


def test_a_stop_after_a_start_whose_ack_was_held_is_not_acknowledged():
    with scripted(ascii_script(None), ascii_requests, protocol='ap_ascii',
                  timeout_s=0.25) as (transport, line):
        assert isinstance(outcome(transport, 20, AsciiCommand('B10')), NoResponse)
        result = outcome(transport, 20, AsciiCommand('B12'))
        b12_sent = [fragment for _, fragment in line.requests
                    if fragment.kind == 'message' and fragment.code == 'B12']
    assert isinstance(result, AmbiguousReply), result  # two ACKs to the address
    assert b12_sent == []  # and the stop's own fragment never went out


def test_a_start_whose_ack_came_late_leaves_the_stop_to_its_own_ack():
    with scripted(ascii_script(0.25 + 0.05), ascii_requests, protocol='ap_ascii',
                  timeout_s=0.25) as (transport, line):
        assert isinstance(outcome(transport, 20, AsciiCommand('B10')), NoResponse)
        assert late_units(transport) == [None]  # the late ACK, read in the quarantine
        assert transport.execute(20, AsciiCommand('B12')) is None


# -- FC protocol: process data echoes nothing -------------------------------------------------
def fc_answer(telegram: fc_telegram.FcTelegram) -> bytes:
    return fc_telegram.reply_to(telegram, 0x0607, telegram.pcd2).encode()  # MAV = the reference


def test_late_fc_process_data_is_never_taken():
    def script(line, index, telegram):
        if index == 0:
            line.held += fc_answer(telegram)
            return []
        return [(0.01, fc_answer(telegram))]
    with scripted(script, fc_requests, protocol='fc_protocol') as (transport, line):
        assert isinstance(outcome(transport, 1, fc_telegram.process_request(0x047C, 0x1111)),
                          NoResponse)
        result = outcome(transport, 1, fc_telegram.process_request(0x047C, 0x2222))
    assert isinstance(result, AmbiguousReply), result


def test_a_late_fc_reply_in_the_guard_is_discarded_and_the_next_answer_is_its_own():
    def script(line, index, telegram):
        delay_s = TIMEOUT_S + 0.02 if index == 0 else 0.01
        return [(delay_s, fc_answer(telegram))]
    with scripted(script, fc_requests, protocol='fc_protocol') as (transport, line):
        assert isinstance(outcome(transport, 1, fc_telegram.process_request(0x047C, 0x1111)),
                          NoResponse)
        assert late_units(transport) == [1]
        assert transport.execute(1, fc_telegram.process_request(0x047C, 0x2222)).pcd2 == 0x2222


# -- the bus against the simulator's late replies ---------------------------------------------
def test_a_device_that_answers_only_late_goes_offline_publishes_nothing_and_comes_back():
    """Every reply of one starter comes 20 ms after the timeout; the other keeps its rate."""
    server = make_mcd_server({20: 'mcd500', 21: 'mcd202'})
    server.open_pty()
    server.start()
    events = []
    specs = [DeviceSpec('lagging', 20, McdProfile('mcd500'), poll_rate_hz=10.0),
             DeviceSpec('other', 21, McdProfile('mcd202'), poll_rate_hz=10.0)]
    bus = BusMaster(make_transport(LinkSettings(port=server.pty_path, parity='N',
                                                timeout_s=TIMEOUT_S)),
                    specs, BusTiming(backoff_max_s=0.5), listener=events.append).start()
    try:
        assert wait_until(lambda: bus.snapshot('lagging').online, 5.0)
        lag = FaultPlan(1.0, ('late',), master_timeout_s=TIMEOUT_S, late_s=0.02,
                        units=frozenset({20}))
        server.faults.set_plan(lag)
        lag_began = len(events)
        assert wait_until(lambda: went_offline(events, 'lagging', lag_began) is not None, 10.0)
        offline = went_offline(events, 'lagging', lag_began)
        assert wait_until(lambda: int(bus.snapshot('lagging').stats['late_replies']) >= 5, 10.0)
        readings = [event for event in events[offline:] if isinstance(event, ReadingEvent)]
        assert [event.device for event in readings if event.device == 'lagging'] == []
        assert sum(event.device == 'other' for event in readings) >= 10
        during = [event for event in events[lag_began:offline]
                  if isinstance(event, ReadingEvent) and event.device == 'lagging']
        assert len(during) <= 1  # at most the poll cycle that was on the wire when it began
        server.faults.set_plan(replace(lag, rate=0.0))  # the lag ends
        assert wait_until(lambda: bus.snapshot('lagging').online is True, 10.0)
    finally:
        bus.shutdown(stop_motors=False)
        server.stop()


def went_offline(events, name: str, since: int):
    """Return the index of the first DeviceOffline of ``name`` from ``since`` on, or None."""
    for index in range(since, len(events)):
        if isinstance(events[index], DeviceOffline) and events[index].device == name:
            return index
    return None
