"""The slow readouts come at most once a readout period; the fast values every poll."""

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.devices import fc51, mcd
from drive_bridge.devices.contracts import Freshness, SlowReadouts
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.devices.lvsg import LvsgProfile
from drive_bridge.devices.mcd_ascii import McdAsciiProfile
from drive_bridge.protocol import lvsg, words
from drive_bridge.protocol.requests import AsciiRequest, ReadCoils, ReadRegisters
from drive_bridge.transport.base import Transport
from fakes import drive_cycle, FakeClock, run_for

PRODUCT_MCD500 = (7 << 3) | 1


def slow(period_s):
    return FakeClock(), SlowReadouts(period_s)


def test_slow_readouts_are_due_once_a_period():
    clock, schedule = slow(1.0)
    assert schedule.due(clock.now) and not schedule.due(clock.now)
    clock.now += 0.99
    assert not schedule.due(clock.now)
    clock.now += 0.02
    assert schedule.due(clock.now)
    assert all(SlowReadouts(0.0).due(0.0) for _ in range(3))  # period 0: every poll


def fc_answer(request):
    if isinstance(request, ReadCoils):
        return list(words.words_to_coils([0x0607, 0]))
    return [0] * request.count


def test_an_fc51_reads_status_and_current_every_poll_and_one_slow_readout_a_period():
    clock, schedule = slow(1.0)
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51', slow_readouts=schedule)
    profile._identified = True
    polls = []
    for _ in range(10):  # ten polls in 0.5 s
        polls.append(drive_cycle(profile, fc_answer, now_s=clock.now)[0])
        clock.now += 0.05
    assert all(poll[:2] == [ReadCoils(32, 32), ReadRegisters(16139, 2)] for poll in polls)
    assert [len(poll) for poll in polls] == [3] + [2] * 9  # one slow readout in the period


def mcd_answer(request):
    return [1, 255, 10, 5, PRODUCT_MCD500, 1][:request.count]


def test_an_mcd_reads_its_product_registers_only_when_due_once_the_model_is_known():
    clock, schedule = slow(2.0)
    profile = mcd.McdProfile('auto', slow_readouts=schedule)
    counts = []
    for _ in range(5):
        requests, reading = drive_cycle(profile, mcd_answer, now_s=clock.now)
        counts.append(requests[0].count)
        clock.now += 0.5
    assert counts == [6, 4, 4, 4, 6] and profile.model == 'mcd500'
    assert reading.details['product_type'] == 'MCD 500'  # kept from the last read
    profile.on_offline()
    assert drive_cycle(profile, mcd_answer, now_s=clock.now)[0][0].count == 6  # back: again


def test_ap_ascii_asks_for_the_trip_code_only_when_tripped_or_due():
    clock, schedule = slow(10.0)
    profile = McdAsciiProfile('mcd500', slow_readouts=schedule)
    ready = {'C22': 0x41, 'C18': 255, 'D10': 80, 'D12': 40}

    def answer(status):
        return lambda request: dict(ready, C22=status)[request.code]
    first, _ = drive_cycle(profile, answer(0x41))
    second, reading = drive_cycle(profile, answer(0x41))
    assert AsciiRequest('C18', 'status') in first
    assert AsciiRequest('C18', 'status') not in second and reading.trip_code == 0
    trip = {'C22': 0x46, 'C18': 2, 'D10': 0, 'D12': 90}
    tripped, reading = drive_cycle(profile, lambda request: trip[request.code])
    assert AsciiRequest('C18', 'status') in tripped and reading.trip_code == 2


def test_lvsg_current_and_temperature_take_turns_product_and_state_once_a_period():
    clock, schedule = slow(1.0)
    profile = LvsgProfile('mcd202', input_register=0, output_register=100,
                          slow_readouts=schedule)
    requests = []
    values = {1: (4 << 3) << 8 | 3, 2: 255 << 8 | 1, 3: 50, 4: 20}
    for _ in range(12):
        request = profile.operating.request
        requests.append(request)
        status = lvsg.encode_status(True, False, False, False, 0,
                                    (request, values[request], False))
        image = words.bytes_to_registers(status, 'big')

        def answer(request, image=image):
            return image if request == ReadRegisters(0, 3) else [0, 0]
        drive_cycle(profile, answer, now_s=clock.now)
        clock.now += 0.1
    assert requests[:4] == [1, 2, 3, 4]
    assert requests.count(3) >= 4 and requests.count(4) >= 4
    assert requests[4:].count(1) + requests[4:].count(2) <= 2  # at most one a second


def test_the_readout_period_is_a_device_setting_of_every_family():
    device = {'family': 'fc', 'address': 1, 'readout_period': 2.5}
    config = build_config({'devices': ['a']}, {'a': device})
    assert config.devices[0].make_spec().profile.slow_readouts.period_s == 2.5


class McdOnAFakeClock(Transport):
    """An MCD 500 at address 1 that answers every read 20 ms later on ``clock``."""

    def __init__(self, link, clock):
        super().__init__(link)
        self.clock = clock
        self.reads = []  # (time, registers read)

    @property
    def connected(self):
        return True

    def connect(self):
        pass

    def close(self):
        pass

    def execute(self, unit, transaction):
        self.reads.append((self.clock.now, transaction.count))
        self.clock.now += 0.02
        return mcd_answer(transaction)


def test_a_bus_on_a_virtual_clock_reads_the_slow_readouts_by_its_own_clock():
    # A profile made from the configuration, on a bus whose clock is not the wall clock
    # (the virtual soak's line, these tests): once a readout period of the bus's time, not
    # of wall time (which barely moves while the fake clock runs 10 s).
    device = {'family': 'mcd', 'model': 'mcd500', 'address': 1, 'readout_period': 1.0,
              'poll_rate': 5.0}
    config = build_config({'devices': ['a']}, {'a': device})
    clock = FakeClock()
    transport = McdOnAFakeClock(config.link, clock)
    bus = BusMaster(transport, [config.devices[0].make_spec()], config.timing,
                    listener=lambda event: None, clock=clock, sleep=clock.sleep)
    run_for(bus, clock, 10.0)
    slow_reads = [time_s for time_s, count in transport.reads if count == 6]
    assert len(transport.reads) >= 45
    assert len(slow_reads) in (10, 11), transport.reads
    assert all(later - earlier > 1.0 - 1e-9 for earlier, later in zip(slow_reads, slow_reads[1:]))


def test_a_value_read_counts_only_from_the_poll_its_fast_signal_took_its_value():
    read = Freshness()
    read.begin_poll()
    read.take('state', 'starting')
    assert read.hold('ramping', True) == 1
    read.begin_poll()
    assert read.hold('ramping', True) == 1  # unchanged: still since poll 1
    assert read.current('state', read.hold('ramping', True)) == 'starting'
    read.begin_poll()
    since = read.hold('ramping', False)  # changed in poll 3: the value read in 1 is older
    assert since == 3 and read.current('state', since) is None
    assert read.get('state') == 'starting' and read.read_in('state') == 1  # kept, not current
    read.take('state', 'running')
    assert read.is_current('state', since) and read.current('state', since) == 'running'
    read.drop('state')
    assert read.get('state') is None and not read.is_current('state', 0)
    read.forget()
    read.begin_poll()
    assert read.hold('ramping', False) == 4  # forgotten: a new signal
