"""
The line discipline's wire trace: each request and each frame read, with its outcome.

On a scripted line and a fake clock (:class:`fakes.ScriptedLine`): what the trace holds for
each way a transaction ends, the times of the frames, and that with no trace nothing of it
runs.
"""

from drive_bridge.errors import (
    AmbiguousReply, CrcError, LineBabble, NoResponse, TruncatedFrame, WrongAddress)
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ReadRegisters
from drive_bridge.transport import line_trace
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.packet_trace import PacketTracer
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from fakes import FakeClock, ScriptedLine
import pytest
from trace_helpers import RecordingTrace

TIMEOUT_S = 0.3
GUARD_S = 0.1
SETTINGS = LinkSettings(port='/dev/ttyTEST', baudrate=19200, parity='E', timeout_s=TIMEOUT_S,
                        reply_guard_s=GUARD_S)
TURNAROUND_S = 0.005
READ = ReadRegisters(10, 3)
REQUEST = rtu.RtuFrame(20, 3, bytes([0, 10, 0, 3])).encode().hex()


def registers(unit, values) -> bytes:
    return rtu.registers_response(unit, 3, list(values)).encode()


OURS = registers(20, [1010, 1011, 1012])
OLD = registers(20, [7, 8, 9])
OTHER = registers(21, [4, 5, 6])


def traced_line(*replies, echo=False):
    """Return (transport, line, trace): a traced RTU line whose device answers ``replies``."""
    clock = FakeClock()
    clock.now = 100.0
    queue = list(replies)
    line = ScriptedLine(clock, lambda request, now: queue.pop(0) if queue else [])
    if echo:
        device = line.device
        line.device = lambda request, now: [(0.0, request)] + device(request, now)
    settings = LinkSettings(**{**SETTINGS.__dict__, 'local_echo': echo})
    transport = RtuSerialTransport(settings, paced=False, clock=clock, line=line)
    trace = RecordingTrace()
    transport.discipline.start_trace(trace)
    transport.connect()
    return transport, line, trace


def test_a_request_and_its_answer_are_traced_ok_with_the_times_of_their_bytes():
    transport, line, trace = traced_line([(TURNAROUND_S, OURS)])
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    assert trace.rows() == [('TX', REQUEST, 'ok', 20), ('RX', OURS.hex(), 'ok', 20)]
    sent, answer = trace.records
    assert answer.start_ns - sent.start_ns == pytest.approx(TURNAROUND_S * 1e9, abs=1e3)


def test_a_frame_of_another_unit_in_the_window_is_late_and_names_its_unit():
    transport, line, trace = traced_line([(TURNAROUND_S, OTHER), (TURNAROUND_S + 0.01, OURS)])
    transport.execute(20, READ)
    assert trace.rows() == [('TX', REQUEST, 'ok', 20), ('RX', OTHER.hex(), 'late', 21),
                            ('RX', OURS.hex(), 'ok', 20)]


def test_a_bad_checksum_is_crc_on_the_request_and_the_frame():
    spoiled = OURS[:-1] + bytes([OURS[-1] ^ 0xFF])
    transport, line, trace = traced_line([(TURNAROUND_S, spoiled)])
    with pytest.raises(CrcError):
        transport.execute(20, READ)
    assert trace.rows() == [('TX', REQUEST, 'crc', 20), ('RX', spoiled.hex(), 'crc', 20)]


def test_no_reply_is_a_request_traced_timeout_and_a_late_one_in_the_guard_is_quarantined():
    transport, line, trace = traced_line([(TIMEOUT_S + 0.02, OLD)], [(TURNAROUND_S, OURS)])
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    assert trace.rows() == [('TX', REQUEST, 'timeout', 20), ('RX', OLD.hex(), 'quarantined', 20)]
    late = trace.records[1]
    assert late.start_ns - trace.records[0].start_ns == pytest.approx(
        (TIMEOUT_S + 0.02) * 1e9, abs=1e3)


def test_bytes_waiting_before_a_request_are_quarantined_before_it_goes_out():
    transport, line, trace = traced_line([(TURNAROUND_S, OURS)])
    line.arrive(0.0, OTHER + b'\x00\x01')
    transport.execute(20, READ)
    assert trace.rows() == [('RX', OTHER.hex(), 'quarantined', 21),
                            ('RX', '0001', 'quarantined', None),
                            ('TX', REQUEST, 'ok', 20), ('RX', OURS.hex(), 'ok', 20)]


def test_a_cut_reply_is_truncated_and_only_other_units_is_wrong_address():
    transport, line, trace = traced_line([(TURNAROUND_S, OURS[:6])], [(TURNAROUND_S, OTHER)])
    with pytest.raises(TruncatedFrame):
        transport.execute(20, READ)
    with pytest.raises(WrongAddress):
        transport.execute(20, READ)
    assert trace.rows() == [('TX', REQUEST, 'truncated', 20),
                            ('RX', OURS[:6].hex(), 'truncated', None),
                            ('TX', REQUEST, 'wrong_address', 20),
                            ('RX', OTHER.hex(), 'late', 21)]


def test_a_held_reply_and_the_answer_in_one_window_are_both_ambiguous():
    transport, line, trace = traced_line([], [(TURNAROUND_S, OLD), (TURNAROUND_S + 0.05, OURS)])
    with pytest.raises(NoResponse):
        transport.execute(20, ReadRegisters(2, 3))
    with pytest.raises(AmbiguousReply):
        transport.execute(20, READ)
    assert [row[2] for row in trace.rows()] == ['timeout', 'ambiguous', 'ambiguous',
                                                'ambiguous']


def test_a_babbling_line_is_traced_as_babble():
    transport, line, trace = traced_line([(TURNAROUND_S, b'\xff')])
    for step in range(1, 200):
        line.arrive(step * 0.005, b'\xff\x00')
    with pytest.raises(LineBabble):
        transport.execute(20, READ)
    outcomes = [row[2] for row in trace.rows()]
    assert outcomes[:2] == ['bad_frame', 'bad_frame'] and outcomes[-1] == 'babble'


def test_the_adapter_s_echo_is_traced_as_echo():
    transport, line, trace = traced_line([(TURNAROUND_S, OURS)], echo=True)
    transport.execute(20, READ)
    assert trace.rows() == [('TX', REQUEST, 'ok', 20), ('RX', REQUEST, 'echo', None),
                            ('RX', OURS.hex(), 'ok', 20)]


def test_with_no_trace_the_line_is_not_wrapped_and_no_tracer_code_runs(monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError('traced with the trace off')
    for name in ('window', 'discarded', 'sent', 'received'):
        monkeypatch.setattr(line_trace.LineTracer, name, never)
    clock = FakeClock()
    clock.now = 100.0
    replies = [[(TURNAROUND_S, OTHER), (0.01, OURS)], [], [(TURNAROUND_S, OURS)]]
    line = ScriptedLine(clock, lambda request, now: replies.pop(0) if replies else [])
    transport = RtuSerialTransport(SETTINGS, paced=False, clock=clock, line=line)
    transport.connect()
    assert transport.discipline.line is line and transport.discipline.tracer is None
    transport.execute(20, READ)
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    transport.execute(20, READ)


class BrokenTrace(RecordingTrace):
    """A trace whose writing fails with an error nobody foresaw."""

    def write(self, records) -> None:
        raise RuntimeError('a bug in the trace')


def test_a_failing_trace_stops_itself_and_never_changes_what_the_transaction_raises():
    spoiled = OURS[:-1] + bytes([OURS[-1] ^ 0xFF])
    transport, line, _ = traced_line([(TURNAROUND_S, spoiled)], [(TURNAROUND_S, OURS)])
    trace = BrokenTrace()
    transport.discipline.tracer.trace = trace
    with pytest.raises(CrcError):
        transport.execute(20, READ)
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    assert [str(error) for error in trace.failures] == ['a bug in the trace']


def test_a_failing_modbus_tcp_trace_stops_itself_and_lets_the_transaction_go_on():
    tracer = PacketTracer(BrokenTrace())
    adu = bytes.fromhex('000100000006140300020002')
    assert tracer.packet(True, adu) == adu
    assert tracer.packet(False, bytes.fromhex('00010000000714030400410042')) is not None
    tracer.end(20, None)  # does not raise
    assert [str(error) for error in tracer.trace.failures] == ['a bug in the trace']
    tracer.end(20, None)
    assert len(tracer.trace.failures) == 1


def test_modbus_tcp_adus_are_cut_by_their_length_and_another_id_is_late():
    trace = RecordingTrace()
    tracer = PacketTracer(trace)
    request = bytes.fromhex('000200000006140300020002')
    late = bytes.fromhex('00010000000714030400410042')
    answer = bytes.fromhex('00020000000714030400410043')
    tracer.packet(True, request)
    both = late + answer
    tracer.packet(False, both[:5])  # pymodbus 3.6 reads a header, then the rest
    tracer.packet(False, both[5:])
    tracer.end(20, None)
    assert trace.rows() == [('TX', request.hex(), 'ok', 20), ('RX', late.hex(), 'late', 20),
                            ('RX', answer.hex(), 'ok', 20)]
