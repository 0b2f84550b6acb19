"""Unit tests of the bus with FC-profile drives: keepalive, deadman, set-up, exceptions."""

from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.bus.motor import Motion
from drive_bridge.devices import fc51
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.errors import CommandRefused, DeviceException, NoResponse
from drive_bridge.protocol import words
from drive_bridge.protocol.requests import ReadCoils, ReadRegisters, WriteCoils, WriteRegisters
from drive_bridge.transport.base import Transport
from drive_bridge.transport.link import LinkSettings
from fakes import FakeClock, kind, message, run_for
import pytest

RTT_S = 0.02


class FakeDrive(Transport):
    """One drive on a fake bus: answers the status coils and readouts, logs writes."""

    def __init__(self, clock):
        super().__init__(LinkSettings())
        self.clock = clock
        self._connected = False
        self.status_word = 0x0607
        self.silent = False
        self.refuse = {}  # frame address -> exception code
        self.log = []

    @property
    def connected(self):
        return self._connected

    def connect(self):
        self._connected = True

    def close(self):
        self._connected = False

    def execute(self, unit, transaction):
        self.log.append((self.clock.now, transaction))
        if self.silent:
            self.clock.now += 0.2
            raise NoResponse('no reply within 0.2 s')
        self.clock.now += RTT_S
        address = getattr(transaction, 'address', None)
        if address in self.refuse:
            raise DeviceException(self.refuse[address])
        if isinstance(transaction, ReadCoils):
            return list(words.words_to_coils([self.status_word, 0]))
        if isinstance(transaction, ReadRegisters):
            if transaction.address == 6:
                return [17]
            return [0] * transaction.count
        return None

    def writes(self, kind=WriteCoils):
        return [(t, txn) for t, txn in self.log if isinstance(txn, kind)]


def make_bus(timeout_s=0.0, **profile_options):
    clock = FakeClock()
    drive = FakeDrive(clock)
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51', **profile_options)
    spec = DeviceSpec('conv', 1, profile, poll_rate_hz=10.0, reference_timeout_s=timeout_s)
    events = []
    bus = BusMaster(drive, [spec], BusTiming(retries=0, offline_after=2,
                                             backoff_initial_s=1.0, backoff_max_s=2.0),
                    listener=events.append, clock=clock, sleep=clock.sleep)
    return bus, drive, clock, events


def control_words(drive):
    return [words.coils_to_words(list(txn.values))[0] for _, txn in drive.writes()]


def test_no_write_until_a_command_then_keepalive_at_the_poll_rate():
    bus, drive, clock, _ = make_bus()
    run_for(bus, clock, 2.0)
    assert drive.writes() == [] and drive.writes(WriteRegisters) == []
    bus.submit_command('conv', 'start')
    run_for(bus, clock, 1.0)
    assert control_words(drive)[0] == 0x047C
    assert 9 <= len(drive.writes()) <= 12  # one rewrite a poll at 10 Hz


def test_a_drive_lost_while_running_gets_the_stop_word_when_it_returns_never_the_run_word():
    bus, drive, clock, events = make_bus()
    run_for(bus, clock, 0.5)
    bus.submit_command('conv', 'start')
    run_for(bus, clock, 0.5)
    drive.silent = True
    run_for(bus, clock, 1.0)
    assert [kind(e) for e in events if kind(e) == 'offline'] == ['offline']
    assert bus.snapshot('conv').motion is Motion.MAY_RUN  # shutdown still stops it
    count = len(drive.writes())
    drive.silent = False
    run_for(bus, clock, 5.0)
    assert bus.snapshot('conv').online
    after = control_words(drive)[count:]
    assert after and set(after) == {0x043C}  # the run is never resumed
    assert any(kind(e) == 'notice' and 'the run is not resumed' in e.message for e in events)


def test_no_write_at_all_for_a_drive_that_was_never_commanded_after_an_outage():
    bus, drive, clock, _ = make_bus()
    run_for(bus, clock, 0.5)
    drive.silent = True
    run_for(bus, clock, 1.0)
    drive.silent = False
    run_for(bus, clock, 3.0)
    assert bus.snapshot('conv').online and drive.writes() == []


def test_a_drive_stopped_before_an_outage_gets_its_stop_word_again_after_it():
    # docs/safety.md, the write rule: "A device that was stopped keeps getting its stop image
    # after an outage, as before it" (and no notice: no run was held).
    bus, drive, clock, events = make_bus()
    run_for(bus, clock, 0.3)
    bus.submit_command('conv', 'start')
    run_for(bus, clock, 0.5)
    bus.submit_command('conv', 'stop')
    run_for(bus, clock, 0.5)
    assert control_words(drive)[-1] == 0x043C
    drive.silent = True
    run_for(bus, clock, 1.0)
    assert not bus.snapshot('conv').online
    count = len(drive.writes())
    drive.silent = False
    run_for(bus, clock, 3.0)
    after = control_words(drive)[count:]
    assert bus.snapshot('conv').online and len(after) >= 10 and set(after) == {0x043C}
    assert not any('not resumed' in getattr(e, 'message', '') for e in events)


def test_a_trip_ends_the_run_word_the_keepalive_writes_a_stop():
    bus, drive, clock, events = make_bus()
    run_for(bus, clock, 0.3)
    bus.submit_command('conv', 'start')
    run_for(bus, clock, 0.5)
    drive.status_word = 0x0607 | 1 << 3  # tripped
    run_for(bus, clock, 0.5)
    words_sent = control_words(drive)
    assert words_sent[-1] == 0x043C and 0x047C in words_sent
    assert bus.snapshot('conv').motion is Motion.IDLE
    drive.status_word = 0x0607  # reset at the drive's LCP: the drive must not start again
    run_for(bus, clock, 0.5)
    assert set(control_words(drive)[len(words_sent):]) == {0x043C}


def test_speed_reference_goes_out_with_the_next_cycle():
    bus, drive, clock, _ = make_bus()
    run_for(bus, clock, 0.3)
    assert bus.set_speed_reference('conv', 40.0) == 0x1999
    bus.submit_command('conv', 'start')
    run_for(bus, clock, 0.2)
    writes = len(drive.writes())
    bus.set_speed_reference('conv', -50.0)
    bus.run_once()
    assert len(drive.writes()) == writes  # no extra traffic: it waits for the next cycle
    run_for(bus, clock, 0.15)
    references = [words.coils_to_words(list(txn.values))[1] for _, txn in drive.writes()]
    assert references[0] == 0x1999 and references[-1] == 0xE000
    with pytest.raises(CommandRefused, match='nothing sent'):
        bus.set_speed_reference('conv', float('nan'))
    assert bus.snapshot('conv').stats['rejected_references'] == '1'


def test_deadman_ramp_stops_when_reference_messages_stop():
    bus, drive, clock, events = make_bus(timeout_s=0.5)
    run_for(bus, clock, 0.3)
    bus.submit_command('conv', 'start')
    for _ in range(10):  # messages every 0.2 s keep it running
        bus.set_speed_reference('conv', 30.0, from_topic=True)
        run_for(bus, clock, 0.2)
    assert set(control_words(drive)) == {0x047C}
    run_for(bus, clock, 1.0)
    assert control_words(drive)[-1] == 0x043C
    assert bus.snapshot('conv').stats['deadman_stops'] == '1'
    assert any(kind(e) == 'notice' and 'reference timeout' in e.message for e in events)
    run_for(bus, clock, 2.0)  # the stop word is kept up; no second deadman stop
    assert bus.snapshot('conv').stats['deadman_stops'] == '1'


def test_setup_writes_when_the_drive_comes_online():
    bus, drive, clock, _ = make_bus(comms_timeout_s=1.0, comms_timeout_function=2)
    run_for(bus, clock, 0.5)
    setup = [txn for _, txn in drive.log
             if getattr(txn, 'address', None) in (8029, 8039)]
    assert setup[0] == WriteRegisters(8029, (0, 10))
    assert len(setup) == 2


def test_exception_04_reads_register_7_for_the_detail():
    bus, drive, clock, _ = make_bus()
    run_for(bus, clock, 0.3)
    drive.refuse[fc51.DATA.spec(124).address] = 4
    future = bus.write_parameter('conv', 124, 2.5)
    run_for(bus, clock, 0.1)
    with pytest.raises(CommandRefused) as error:
        future.result(timeout=0)
    assert 'not possible in the present mode' in str(error.value)
    assert 'register 7 = 17' in str(error.value)


def test_local_operation_refuses_commands_before_sending():
    bus, drive, clock, _ = make_bus()
    drive.status_word = 0x0407
    run_for(bus, clock, 0.3)
    future = bus.submit_command('conv', 'start')
    with pytest.raises(CommandRefused, match='local operation'):
        future.result(timeout=0)
    assert drive.writes() == []


def test_a_refused_setup_write_is_reported_not_fatal():
    bus, drive, clock, events = make_bus(comms_timeout_s=1.0)
    drive.refuse[8029] = 4
    run_for(bus, clock, 0.5)
    snapshot = bus.snapshot('conv')
    assert snapshot.online and snapshot.reading.state == 'ready'
    # Named by the parameter it sets, not by the register it maps to.
    assert snapshot.stats['setup_error'].startswith(
        'set-up write Control Word Timeout Time (par. 8-03) = 1 failed: ')
    assert 'register 7 = 17' in snapshot.stats['setup_error']
    assert [kind(e) for e in events if 'set-up' in message(e)] == ['notice']


class LosesOneReply(FakeDrive):
    """A drive that executes the next write but whose reply is lost (or refused)."""

    def __init__(self, clock):
        super().__init__(clock)
        self.fail_next_write_with = None

    def execute(self, unit, transaction):
        error, self.fail_next_write_with = (
            (self.fail_next_write_with, None) if isinstance(transaction, WriteCoils)
            else (None, self.fail_next_write_with))
        result = super().execute(unit, transaction)
        if error is not None:
            raise error
        return result


def bus_losing_one_reply():
    """Return (bus, drive, clock) with a drive whose next write's reply can be lost."""
    clock = FakeClock()
    drive = LosesOneReply(clock)
    spec = DeviceSpec('conv', 1, FcProfileModbusDrive(fc51.DATA, 'fc51'), poll_rate_hz=10.0)
    bus = BusMaster(drive, [spec], BusTiming(retries=0), clock=clock, sleep=clock.sleep)
    run_for(bus, clock, 0.5)
    return bus, drive, clock


@pytest.mark.parametrize('failure', [NoResponse('no reply'), DeviceException(6)])
def test_a_failed_stop_is_kept_by_the_keepalive_never_the_old_run_word(failure):
    bus, drive, clock = bus_losing_one_reply()
    bus.submit_command('conv', 'start')
    run_for(bus, clock, 0.5)
    drive.fail_next_write_with = failure
    future = bus.submit_command('conv', 'stop')
    run_for(bus, clock, 1.0)
    assert future.exception() is not None  # reported as failed
    sent = control_words(drive)
    stop_at = sent.index(0x043C)
    assert stop_at > 0 and sent[stop_at:] == [0x043C] * len(sent[stop_at:])
    assert len(sent[stop_at:]) >= 5  # and repeated by the keepalive


def test_a_failed_start_is_not_repeated_the_keepalive_keeps_the_stop():
    bus, drive, clock = bus_losing_one_reply()
    bus.submit_command('conv', 'stop')
    run_for(bus, clock, 0.5)
    drive.fail_next_write_with = NoResponse('no reply')
    future = bus.submit_command('conv', 'start')
    run_for(bus, clock, 1.0)
    assert 'may or may not have been executed' in str(future.exception())
    sent = control_words(drive)
    assert sent.count(0x047C) == 1  # the start went out once
    assert sent[sent.index(0x047C) + 1:] and set(sent[sent.index(0x047C) + 1:]) == {0x043C}
    assert bus.snapshot('conv').holds_run  # so a shutdown still stops it


def test_a_first_start_without_reply_is_followed_by_the_stop_word_never_a_second_start():
    bus, drive, clock = bus_losing_one_reply()
    drive.fail_next_write_with = NoResponse('no reply')
    future = bus.submit_command('conv', 'start')
    run_for(bus, clock, 1.0)
    assert 'may or may not have been executed' in str(future.exception())
    sent = control_words(drive)
    assert sent[0] == 0x047C and sent.count(0x047C) == 1
    assert len(sent) > 3 and set(sent[1:]) == {0x043C}


def test_a_reading_is_stamped_when_the_reply_with_its_process_data_arrived():
    bus, drive, clock, events = make_bus()
    run_for(bus, clock, 0.5)
    bus.submit_command('conv', 'start')
    run_for(bus, clock, 0.5)
    status_replies = [t + RTT_S for t, txn in drive.log if isinstance(txn, ReadCoils)]
    stamps = [e.stamp_s for e in events if kind(e) == 'reading']
    assert stamps and set(stamps) <= set(status_replies)
