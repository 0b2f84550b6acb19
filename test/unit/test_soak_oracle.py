"""The soak oracle's rules on hand-made records (the catch tests run it on real soaks)."""

from drive_bridge.protocol.lvsg import Control
from soak_harness.line import ControlWrite, drive_label, lvsg_label, WireFrame
from soak_harness.oracle import (
    ACKNOWLEDGED, ClientLog, DeviceInfo, NOT_SENT, Oracle, outcome_of_reply, UNACKNOWLEDGED)

FAN = DeviceInfo('fan', 2, 'drive', reference_pct=25.0)
PRESS = DeviceInfo('press', 21, 'mcd')
PUMP = DeviceInfo('pump', 3, 'drive', monitor_only=True)
RUN, STOP = 0x047C, 0x043C
WORD_25 = 0x1000  # 25 % of 0x4000


class Line:
    """A line log and a client log written by hand, in one order."""

    def __init__(self, exact: bool = True):
        self.frames = []
        self.log = ClientLog(lambda: len(self.frames), clock=lambda: 0.0, exact=exact)

    def drive(self, unit: int, word: int, reference: int = WORD_25, executed: bool = True,
              fault=None) -> None:
        control = ControlWrite(drive_label(word), f'0x{word:04X}', word, reference)
        self._add(unit, 0x0F, control, executed, fault)

    def mcd(self, unit: int, value: int) -> None:
        label = {1: 'start', 2: 'stop', 3: 'reset', 4: 'quick_stop'}[value]
        self._add(unit, 0x06, ControlWrite(label, f'40002 = {value}'), True, None)

    def read(self, unit: int) -> None:
        self._add(unit, 0x03, None, True, None)

    def _add(self, unit, function, control, executed, fault) -> None:
        self.frames.append(WireFrame(len(self.frames) + 1, 0.0, unit, function, b'\0' * 4,
                                     fault, executed, control))

    def check(self, *devices, final_states=None) -> list:
        return [violation.kind
                for violation in Oracle(self.frames, self.log, devices).check(final_states)]


def test_keepalive_of_an_acknowledged_start_until_a_stop_is_asked():
    line = Line()
    start = line.log.ask('fan', 'start')
    line.drive(2, RUN)
    line.log.answer(start, ACKNOWLEDGED)
    line.drive(2, RUN)  # keepalive
    line.read(2)
    stop = line.log.ask('fan', 'stop')
    line.drive(2, STOP)
    line.log.answer(stop, ACKNOWLEDGED)
    line.drive(2, STOP)
    assert line.check(FAN) == []
    line.drive(2, RUN)  # the run word again, after the stop
    assert line.check(FAN) == ['run_after_end']


def test_a_start_told_failed_never_runs_again_but_its_own_write_counts_once():
    line = Line()
    start = line.log.ask('fan', 'start')
    line.drive(2, RUN, fault='no_reply')  # executed, the reply lost
    line.log.answer(start, UNACKNOWLEDGED)
    line.drive(2, STOP)
    assert line.check(FAN) == []
    line.drive(2, RUN)
    assert line.check(FAN) == ['run_after_failed_start']


def test_a_pulse_start_needs_its_own_request_each_time():
    line = Line()
    line.mcd(21, 1)
    assert line.check(PRESS) == ['run_without_start']
    line = Line()
    start = line.log.ask('press', 'start')
    line.mcd(21, 1)
    line.log.answer(start, ACKNOWLEDGED)
    line.mcd(21, 1)
    assert line.check(PRESS) == ['start_twice']  # written again after its answer


def test_an_acknowledged_command_must_be_the_last_write_before_its_answer():
    line = Line()
    start = line.log.ask('press', 'start')
    line.read(21)  # the start never went out
    line.log.answer(start, ACKNOWLEDGED)
    assert line.check(PRESS) == ['ack_not_on_wire']
    line = Line()
    stop = line.log.ask('press', 'stop')
    line.mcd(21, 2)
    line.frames[-1] = WireFrame(1, 0.0, 21, 0x06, b'\0' * 4, 'crc', True,
                                line.frames[-1].control)
    line.log.answer(stop, ACKNOWLEDGED)
    assert line.check(PRESS) == ['ack_spoiled_reply']


def test_two_identical_commands_back_to_back_keep_their_own_frames():
    # The first stop's write got a good reply and was acknowledged; the second one's reply
    # was spoiled and it was answered unacknowledged. The second write must not be taken for
    # the first one's (as if the simulator had taken the first late).
    line = Line()
    first = line.log.ask('press', 'stop')
    second = line.log.ask('press', 'stop')
    line.mcd(21, 2)
    line.log.answer(first, ACKNOWLEDGED)
    line.mcd(21, 2)
    line.frames[-1] = WireFrame(2, 0.0, 21, 0x06, b'\0' * 4, 'crc', True,
                                line.frames[-1].control)
    line.log.answer(second, UNACKNOWLEDGED)
    assert line.check(PRESS) == []
    assert Oracle(line.frames, line.log, [PRESS], slack=1).check() == []  # a pty soak's
    # Taken late by the simulator: its write just after the answer still counts.
    line = Line()
    line.read(21)
    stop = line.log.ask('press', 'stop')
    line.log.answer(stop, ACKNOWLEDGED)
    line.mcd(21, 2)
    assert Oracle(line.frames, line.log, [PRESS], slack=1).check() == []


def test_in_a_window_record_a_stop_ends_the_run_from_its_answer_on():
    line = Line(exact=False)
    start = line.log.ask('fan', 'start')
    line.drive(2, RUN)
    line.log.answer(start, ACKNOWLEDGED)
    stop = line.log.ask('fan', 'stop')
    line.drive(2, RUN)  # a keepalive before the node took the stop: allowed
    line.drive(2, STOP)
    line.log.answer(stop, ACKNOWLEDGED)
    line.drive(2, RUN)  # one request late: the master may have given up on it already
    assert line.check(FAN) == []
    line.drive(2, RUN)
    assert line.check(FAN) == ['run_after_end']


def test_offline_and_trip_notices_end_a_run():
    for kind in ('offline', 'tripped'):
        line = Line()
        start = line.log.ask('fan', 'start')
        line.drive(2, RUN)
        line.log.answer(start, ACKNOWLEDGED)
        line.log.notice('fan', kind)
        line.drive(2, STOP)
        assert line.check(FAN) == []
        line.drive(2, RUN)
        assert line.check(FAN) == ['run_after_end'], kind


def test_references_must_be_the_latest_the_client_set():
    line = Line()
    line.drive(2, STOP, reference=WORD_25)  # the configured 25 %
    line.log.reference('fan', 50.0, True)
    line.drive(2, STOP, reference=0x2000)
    line.log.reference('fan', float('nan'), False)
    line.drive(2, STOP, reference=0x2000)
    assert line.check(FAN) == []
    line.drive(2, STOP, reference=WORD_25)  # an older one
    line.log.reference('fan', 250.0, True)  # taken although out of range
    assert line.check(FAN) == ['reference', 'reference']


def test_a_monitor_only_device_gets_no_write_even_unexecuted():
    line = Line()
    line.read(3)
    assert line.check(PUMP) == []
    line.drive(3, STOP, executed=False)
    assert line.check(PUMP) == ['monitor_only_write']


def test_a_start_sent_after_a_later_stop_was_carried_out():
    line = Line()
    start = line.log.ask('press', 'start')
    stop = line.log.ask('press', 'stop')
    line.mcd(21, 2)
    line.log.answer(stop, ACKNOWLEDGED)
    line.mcd(21, 1)
    line.log.answer(start, ACKNOWLEDGED)
    assert line.check(PRESS) == ['start_after_stop']


def test_labels_of_control_words_and_gateway_images():
    assert drive_label(RUN) == 'start' and drive_label(STOP) == 'stop'
    assert drive_label(0x04BC) == 'reset' and drive_label(0x042C) == 'quick_stop'
    assert drive_label(0x0434) == 'coast_stop' and drive_label(0x007C) == 'ignored'
    held, clear = Control(fwd_run=True), Control()
    assert lvsg_label(clear, Control(fwd_run=True, quick_stop=True)) == 'start'  # rising
    assert lvsg_label(held, Control(fwd_run=True, quick_stop=True)) == 'quick_stop_hold'
    assert lvsg_label(held, held) == 'start' and lvsg_label(held, clear) == 'stop'
    assert lvsg_label(clear, Control(reset=True)) == 'reset'


def test_reply_texts_give_the_outcome():
    assert outcome_of_reply(True, 'start acknowledged by fan (address 2)') == ACKNOWLEDGED
    assert outcome_of_reply(False, 'fan is offline (no reply): nothing sent') == NOT_SENT
    assert outcome_of_reply(False, 'start not sent: the bus did not get to it') == NOT_SENT
    assert outcome_of_reply(False, 'rejected by fan: busy') == 'rejected'
    assert outcome_of_reply(False, 'no acknowledgement from fan for start (...)') == \
        UNACKNOWLEDGED


def test_a_lost_start_taken_late_by_the_simulator_is_its_own_write_not_a_resend():
    line = Line()
    start = line.log.ask('press', 'start')
    line.log.answer(start, UNACKNOWLEDGED)  # the master gave up before the simulator took it
    line.mcd(21, 1)
    assert line.check(PRESS) == []
    line.mcd(21, 1)
    assert line.check(PRESS) == ['run_after_failed_start']
    line = Line()
    start = line.log.ask('press', 'start')
    line.mcd(21, 1)
    line.log.answer(start, UNACKNOWLEDGED)
    line.mcd(21, 1)  # sent again after the failure was reported
    assert line.check(PRESS) == ['run_after_failed_start']


def test_a_signal_ends_nothing_until_the_bridge_exits_but_a_device_left_running_gets_no_write():
    left = DeviceInfo('press', 21, 'mcd', stop_on_shutdown=False)
    line = Line(exact=False)
    start = line.log.ask('fan', 'start')
    line.drive(2, RUN)
    line.log.answer(start, ACKNOWLEDGED)
    line.log.shutdown(ends_runs=False)  # SIGTERM sent
    line.read(2)
    line.drive(2, RUN)  # the node has not taken the signal yet
    line.drive(2, STOP)
    line.log.shutdown()  # the node exited
    stopped = {'fan': '', 'press': 'starter state 3'}  # press is left running: allowed
    assert line.check(FAN, left, final_states=stopped) == []
    line.mcd(21, 2)
    assert line.check(FAN, left, final_states=stopped) == ['shutdown_write']
    assert line.check(FAN, left, final_states={'fan': 'control word 0x047C (run)'}) == \
        ['not_stopped', 'shutdown_write']


def test_a_late_request_is_not_judged_by_time_but_is_still_a_start_s_own_write():
    line = Line()
    start = line.log.ask('fan', 'start')
    line.drive(2, RUN)
    line.frames[-1] = WireFrame(1, 0.0, 2, 0x0F, b'\0' * 4, None, True,
                                line.frames[-1].control, late=True)
    line.log.answer(start, ACKNOWLEDGED)
    line.drive(2, RUN)  # the keepalive of that start
    line.read(2)
    line.log.notice('fan', 'offline')
    line.frames.append(WireFrame(4, 0.0, 2, 0x0F, b'\0' * 4, None, True,
                                 line.frames[1].control, late=True))  # sent before the notice
    assert line.check(FAN) == []
