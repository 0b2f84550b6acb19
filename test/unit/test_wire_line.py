"""Unit tests of the wire pacer's timing model, with the time passed in (a fake clock)."""

from drive_bridge.protocol import rtu
from drive_bridge.sim.cli import parse_pace
from drive_bridge.sim.wire_pacer import (
    COLLISION, GAP_VIOLATION, GLUED, LineTiming, MASTER, OK, SLAVE, transactions, wire_fraction,
    WireFrame, WireLine)
import pytest

TIMING = LineTiming(9600, 'E', 1)  # 11 bits a character
CHAR_S = 11 / 9600
GAP_S = 3.5 * CHAR_S
REQUEST = rtu.read_registers_request(20, 2, 6).encode()  # 8 bytes
REPLY = rtu.registers_response(20, 3, [1, 2, 3, 4, 5, 6]).encode()  # 17 bytes
EPS = 1e-9  # byte times add up one by one: allow for rounding at exact boundaries


def received(line, now_s):
    """Return what each side has received by ``now_s`` as a dict."""
    result = {MASTER: b'', SLAVE: b''}
    for side, data in line.take_due(now_s):
        result[side] += data
    return result


def transaction(line, start_s, request=REQUEST, reply=REPLY):
    """Run one request/reply with the slave answering as soon as it has the request."""
    line.transmit(MASTER, request, start_s)
    handed_s = line.next_due_s()
    assert received(line, handed_s)[SLAVE] == request
    line.transmit(SLAVE, reply, handed_s)
    reply_end_s = handed_s + len(reply) * CHAR_S + EPS
    assert received(line, reply_end_s)[MASTER] == reply
    return reply_end_s


def test_character_times_and_gaps():
    assert TIMING.char_s == pytest.approx(CHAR_S)
    assert LineTiming(9600, 'N', 2).char_s == pytest.approx(CHAR_S)  # 8N2: 11 bits too
    assert LineTiming(9600, 'N', 1).char_s == pytest.approx(10 / 9600)  # 8N1: 10 bits
    assert TIMING.gap_s == pytest.approx(GAP_S)
    assert TIMING.inner_gap_s == pytest.approx(1.5 * CHAR_S)
    assert LineTiming(38400).gap_s == pytest.approx(0.00175)  # fixed above 19200 baud
    assert LineTiming(38400).inner_gap_s == pytest.approx(0.00075)
    assert TIMING.transaction_s(8, 17) == pytest.approx(25 * CHAR_S + 2 * GAP_S)
    assert LineTiming(19200, gap_rule=False).describe() == \
        '19200 baud 8E1 (11 bits), gap rule off'
    for bad in ({'baudrate': 0}, {'baudrate': 9600, 'parity': 'X'},
                {'baudrate': 9600, 'stopbits': 3}):
        with pytest.raises(ValueError):
            LineTiming(**bad)


def test_an_fc_protocol_line_takes_a_frame_after_two_characters_not_fewer():
    fc_timing = LineTiming(9600, 'E', 1, gap_characters=2)
    assert fc_timing.gap_s == pytest.approx(2 * CHAR_S)
    assert fc_timing.transaction_s(16, 16) == pytest.approx(36 * CHAR_S)
    assert LineTiming(38400, gap_characters=2).gap_s == pytest.approx(2 * 11 / 38400)
    line = WireLine(fc_timing)
    reply_end_s = transaction(line, 0.0)
    line.transmit(MASTER, REQUEST, reply_end_s + 2 * CHAR_S)  # the FC protocol's pause
    assert line.counters.gap_violations == 0
    line = WireLine(fc_timing)
    reply_end_s = transaction(line, 0.0)
    line.transmit(MASTER, REQUEST, reply_end_s + 1.5 * CHAR_S)  # short of it
    assert line.counters.gap_violations == 1


def test_a_slave_gets_the_request_after_its_wire_time_and_the_gap():
    line = WireLine(TIMING)
    line.transmit(MASTER, REQUEST, 1.0)
    end_s = 1.0 + 8 * CHAR_S
    assert line.next_due_s() == pytest.approx(end_s + GAP_S)
    assert received(line, end_s + GAP_S - 1e-6) == {MASTER: b'', SLAVE: b''}
    assert received(line, end_s + GAP_S + EPS)[SLAVE] == REQUEST
    assert line.next_due_s() is None
    assert line.frames() == [WireFrame(MASTER, 1.0, pytest.approx(end_s), REQUEST, OK)]


def test_the_master_gets_each_byte_as_it_leaves_the_wire():
    line = WireLine(TIMING)
    line.transmit(SLAVE, REPLY, 2.0)
    assert line.next_due_s() == pytest.approx(2.0 + CHAR_S)
    assert received(line, 2.0 + 3.5 * CHAR_S)[MASTER] == REPLY[:3]
    assert received(line, 2.0 + 16.5 * CHAR_S)[MASTER] == REPLY[3:16]
    assert received(line, 2.0 + 17 * CHAR_S + EPS)[MASTER] == REPLY[16:]


def test_batches_never_hold_back_the_last_byte():
    line = WireLine(TIMING)
    line.transmit(SLAVE, REPLY, 0.0)
    assert line.next_due_s(batch_s=0.002) == pytest.approx(CHAR_S + 0.002)
    assert line.next_due_s(batch_s=1.0) == pytest.approx(17 * CHAR_S)


def test_bytes_written_while_the_line_is_busy_queue_behind_in_one_frame():
    line = WireLine(TIMING)
    line.transmit(MASTER, REQUEST[:3], 0.0)
    line.transmit(MASTER, REQUEST[3:], CHAR_S)  # written while byte 2 is on the wire
    frames = line.frames()
    assert len(frames) == 1 and frames[0].data == REQUEST
    assert frames[0].end_s == pytest.approx(8 * CHAR_S)
    assert received(line, 8 * CHAR_S + GAP_S + EPS)[SLAVE] == REQUEST


def test_transactions_alternate_and_take_their_wire_time():
    line = WireLine(TIMING)
    now_s = 0.0
    for _ in range(3):
        now_s = transaction(line, now_s + GAP_S)
    frames = line.frames()
    assert [frame.sender for frame in frames] == [MASTER, SLAVE] * 3
    assert all(frame.fate == OK for frame in frames)
    for request, reply in transactions(frames):
        assert request.end_s - request.start_s == pytest.approx(8 * CHAR_S)
        assert reply.start_s - request.end_s == pytest.approx(GAP_S)
    counters = line.counters
    assert counters.frames == {MASTER: 3, SLAVE: 3}
    assert counters.bytes_sent == {MASTER: 24, SLAVE: 51}
    assert (counters.gap_violations, counters.collisions, counters.lost_frames) == (0, 0, 0)
    # Back to back with both gaps the line is full: exactly the wire limit.
    pairs = transactions(frames)
    assert wire_fraction(pairs, TIMING, now_s) == pytest.approx(1.0)


def test_a_request_without_the_gap_is_not_recognised():
    line = WireLine(TIMING)
    reply_end_s = transaction(line, 0.0)
    line.transmit(MASTER, REQUEST, reply_end_s + 2 * CHAR_S)  # 2 of 3.5 characters
    assert line.counters.gap_violations == 1
    assert line.frames()[-1].fate == GAP_VIOLATION
    assert line.frames()[-2].fate == OK  # the master had the reply already
    assert received(line, reply_end_s + 1.0) == {MASTER: b'', SLAVE: b''}
    # After a silence of 3.5 characters the next request is a frame again.
    line.transmit(MASTER, REQUEST, reply_end_s + 1.0)
    assert received(line, reply_end_s + 1.0 + 8 * CHAR_S + GAP_S + EPS)[SLAVE] == REQUEST
    assert line.counters.gap_violations == 1 and line.counters.lost_frames == 1


def test_the_gap_just_kept_is_enough():
    line = WireLine(TIMING)
    reply_end_s = transaction(line, 0.0)
    line.transmit(MASTER, REQUEST, reply_end_s + GAP_S)
    assert line.counters.gap_violations == 0
    assert received(line, reply_end_s + 2 * GAP_S + 8 * CHAR_S)[SLAVE] == REQUEST


def test_a_slave_that_answers_too_soon_is_not_heard_and_the_request_is_lost_too():
    line = WireLine(TIMING)
    line.transmit(MASTER, REQUEST, 0.0)
    line.transmit(SLAVE, REPLY, 8 * CHAR_S + CHAR_S)  # before the slave could have it
    assert line.counters.gap_violations == 1
    assert [frame.fate for frame in line.frames()] == [GLUED, GAP_VIOLATION]
    assert received(line, 1.0) == {MASTER: b'', SLAVE: b''}
    assert line.counters.lost_frames == 2


def test_back_to_back_requests_glue_into_one_frame_without_a_gap():
    line = WireLine(TIMING)
    line.transmit(MASTER, REQUEST, 0.0)
    line.transmit(MASTER, REQUEST, 8 * CHAR_S + 2 * CHAR_S)  # 2 characters of silence
    assert len(line.frames()) == 1 and line.frames()[0].fate == GAP_VIOLATION
    assert received(line, 1.0)[SLAVE] == b''


def test_a_short_pause_inside_a_frame_is_allowed():
    line = WireLine(TIMING)
    line.transmit(MASTER, REQUEST[:4], 0.0)
    line.transmit(MASTER, REQUEST[4:], 4 * CHAR_S + 1.0 * CHAR_S)  # under 1.5 characters
    assert received(line, 1.0)[SLAVE] == REQUEST
    assert line.counters.gap_violations == 0


def test_overlapping_frames_collide_and_both_are_lost():
    line = WireLine(TIMING)
    line.transmit(SLAVE, REPLY, 0.0)
    collision_s = 5 * CHAR_S
    line.transmit(MASTER, REQUEST, collision_s)
    line.transmit(MASTER, REQUEST, collision_s + 4 * CHAR_S)  # the same frame, queued
    assert line.counters.collisions == 1
    assert [frame.fate for frame in line.frames()] == [COLLISION, COLLISION]
    everything = received(line, 1.0)
    assert everything[MASTER] == REPLY[:5]  # the bytes before the collision arrived
    assert everything[SLAVE] == b''
    assert line.counters.lost_frames == 2 and line.counters.gap_violations == 0


def test_a_frame_started_under_a_longer_one_collides_from_its_start():
    line = WireLine(TIMING)
    line.transmit(MASTER, REQUEST, 0.0)
    line.transmit(SLAVE, b'\x01', 2 * CHAR_S)
    assert line.counters.collisions == 1
    assert received(line, 1.0) == {MASTER: b'', SLAVE: b''}


def test_without_the_gap_rule_bytes_stream_both_ways():
    line = WireLine(LineTiming(9600, 'N', 1, gap_rule=False))
    char_s = 10 / 9600
    line.transmit(MASTER, b'\x0420\x05', 0.0)  # an AP ASCII address fragment
    assert line.next_due_s() == pytest.approx(char_s)
    assert received(line, 4 * char_s)[SLAVE] == b'\x0420\x05'
    line.transmit(SLAVE, b'\x06', 4 * char_s)  # ACK at once: no gap needed
    line.transmit(MASTER, b'\x02B10', 5 * char_s + 0.1 * char_s)
    assert received(line, 5 * char_s)[MASTER] == b'\x06'
    assert [frame.sender for frame in line.frames()] == [MASTER, SLAVE, MASTER]
    assert all(frame.fate == OK for frame in line.frames())
    assert line.counters.gap_violations == 0


def test_without_the_gap_rule_collisions_still_count():
    line = WireLine(LineTiming(9600, 'N', 1, gap_rule=False))
    line.transmit(MASTER, b'abcdef', 0.0)
    line.transmit(SLAVE, b'xyz', 0.0011)  # 'a' has crossed (1.04 ms), 'b' is on the wire
    assert line.counters.collisions == 1
    assert received(line, 1.0) == {MASTER: b'', SLAVE: b'a'}


def test_the_log_keeps_the_newest_frames():
    line = WireLine(TIMING, log_size=3)
    now_s = 0.0
    for _ in range(3):
        now_s = transaction(line, now_s + GAP_S)
    frames = line.frames()
    assert len(frames) == 3
    assert [frame.sender for frame in frames] == [SLAVE, MASTER, SLAVE]
    assert line.counters.frames == {MASTER: 3, SLAVE: 3}


def test_an_endless_burst_is_logged_in_bounded_frames():
    line = WireLine(LineTiming(9600, 'N', 1, gap_rule=False))
    line.transmit(MASTER, bytes(5000), 0.0)
    assert [len(frame.data) for frame in line.frames()] == [4096, 904]
    assert len(received(line, 10.0)[SLAVE]) == 5000
    line = WireLine(TIMING)  # with the gap rule it is no frame at all
    line.transmit(MASTER, bytes(5000), 0.0)
    assert received(line, 10.0)[SLAVE] == b''


def test_transactions_skip_lost_and_unanswered_frames():
    request = WireFrame(MASTER, 0.0, 0.01, REQUEST)
    reply = WireFrame(SLAVE, 0.02, 0.04, REPLY)
    lost = WireFrame(MASTER, 0.05, 0.06, REQUEST, GAP_VIOLATION)
    assert transactions([request, reply, lost, reply, request, request, reply]) == \
        [(request, reply), (request, reply)]


def test_unknown_sender_is_refused():
    with pytest.raises(ValueError, match='sender must be'):
        WireLine(TIMING).transmit('both', b'x', 0.0)


def test_the_simulator_pace_option():
    assert parse_pace('19200:E:1') == LineTiming(19200, 'E', 1, gap_rule=True)
    assert parse_pace('9600') == LineTiming(9600, 'E', 1)
    assert parse_pace('9600:N') == LineTiming(9600, 'N', 2)  # Modbus: 8N2
    assert parse_pace('9600', 'ap_ascii') == LineTiming(9600, 'N', 1, gap_rule=False)
    for bad in ('fast', '9600:X', '9600:E:3', '9600:E:1:1', '0'):
        with pytest.raises(SystemExit, match='--pace'):
            parse_pace(bad)


# -- the ideal slave of the benches ------------------------------------------------------
def test_an_ideal_slave_gets_the_request_as_it_leaves_the_wire():
    line = WireLine(TIMING, ideal_slave=True)
    line.transmit(MASTER, REQUEST, 0.0)
    assert received(line, 4 * CHAR_S + EPS)[SLAVE] == REQUEST[:4]
    assert received(line, 8 * CHAR_S + EPS)[SLAVE] == REQUEST[4:]


def test_an_ideal_slaves_early_reply_starts_exactly_one_gap_after_the_request():
    line = WireLine(TIMING, ideal_slave=True)
    line.transmit(MASTER, REQUEST, 0.0)
    request_end_s = 8 * CHAR_S
    line.transmit(SLAVE, REPLY, request_end_s + 0.0001)  # answered at once
    request, reply = line.frames()
    assert reply.start_s == pytest.approx(request_end_s + GAP_S)
    assert (request.fate, reply.fate) == (OK, OK)
    assert received(line, reply.start_s + CHAR_S - 1e-6)[MASTER] == b''
    assert received(line, reply.end_s + EPS)[MASTER] == REPLY
    assert line.counters.gap_violations == 0


def test_an_ideal_slave_answering_late_is_not_moved_and_keeps_its_frame_whole():
    line = WireLine(TIMING, ideal_slave=True)
    line.transmit(MASTER, REQUEST, 0.0)
    line.transmit(SLAVE, REPLY[:5], 0.05)
    line.transmit(SLAVE, REPLY[5:], 0.05 + 2 * CHAR_S)  # written while its start is on
    frames = line.frames()
    assert [frame.sender for frame in frames] == [MASTER, SLAVE]
    assert frames[1].start_s == 0.05 and frames[1].data == REPLY


def test_a_master_that_skips_the_gap_still_loses_against_an_ideal_slave():
    line = WireLine(TIMING, ideal_slave=True)
    line.transmit(MASTER, REQUEST, 0.0)
    line.transmit(SLAVE, REPLY, 8 * CHAR_S)
    reply_end_s = line.frames()[-1].end_s
    assert received(line, reply_end_s + EPS)[MASTER] == REPLY
    line.transmit(MASTER, REQUEST, reply_end_s + CHAR_S)  # 1 of 3.5 characters
    assert line.frames()[-1].fate == GAP_VIOLATION
    assert received(line, 1.0)[SLAVE] == b''  # nothing of it reaches the slave
    # A request glued to the slave's held reply collides with it: both are lost.
    line = WireLine(TIMING, ideal_slave=True)
    line.transmit(MASTER, REQUEST, 0.0)
    line.transmit(SLAVE, REPLY, 8 * CHAR_S)  # held until 8 + 3.5 characters
    line.transmit(MASTER, REQUEST, 9 * CHAR_S)
    assert line.counters.collisions == 1
    assert received(line, 1.0)[MASTER] == b''
