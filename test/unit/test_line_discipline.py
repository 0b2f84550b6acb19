"""
The line discipline on a fake clock: every reply answers its own request (issue 40).

A scripted line (test/fakes.py ScriptedLine) delivers the device's bytes at set times after
each request; the clock moves only as the transport waits. Every rule of
drive_bridge/transport/exchange.py is checked here for Modbus RTU; the AP ASCII and FC
protocol cases check what differs (frames that name no unit, telegrams that echo nothing).
"""

from drive_bridge.errors import (
    AmbiguousReply, BadFrame, CrcError, DeviceException, LineBabble, LinkDown, MismatchedReply,
    NoResponse, TruncatedFrame, WrongAddress)
from drive_bridge.protocol import ap_ascii, rtu
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.requests import (
    AsciiCommand, AsciiRequest, ReadRegisters, WriteCoils, WriteRegister)
from drive_bridge.protocol.words import words_to_coils
from drive_bridge.transport.ap_ascii import ApAsciiTransport
from drive_bridge.transport.fc_protocol import FcProtocolTransport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from fakes import FakeClock, ScriptedLine
import pytest

TIMEOUT_S = 0.3
GUARD_S = 0.1
SETTINGS = LinkSettings(port='/dev/ttyTEST', baudrate=19200, parity='E', timeout_s=TIMEOUT_S,
                        reply_guard_s=GUARD_S)
GAP_S = SETTINGS.frame_gap_s
CHAR_S = rtu.character_time_s(19200, 'E', 1)
TURNAROUND_S = 0.005  # the simulated device answers this long after a request


def registers(unit: int, values) -> bytes:
    return rtu.registers_response(unit, 3, list(values)).encode()


def answering(*replies):
    """Return a device answering each request with the next entry: [(delay_s, bytes)]."""
    queue = list(replies)

    def device(request, now):
        return queue.pop(0) if queue else []
    return device


def rtu_line(*replies, paced=False, char_s=0.0, echo=False, settings=SETTINGS):
    """Return (transport, line, clock) with a device that answers as ``replies`` say."""
    clock = FakeClock()
    clock.now = 100.0
    line = ScriptedLine(clock, answering(*replies), char_s)
    if echo:
        device = line.device
        line.device = lambda request, now: [(0.0, request)] + device(request, now)
    settings = LinkSettings(**{**settings.__dict__, 'local_echo': echo})
    transport = RtuSerialTransport(settings, paced=paced, clock=clock, line=line)
    transport.connect()
    return transport, line, clock


def late_units(transport):
    return [frame.unit for frame in transport.last_report.late]


READ = ReadRegisters(10, 3)
OURS = registers(20, [1010, 1011, 1012])
OLD = registers(20, [7, 8, 9])  # a read of the same size, answered late


# -- the clean path ---------------------------------------------------------------------
def test_one_reply_and_the_silence_after_it_is_the_answer():
    transport, line, clock = rtu_line([(TURNAROUND_S, OURS)])
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    assert transport.last_report.late == [] and transport.last_report.noise_bytes == 0
    # the end-of-frame silence was kept and is reported, so the bus does not wait it again
    assert transport.last_report.quiet_s == pytest.approx(GAP_S)
    assert clock.now == pytest.approx(100.0 + TURNAROUND_S + GAP_S)


def test_an_exception_reply_is_a_refusal_without_a_quarantine():
    refusal = rtu.exception_response(20, 3, 2).encode()
    transport, line, clock = rtu_line([(TURNAROUND_S, refusal)], [(TURNAROUND_S, OURS)])
    with pytest.raises(DeviceException) as raised:
        transport.execute(20, READ)
    assert raised.value.code == 2
    assert clock.now == pytest.approx(100.0 + TURNAROUND_S + GAP_S)  # no guard waited
    assert transport.execute(20, READ) == [1010, 1011, 1012]


# -- one frame of the unit per window ---------------------------------------------------
def test_a_frame_of_another_unit_is_skipped_counted_and_the_line_quarantined():
    other = registers(21, [5, 6, 7])
    transport, line, clock = rtu_line([(TURNAROUND_S, other), (TURNAROUND_S + 0.01, OURS)])
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    assert late_units(transport) == [21]
    assert clock.now >= 100.0 + TURNAROUND_S + 0.01 + GUARD_S  # quarantined after it


def test_only_frames_of_other_units_is_a_wrong_address_and_the_unit_owes_a_reply():
    transport, line, clock = rtu_line([(TURNAROUND_S, registers(21, [5, 6, 7]))])
    with pytest.raises(WrongAddress, match='no reply from address 20'):
        transport.execute(20, READ)
    assert late_units(transport) == [21]
    assert 20 in set(transport.discipline.owed)


@pytest.mark.parametrize('late', [
    registers(20, [1, 2]),  # a read of another size
    rtu.write_register_request(20, 1, 1).encode(),  # the echo of a write
    rtu.exception_response(20, 6, 4).encode(),  # a refusal of another function
])
def test_a_frame_of_the_unit_that_does_not_answer_the_request_is_late(late):
    transport, line, clock = rtu_line([(TURNAROUND_S, late)])
    with pytest.raises(MismatchedReply, match='not the answer'):
        transport.execute(20, READ)
    assert late_units(transport) == [20]


def test_a_write_echo_with_another_value_is_not_the_acknowledgement():
    old_echo = rtu.write_register_request(20, 1, 2).encode()
    transport, line, clock = rtu_line([(TURNAROUND_S, old_echo)])
    with pytest.raises(MismatchedReply):
        transport.execute(20, WriteRegister(1, 1))


@pytest.mark.parametrize('later_s', [0.0, 0.001, 0.005, 0.02])
def test_a_held_reply_and_the_answer_in_one_window_fail_it_as_ambiguous(later_s):
    """A unit that owes a reply holds it until the next request: both come, neither taken."""
    transport, line, clock = rtu_line([], [(TURNAROUND_S, OLD), (TURNAROUND_S + later_s, OURS)])
    with pytest.raises(NoResponse):
        transport.execute(20, ReadRegisters(2, 3))  # the device holds this reply
    assert set(transport.discipline.owed) == {20}
    with pytest.raises(BadFrame) as raised:  # ambiguous, or one corrupt frame (0 ms)
        transport.execute(20, READ)
    assert isinstance(raised.value, AmbiguousReply) or later_s < GAP_S
    assert set(transport.discipline.owed) == set()


def test_three_replies_in_one_window_fail_it():
    transport, line, clock = rtu_line(
        [], [], [(TURNAROUND_S, OLD), (TURNAROUND_S + 0.01, OLD), (TURNAROUND_S + 0.02, OURS)])
    for _ in range(2):
        with pytest.raises(NoResponse):
            transport.execute(20, READ)
    with pytest.raises(AmbiguousReply):
        transport.execute(20, READ)
    assert late_units(transport) == [20, 20, 20]  # the third read in the quarantine


def test_a_window_of_a_unit_that_owes_a_reply_stays_open_and_one_frame_of_another_shape_is_ours():
    other_block = ReadRegisters(30, 5)
    ours = registers(20, [1, 2, 3, 4, 5])
    transport, line, clock = rtu_line([], [(TURNAROUND_S, ours)])
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    started = clock.now
    assert transport.execute(20, other_block) == [1, 2, 3, 4, 5]  # no answer to READ
    assert clock.now == pytest.approx(started + TIMEOUT_S)  # held open to the deadline
    assert set(transport.discipline.owed) == set()
    line_clean = clock.now
    line.device = answering([(TURNAROUND_S, OURS)])
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    assert clock.now < line_clean + 0.05  # no longer held open


def test_an_acknowledgement_that_would_also_acknowledge_the_owed_write_is_none():
    """A drive's next control word after a lost one: the one echo may be the held one."""
    write = WriteRegister(49999, 0x047C)
    echo = rtu.write_register_request(20, 49999, 0x047C).encode()
    transport, line, clock = rtu_line([], [(TURNAROUND_S, echo)], [(TURNAROUND_S, echo)])
    with pytest.raises(NoResponse):
        transport.execute(20, write)
    with pytest.raises(AmbiguousReply, match='would also acknowledge an earlier request'):
        transport.execute(20, write)
    assert late_units(transport) == [20] and set(transport.discipline.owed) == set()
    assert transport.execute(20, write) is None  # the debt is settled


def test_a_read_after_a_lost_read_of_the_same_block_is_its_answer_when_alone():
    """Only acknowledgements are held to the owed request: a held reply comes with ours."""
    transport, line, clock = rtu_line([], [(TURNAROUND_S, OURS)])
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    assert transport.execute(20, READ) == [1010, 1011, 1012]


def test_another_units_request_is_not_held_open_by_what_one_unit_owes():
    transport, line, clock = rtu_line([], [(TURNAROUND_S, registers(21, [1, 2, 3]))])
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    started = clock.now
    assert transport.execute(21, READ) == [1, 2, 3]
    assert clock.now < started + 0.05


# -- end of frame -----------------------------------------------------------------------
def test_bytes_right_behind_a_reply_make_it_one_corrupt_frame():
    transport, line, clock = rtu_line([(TURNAROUND_S, OURS + b'\x00\x01')])
    with pytest.raises(BadFrame, match='one corrupt frame'):
        transport.execute(20, READ)


def test_bytes_within_the_silence_after_a_reply_make_it_one_corrupt_frame():
    transport, line, clock = rtu_line([(TURNAROUND_S, OURS), (TURNAROUND_S + GAP_S / 2, OLD)])
    with pytest.raises(BadFrame, match='within the inter-frame silence'):
        transport.execute(20, READ)
    assert transport.last_report.noise_bytes == len(OURS + OLD)  # one corrupt frame


# -- quarantine -------------------------------------------------------------------------
def test_a_late_reply_in_the_guard_is_discarded_counted_and_settles_the_debt():
    transport, line, clock = rtu_line([(TIMEOUT_S + 0.02, OLD)], [(TURNAROUND_S, OURS)])
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    assert late_units(transport) == [20]
    assert clock.now == pytest.approx(100.0 + TIMEOUT_S + GUARD_S)
    assert set(transport.discipline.owed) == set()
    assert transport.execute(20, READ) == [1010, 1011, 1012]


def test_a_quarantine_lasts_until_the_line_is_silent_after_the_guard():
    transport, line, clock = rtu_line([(TIMEOUT_S + GUARD_S - 0.001, OLD)])
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    silence = transport.discipline.timing.quarantine_silence_s
    assert clock.now == pytest.approx(100.0 + TIMEOUT_S + GUARD_S - 0.001 + silence)


def test_bytes_waiting_before_a_request_are_counted_and_the_line_quarantined_first():
    transport, line, clock = rtu_line([(TURNAROUND_S, OURS)])
    line.arrive(0.0, registers(21, [4, 5, 6]))
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    assert late_units(transport) == [21]
    assert line.writes[0][0] == pytest.approx(100.0 + GUARD_S)  # sent after the quarantine


def test_a_line_that_keeps_talking_is_babble():
    transport, line, clock = rtu_line([(TURNAROUND_S, b'\xff')])
    for step in range(1, 200):
        line.arrive(step * 0.005, b'\xff\x00')
    with pytest.raises(LineBabble, match='keeps talking'):
        transport.execute(20, READ)


@pytest.mark.parametrize('reply, error, owes', [
    (OURS[:-1] + bytes([OURS[-1] ^ 0xFF]), CrcError, False),  # it answered; noise spoiled it
    (OURS[:6], TruncatedFrame, False),
    (b'\x14\x99\x00\x00\x00', BadFrame, True),  # garbage: its answer may still come
])
def test_a_bad_reply_fails_and_the_line_is_quarantined_to_the_guard_after_the_deadline(
        reply, error, owes):
    transport, line, clock = rtu_line([(TURNAROUND_S, reply)])
    with pytest.raises(error):
        transport.execute(20, READ)
    assert clock.now >= 100.0 + TIMEOUT_S + GUARD_S  # however soon the window failed
    assert (20 in transport.discipline.owed) is owes


# -- early failures (found by an adversarial review) ----------------------------------------
def device_by_index(respond):
    """Return a device answering the i-th request with ``respond(i, request)``."""
    count = [0]

    def device(request, now):
        count[0] += 1
        return respond(count[0] - 1, request)
    return device


@pytest.mark.parametrize('noise', [b'\x00' * 5, registers(21, [1, 2])[:-1] + b'\x00'])
def test_an_answer_in_time_after_early_noise_is_never_the_next_requests(noise):
    """Noise fails the window at once; the device still answers it at 0.15 s, in time."""
    def respond(index, request):
        address = int.from_bytes(request[2:4], 'big')
        answer = (0.15, registers(20, [address * 100 + i for i in range(3)]))
        return [(0.002, noise), answer] if index == 0 else [answer]
    clock = FakeClock()
    line = ScriptedLine(clock, device_by_index(respond))
    transport = RtuSerialTransport(SETTINGS, clock=clock, line=line)
    transport.connect()
    with pytest.raises(BadFrame):
        transport.execute(20, ReadRegisters(10, 3))
    assert transport.execute(20, ReadRegisters(50, 3)) == [5000, 5001, 5002]


def test_a_stop_is_never_acknowledged_by_a_starts_acknowledgement_after_early_noise():
    """A drive's 0F write echoes address and quantity only: every control word's is alike."""
    start = WriteCoils(0, words_to_coils([0x047F, 0x2000]))
    stop = WriteCoils(0, words_to_coils([0x043C, 0x2000]))
    ack = rtu.RtuFrame(20, rtu.WRITE_MULTIPLE_COILS, bytes([0, 0, 0, 32])).encode()
    transport, line, clock = rtu_line([(0.002, b'\x00' * 5), (0.25, ack)], [])
    with pytest.raises(BadFrame):
        transport.execute(20, start)
    with pytest.raises(NoResponse):  # the busy drive never answered the stop
        transport.execute(20, stop)


@pytest.mark.parametrize('first_window', [
    [], [(0.002, b'\x00' * 5)], [(0.002, registers(21, [1, 2])[:-1] + b'\x00')]])
def test_a_reply_held_after_a_window_of_noise_is_never_the_next_answer(first_window):
    held, second = registers(20, [1010, 1011, 1012]), registers(20, [1050, 1051, 1052])
    transport, line, clock = rtu_line(first_window, [(0.0, held), (0.01, second)])
    with pytest.raises(BadFrame if first_window else NoResponse):
        transport.execute(20, READ)
    assert 20 in transport.discipline.owed
    with pytest.raises(AmbiguousReply):
        transport.execute(20, ReadRegisters(50, 3))


def test_a_frame_right_behind_the_answer_in_a_window_held_open_is_one_corrupt_frame():
    transport, line, clock = rtu_line([], [(TURNAROUND_S, OURS + registers(21, [4, 5, 6]))])
    with pytest.raises(NoResponse):
        transport.execute(20, READ)
    with pytest.raises(BadFrame, match='one corrupt frame'):
        transport.execute(20, ReadRegisters(50, 3))


def test_an_ap_ascii_stop_is_not_acknowledged_by_acks_that_outlived_early_noise():
    """One noise byte fails B10 at once; its ACK (in time) must not become B12's."""
    def device(request, now):
        if request == ap_ascii.message_fragment('B12'):
            return []
        noise = [(0.002, b'\x00')] if request == ap_ascii.message_fragment('B10') else []
        return noise + [(0.35, ACK)]  # in time (0.5 s), after the guard from the noise
    clock = FakeClock()
    line = ScriptedLine(clock, device)
    settings = LinkSettings(protocol='ap_ascii', port='/dev/ttyTEST', timeout_s=0.5)
    transport = ApAsciiTransport(settings, clock=clock, line=line)
    transport.connect()
    with pytest.raises(BadFrame):
        transport.execute(20, AsciiCommand('B10'))
    with pytest.raises(NoResponse):
        transport.execute(20, AsciiCommand('B12'))


def test_the_quarantine_before_a_request_is_no_part_of_its_round_trip():
    transport, line, clock = rtu_line([(TURNAROUND_S, OURS)])
    line.arrive(0.0, registers(21, [4, 5, 6]))
    started = clock.now
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    report = transport.last_report
    round_trip_s = clock.now - started - report.held_s - report.after_answer_s
    assert round_trip_s == pytest.approx(TURNAROUND_S)


def test_a_closed_line_reports_nothing_of_the_transaction_before():
    transport, line, clock = rtu_line([(TURNAROUND_S, registers(21, [9])),
                                       (TURNAROUND_S + 0.01, OURS)])
    assert transport.execute(20, READ) == [1010, 1011, 1012]
    assert late_units(transport) == [21]
    transport.close()
    with pytest.raises(LinkDown):
        transport.execute(20, READ)
    assert transport.last_report.late == []


# -- timing evidence on a real UART -------------------------------------------------------
def test_on_a_paced_line_a_reply_whole_before_it_could_have_crossed_the_wire_is_not_ours():
    wire_s = (8 + len(OURS)) * CHAR_S
    transport, line, clock = rtu_line([(wire_s / 3, OURS)], paced=True)
    with pytest.raises(MismatchedReply, match='before the request'):
        transport.execute(20, READ)
    transport, line, clock = rtu_line([(wire_s, OURS)], paced=True)
    assert transport.execute(20, READ) == [1010, 1011, 1012]


def test_on_a_pty_or_tcp_the_timing_says_nothing():
    transport, line, clock = rtu_line([(0.0, OURS)], paced=False)
    assert transport.execute(20, READ) == [1010, 1011, 1012]


# -- local echo -------------------------------------------------------------------------
def test_with_local_echo_the_echo_then_the_reply():
    transport, line, clock = rtu_line([(TURNAROUND_S, OURS)], echo=True)
    assert transport.execute(20, READ) == [1010, 1011, 1012]


def test_another_units_frame_ahead_of_the_echo_is_counted_and_the_write_is_done():
    write = WriteRegister(1, 1)
    echo = rtu.write_register_request(20, 1, 1).encode()
    late = registers(21, [1, 2, 3])
    transport, line, clock = rtu_line([(TURNAROUND_S, echo)])
    device = line.device
    line.device = lambda request, now: [(0.0, late + request)] + device(request, now)
    transport.discipline.timing = transport.discipline.timing.__class__(
        **{**transport.discipline.timing.__dict__, 'echo': True})
    assert transport.execute(20, write) is None
    assert late_units(transport) == [21]


# -- AP ASCII: replies name no unit -------------------------------------------------------
ACK, NAK, BEL = bytes([ap_ascii.ACK]), bytes([ap_ascii.NAK]), bytes([ap_ascii.BEL])
ASCII_SETTINGS = LinkSettings(protocol='ap_ascii', port='/dev/ttyTEST', timeout_s=0.25)


def scripted(transport_class, settings, *replies):
    """Return (transport of ``transport_class``, line, clock), the device answering so."""
    clock = FakeClock()
    line = ScriptedLine(clock, answering(*replies))
    transport = transport_class(settings, clock=clock, line=line)
    transport.connect()
    return transport, line, clock


def ascii_line(*replies):
    return scripted(ApAsciiTransport, ASCII_SETTINGS, *replies)


def test_an_ap_ascii_command_is_acknowledged_by_two_acks():
    transport, line, clock = ascii_line([(0.01, ACK)], [(0.01, ACK)])
    assert transport.execute(20, AsciiCommand('B10')) is None
    sent = [data for _, data in line.writes]
    assert sent == [ap_ascii.address_fragment(20), ap_ascii.message_fragment('B10')]


def test_a_stop_whose_ack_came_with_a_held_one_is_not_acknowledged():
    """B10's ACK is held past the guard; B12's exchange then sees two ACKs: not done."""
    transport, line, clock = ascii_line([(0.01, ACK)], [], [(0.01, ACK), (0.03, ACK)],
                                        [(0.01, ACK)])
    with pytest.raises(NoResponse):
        transport.execute(20, AsciiCommand('B10'))
    assert set(transport.discipline.owed) == {None}  # the whole line: ACKs name no unit
    with pytest.raises(AmbiguousReply):
        transport.execute(20, AsciiCommand('B12'))
    assert len(line.writes) == 3  # B12's message fragment never went out


def test_a_late_ack_in_the_guard_is_discarded_and_the_stop_acknowledged_by_its_own():
    transport, line, clock = ascii_line([(0.01, ACK)], [(0.25 + 0.05, ACK)], [(0.01, ACK)],
                                        [(0.01, ACK)])
    with pytest.raises(NoResponse):
        transport.execute(20, AsciiCommand('B10'))
    assert late_units(transport) == [None]
    assert transport.execute(20, AsciiCommand('B12')) is None


def test_an_ack_to_a_data_request_is_a_late_one():
    transport, line, clock = ascii_line([(0.01, ACK)], [(0.01, ACK)])
    with pytest.raises(MismatchedReply, match='ACK to C22'):
        transport.execute(20, AsciiRequest('C22'))


def test_a_nak_restarts_from_the_address_and_a_bel_is_a_refusal():
    status = ap_ascii.data_fragment(ap_ascii.encode_status(0x1F))
    transport, line, clock = ascii_line([(0.01, ACK)], [(0.01, NAK)], [(0.01, ACK)],
                                        [(0.01, status)])
    assert transport.execute(20, AsciiRequest('C22')) == 0x1F
    assert transport.last_recovered == {'nak': 1}
    transport, line, clock = ascii_line([(0.01, ACK)], [(0.01, BEL)])
    with pytest.raises(DeviceException):
        transport.execute(20, AsciiCommand('B10'))


# -- FC protocol: process telegrams echo nothing ----------------------------------------
FC_SETTINGS = LinkSettings(protocol='fc_protocol', port='/dev/ttyTEST', timeout_s=TIMEOUT_S)


def fc_line(*replies):
    return scripted(FcProtocolTransport, FC_SETTINGS, *replies)


def fc_reply(status: int, value: int, adr: int = 0x81) -> bytes:
    return fc_telegram.FcTelegram(adr, status, value).encode()


def test_a_held_process_reply_and_the_answer_fail_the_exchange():
    transport, line, clock = fc_line([], [(0.01, fc_reply(0x0607, 0x1111)),
                                          (0.03, fc_reply(0x0607, 0x2222))])
    with pytest.raises(NoResponse):
        transport.execute(1, fc_telegram.process_request(0x047C, 0x1111))
    with pytest.raises(AmbiguousReply):
        transport.execute(1, fc_telegram.process_request(0x047C, 0x2222))


def test_a_parameter_reply_to_a_process_telegram_is_a_late_one():
    parameter = fc_telegram.FcTelegram(0x81, 0x0607, 0,
                                       fc_telegram.make_pke(fc_telegram.AK_REPLY_WORD,
                                                            1614)).encode()
    transport, line, clock = fc_line([(0.01, parameter)])
    with pytest.raises(MismatchedReply):
        transport.execute(1, fc_telegram.process_request(0x047C, 0))


def test_a_telegram_from_another_address_is_skipped_and_counted():
    transport, line, clock = fc_line([(0.01, fc_reply(0x0607, 1, adr=0x82)),
                                      (0.03, fc_reply(0x0607, 2))])
    assert transport.execute(1, fc_telegram.process_request(0x047C, 0)).pcd2 == 2
    assert late_units(transport) == [2]


def test_a_broadcast_on_an_echoing_line_reads_its_echo():
    settings = LinkSettings(protocol='fc_protocol', port='/dev/ttyTEST', timeout_s=TIMEOUT_S,
                            local_echo=True)
    answer = fc_reply(0x0607, 0x1234)

    def device(request, now):
        return [(0.0, request)] + ([] if request[2] & 0x7F == 0 else [(0.01, answer)])
    clock = FakeClock()
    line = ScriptedLine(clock, device)
    transport = FcProtocolTransport(settings, clock=clock, line=line)
    transport.connect()
    assert transport.execute(0, fc_telegram.process_request(0x047C, 0)) is None
    assert transport.execute(1, fc_telegram.process_request(0x047C, 0)).pcd2 == 0x1234
    assert transport.last_report.late == [] and transport.last_report.held_s == 0.0


def test_on_rtu_over_tcp_bytes_right_behind_a_reply_are_one_corrupt_frame_too():
    """No gap between transactions on TCP, but the end-of-frame check keeps the line's."""
    settings = LinkSettings(protocol='rtu_over_tcp', tcp_port=5020, timeout_s=TIMEOUT_S)
    transport, line, clock = scripted(
        RtuSerialTransport, settings, [(TURNAROUND_S, OURS), (TURNAROUND_S + 0.001, b'\x00')])
    assert transport.discipline.timing.gap_s > 0.001
    with pytest.raises(BadFrame, match='inter-frame silence'):
        transport.execute(20, READ)


# -- a second adversarial review --------------------------------------------------------------
@pytest.mark.parametrize('glitch', [b'\x14', b'\x55', b'\xf7'])
def test_a_lone_glitch_byte_does_not_settle_a_reply_held_by_a_gateway(glitch):
    """One byte shows no unit or function: the answer may still be held; it owes."""
    held, second = registers(20, [1010, 1011, 1012]), registers(20, [1050, 1051, 1052])
    transport, line, clock = rtu_line([(0.002, glitch)], [(0.0, held), (0.01, second)])
    with pytest.raises(TruncatedFrame):
        transport.execute(20, READ)
    assert 20 in transport.discipline.owed
    with pytest.raises(AmbiguousReply):
        transport.execute(20, ReadRegisters(50, 3))


def test_a_cut_answer_that_shows_its_unit_and_function_leaves_no_debt():
    transport, line, clock = rtu_line([(TURNAROUND_S, OURS[:4])])
    with pytest.raises(TruncatedFrame):
        transport.execute(20, READ)
    assert 20 not in transport.discipline.owed


def test_a_lone_stx_does_not_settle_an_fc_reply_held_by_a_gateway():
    start_reply = fc_reply(0x0F07, 0x2000)
    transport, line, clock = fc_line([(0.002, b'\x02')], [(0.0, start_reply)])
    with pytest.raises(TruncatedFrame):
        transport.execute(1, fc_telegram.process_request(0x047F, 0x2000))
    with pytest.raises(AmbiguousReply):  # the stop, never answered, gets the held reply
        transport.execute(1, fc_telegram.process_request(0x043C, 0x2000))


@pytest.mark.parametrize('noise', [b'\x02', b'\x00\x00\x07\x00'])
def test_ap_ascii_noise_does_not_settle_the_line_s_debt(noise):
    """A stray STX, or a BEL-valued byte in the quarantine, is no answer of anybody's."""
    held = []

    def device(request, now):
        if request == ap_ascii.message_fragment('B10'):
            held.append(ACK)
            return [(0.002, noise)]
        if request == ap_ascii.message_fragment('B12'):
            return []
        released = [(0.0, held.pop())] if held else []
        return released + [(0.01, ACK)]
    settings = LinkSettings(protocol='ap_ascii', port='/dev/ttyTEST', timeout_s=0.5)
    transport, line, clock = scripted(ApAsciiTransport, settings)
    line.device = device
    with pytest.raises(BadFrame):
        transport.execute(20, AsciiCommand('B10'))
    with pytest.raises(AmbiguousReply):
        transport.execute(20, AsciiCommand('B12'))


def test_a_second_frame_of_the_unit_after_its_answer_makes_the_answer_ambiguous():
    """Seen in the quarantine that another unit's frame in the window brought about."""
    other, held = registers(21, [9, 9, 9]), registers(20, [1010, 1011, 1012])
    transport, line, clock = rtu_line(
        [(0.0, other), (0.002, held), (0.02, registers(20, [1050, 1051, 1052]))])
    with pytest.raises(AmbiguousReply, match='second frame of the unit'):
        transport.execute(20, ReadRegisters(50, 3))
    assert 20 in transport.discipline.owed


def test_a_held_acknowledgement_ahead_of_the_echo_came_before_the_request():
    """It settles the debt: the acknowledgement after the echo is the write's own."""
    stop = WriteCoils(0, words_to_coils([0x043C, 0x2000]))
    ack = rtu.RtuFrame(20, rtu.WRITE_MULTIPLE_COILS, bytes([0, 0, 0, 32])).encode()

    def device(request, now):
        if not line.writes[:-1]:  # the first stop: echoed, its acknowledgement held
            return [(0.0, request)]
        return [(0.0, ack), (0.0, request), (0.01, ack)]  # held, the echo, its own
    settings = LinkSettings(**{**SETTINGS.__dict__, 'local_echo': True})
    transport, line, clock = scripted(RtuSerialTransport, settings)
    line.device = device
    with pytest.raises(NoResponse):
        transport.execute(20, stop)
    assert transport.execute(20, stop) is None
