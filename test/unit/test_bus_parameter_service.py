"""The device's ParameterService on the bus thread (BusMaster.run_parameter_service)."""

from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices import mcd
from drive_bridge.errors import (
    CommandRefused, DeviceException, LinkDown, MonitorOnly, NoResponse, ReadBackFailed,
    ReadBackMismatch)
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from fakes import FakeClock, run_for
import pytest
from test_bus_master import FakeTransport

CURRENT_LIMIT = 4  # MCD 500 par. 1-4, Modbus register 40012 (address 11)
ADDRESS = 11


class ParameterTransport(FakeTransport):
    """The bus master's fake, with parameter registers that keep what is written."""

    def __init__(self, clock):
        super().__init__(clock)
        self.registers = {ADDRESS: 350}
        self.keeps = None  # a value the device keeps whatever is written (None: what is)
        self.read_error = None

    def execute(self, unit, transaction):
        if isinstance(transaction, ReadRegisters) and transaction.address == ADDRESS:
            self.log.append((self.clock.now, unit, transaction))
            self.clock.now += 0.02
            if self.read_error is not None:
                raise self.read_error
            return [self.registers[ADDRESS]]
        result = super().execute(unit, transaction)
        if isinstance(transaction, WriteRegister) and transaction.address == ADDRESS:
            self.registers[ADDRESS] = transaction.value if self.keeps is None else self.keeps
        return result

    def parameter_requests(self):
        return [txn for _, _, txn in self.log if getattr(txn, 'address', None) == ADDRESS]


def make_bus(allow_control=True):
    clock = FakeClock()
    transport = ParameterTransport(clock)
    spec = DeviceSpec('d1', 1, mcd.McdProfile('mcd500'), allow_control=allow_control)
    bus = BusMaster(transport, [spec], BusTiming(), clock=clock, sleep=clock.sleep)
    run_for(bus, clock, 0.3)
    assert bus.snapshot('d1').online is True
    return bus, transport, clock


def write(service):
    return service.write(CURRENT_LIMIT, 400)


def test_a_write_is_checked_written_and_read_back_in_one_job():
    bus, transport, clock = make_bus()
    future = bus.run_parameter_service('d1', write)
    assert not future.done()  # the bus thread runs it
    run_for(bus, clock, 0.1)
    assert future.result(timeout=0) == 400
    assert transport.parameter_requests() == [WriteRegister(ADDRESS, 400),
                                              ReadRegisters(ADDRESS, 1)]
    # The write and its read back went back to back, no poll between them.
    log = [txn for _, _, txn in transport.log]
    first = log.index(WriteRegister(ADDRESS, 400))
    assert log[first + 1] == ReadRegisters(ADDRESS, 1)


def test_a_value_out_of_the_table_is_refused_by_the_service_with_nothing_sent():
    bus, transport, clock = make_bus()
    future = bus.run_parameter_service('d1', lambda service: service.write(CURRENT_LIMIT, 70000))
    run_for(bus, clock, 0.1)
    with pytest.raises(CommandRefused, match='nothing written'):
        future.result(timeout=0)
    assert transport.parameter_requests() == []


def test_monitor_only_sends_nothing_from_the_service_job_nor_from_write_parameter():
    bus, transport, clock = make_bus(allow_control=False)
    future = bus.run_parameter_service('d1', write)
    run_for(bus, clock, 0.1)
    with pytest.raises(MonitorOnly, match='monitor only'):
        future.result(timeout=0)
    with pytest.raises(MonitorOnly, match='monitor only'):  # refused at once
        bus.write_parameter('d1', CURRENT_LIMIT, 400).result(timeout=0)
    run_for(bus, clock, 0.5)
    assert transport.parameter_requests() == []
    read = bus.run_parameter_service('d1', lambda service: service.read(CURRENT_LIMIT))
    run_for(bus, clock, 0.1)
    assert read.result(timeout=0) == 350  # a read is taken: it writes nothing
    assert [txn for _, _, txn in transport.log if isinstance(txn, WriteRegister)] == []


def test_while_the_link_is_down_a_job_is_refused_at_once_and_never_runs():
    bus, transport, clock = make_bus()
    transport.failures[1] = LinkDown('bus offline: /dev/ttyFAKE not found')
    transport.link_ok = False
    run_for(bus, clock, 0.5)
    assert bus.link_error
    ran = []
    future = bus.run_parameter_service('d1', lambda service: ran.append(service))
    with pytest.raises(CommandRefused, match='nothing sent'):
        future.result(timeout=0)
    run_for(bus, clock, 0.5)
    assert ran == [] and transport.parameter_requests() == []


def test_a_link_lost_in_the_job_takes_the_link_down_and_sends_nothing_more():
    bus, transport, clock = make_bus()
    transport.write_error[1] = LinkDown('bus offline: /dev/ttyFAKE gone')
    future = bus.run_parameter_service('d1', write)
    bus.run_once()
    with pytest.raises(LinkDown):
        future.result(timeout=0)
    assert bus.link_error and bus.snapshot('d1').online is False
    assert transport.parameter_requests() == [WriteRegister(ADDRESS, 400)]  # no read back


def test_a_device_refusal_is_answered_in_words_and_nothing_more_is_sent():
    bus, transport, clock = make_bus()
    transport.write_error[1] = DeviceException(9)
    future = bus.run_parameter_service('d1', write)
    run_for(bus, clock, 0.1)
    with pytest.raises(CommandRefused) as error:
        future.result(timeout=0)
    assert str(error.value).startswith('rejected by d1: network control disabled')
    assert 'Modbus error 09' in str(error.value)
    assert transport.parameter_requests() == [WriteRegister(ADDRESS, 400)]  # no read back


def test_a_value_that_reads_back_different_is_reported_with_the_value_held():
    bus, transport, clock = make_bus()
    transport.keeps = 300  # the device keeps its own value
    future = bus.run_parameter_service('d1', write)
    run_for(bus, clock, 0.1)
    with pytest.raises(ReadBackMismatch, match='wrote 400, but it reads back 300') as error:
        future.result(timeout=0)
    assert error.value.read == 300


def test_a_failed_read_back_says_the_value_was_written():
    bus, transport, clock = make_bus()
    transport.read_error = NoResponse('no reply within 0.5 s')
    future = bus.run_parameter_service('d1', write)
    run_for(bus, clock, 0.1)
    with pytest.raises(ReadBackFailed, match='written, but the read back failed: no reply'):
        future.result(timeout=0)
    assert transport.parameter_requests()[0] == WriteRegister(ADDRESS, 400)


def test_a_job_given_up_before_the_bus_takes_it_is_never_run():
    bus, transport, clock = make_bus()
    ran = []
    future = bus.run_parameter_service('d1', lambda service: ran.append(service.write(
        CURRENT_LIMIT, 400)))
    assert future.cancel()
    run_for(bus, clock, 0.5)
    assert ran == [] and transport.parameter_requests() == []


def test_a_job_not_begun_by_its_deadline_is_dropped_unsent():
    bus, transport, clock = make_bus()
    future = bus.run_parameter_service('d1', write, deadline_s=0.1)
    clock.now += 0.2
    run_for(bus, clock, 0.1)
    with pytest.raises(CommandRefused, match='never sent'):
        future.result(timeout=0)
    assert transport.parameter_requests() == []


def test_a_bug_in_the_function_is_its_answer_and_the_bus_goes_on():
    bus, transport, clock = make_bus()
    future = bus.run_parameter_service('d1', lambda service: 1 / 0)
    run_for(bus, clock, 0.3)
    with pytest.raises(ZeroDivisionError):
        future.result(timeout=0)
    assert bus.internal_errors == 0 and bus.snapshot('d1').online is True


def test_a_device_without_parameter_access_or_offline_is_refused_at_once():
    bus, transport, clock = make_bus()
    with pytest.raises(CommandRefused, match="unknown device 'nope'"):
        bus.run_parameter_service('nope', write).result(timeout=0)
    transport.failures[1] = NoResponse('no reply within 0.5 s')
    run_for(bus, clock, 5.0)
    assert bus.snapshot('d1').online is False
    with pytest.raises(CommandRefused, match='is offline'):
        bus.run_parameter_service('d1', write).result(timeout=0)


def test_a_bug_below_the_line_answers_the_job_and_the_bus_recovers_as_from_any():
    bus, transport, clock = make_bus()
    transport.write_error[1] = RuntimeError('termios said no')  # not a TransportError
    future = bus.run_parameter_service('d1', write)
    with pytest.raises(RuntimeError) as raised:
        bus.run_once()
    with pytest.raises(RuntimeError, match='termios said no'):
        future.result(timeout=0)
    bus._internal_error(raised.value)  # what the bus thread does with it
    assert bus.internal_errors == 1 and bus.snapshot('d1').online is False
    assert transport.parameter_requests() == [WriteRegister(ADDRESS, 400)]  # no read back
