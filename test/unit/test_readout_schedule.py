"""The slow readouts come at most once a readout period; the fast values every poll."""

from drive_bridge.config import build_config
from drive_bridge.devices import fc, mcd
from drive_bridge.devices.contracts import Freshness, SlowReadouts
from drive_bridge.devices.drive import DriveProfile
from drive_bridge.devices.lvsg import LvsgProfile
from drive_bridge.devices.mcd_ascii import McdAsciiProfile
from drive_bridge.protocol import lvsg, words
from drive_bridge.protocol.requests import AsciiRequest, ReadCoils, ReadRegisters
from fakes import drive_cycle, FakeClock

PRODUCT_MCD500 = (7 << 3) | 1


def slow(period_s):
    clock = FakeClock()
    return clock, SlowReadouts(period_s, clock)


def test_slow_readouts_are_due_once_a_period():
    clock, schedule = slow(1.0)
    assert schedule.due() and not schedule.due()
    clock.now += 0.99
    assert not schedule.due()
    clock.now += 0.02
    assert schedule.due()
    assert all(SlowReadouts(0.0).due() for _ in range(3))  # period 0: every poll


def fc_answer(request):
    if isinstance(request, ReadCoils):
        return list(words.words_to_coils([0x0607, 0]))
    return [0] * request.count


def test_an_fc51_reads_status_and_current_every_poll_and_one_slow_readout_a_period():
    clock, schedule = slow(1.0)
    profile = DriveProfile(fc.DATA, 'fc51', slow_readouts=schedule)
    profile._identified = True
    polls = []
    for _ in range(10):  # ten polls in 0.5 s
        polls.append(drive_cycle(profile, fc_answer)[0])
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
        requests, reading = drive_cycle(profile, mcd_answer)
        counts.append(requests[0].count)
        clock.now += 0.5
    assert counts == [6, 4, 4, 4, 6] and profile.model == 'mcd500'
    assert reading.details['product_type'] == 'MCD 500'  # kept from the last read
    profile.on_offline()
    assert drive_cycle(profile, mcd_answer)[0][0].count == 6  # back: read them again


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
        drive_cycle(profile, answer)
        clock.now += 0.1
    assert requests[:4] == [1, 2, 3, 4]
    assert requests.count(3) >= 4 and requests.count(4) >= 4
    assert requests[4:].count(1) + requests[4:].count(2) <= 2  # at most one a second


def test_the_readout_period_is_a_device_setting_of_every_family():
    device = {'family': 'fc', 'address': 1, 'readout_period': 2.5}
    config = build_config({'devices': ['a']}, {'a': device})
    assert config.devices[0].make_spec().profile.slow_readouts.period_s == 2.5


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
