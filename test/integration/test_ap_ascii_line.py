"""The AP ASCII transport and bus against the simulated AP ASCII line on a pty, faults injected."""

import time

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.errors import BadFrame, CommandRefused, DeviceException, NoResponse
from drive_bridge.protocol.requests import AsciiCommand, AsciiRequest
from drive_bridge.sim.ap_ascii_server import make_ap_ascii_server
from drive_bridge.transport.ap_ascii import ApAsciiTransport
from drive_bridge.transport.link import LinkSettings
from fakes import kind
from integration_helpers import wait_until
import pytest


@pytest.fixture
def line():
    server = make_ap_ascii_server({20: 'mcd500', 21: 'mcd3000'}, start_time_s=0.3,
                                  stop_time_s=0.3)
    server.open_pty()
    server.start()
    yield server
    server.stop()


@pytest.fixture
def transport(line):
    transport = ApAsciiTransport(LinkSettings(protocol='ap_ascii', port=line.pty_path,
                                              parity='N', timeout_s=0.25))
    transport.connect()
    yield transport
    transport.close()


def test_command_and_requests(transport, line):
    assert transport.execute(20, AsciiRequest('C22', 'status')) & 0x0F == 1  # ready
    assert transport.execute(20, AsciiCommand('B10')) is None
    assert list(line.devices[20].commands_received) == [1]
    assert wait_until(lambda: transport.execute(20, AsciiRequest('C22')) & 0x0F == 3, 2.0)
    assert 79 <= transport.execute(20, AsciiRequest('D10', 'data')) <= 81  # 80 A, 1 % ripple
    assert transport.execute(20, AsciiRequest('C18', 'status')) == 255


def test_nak_is_retried_from_the_address_then_reported(transport, line):
    line.inject(20, 'nak')
    assert transport.execute(20, AsciiCommand('B12')) is None  # one NAK, then ACK
    assert transport.naks == 1 and line.stats.naks == 1
    line.inject(20, 'nak', count=3)  # more than nak_retries = 2
    with pytest.raises(BadFrame, match='NAK to address'):
        transport.execute(20, AsciiRequest('C22'))
    assert list(line.devices[20].commands_received) == [2]  # the stop, once


def test_bel_is_a_refusal(transport, line):
    line.devices[20].hand_on = True
    with pytest.raises(DeviceException) as error:
        transport.execute(20, AsciiCommand('B10'))
    assert error.value.code == 7
    assert transport.execute(20, AsciiCommand('B14')) is None  # reset still accepted


def test_silence_and_garbage(transport, line):
    started = time.monotonic()
    with pytest.raises(NoResponse):
        transport.execute(22, AsciiRequest('C22'))  # an unknown address never answers
    assert 0.2 < time.monotonic() - started < 0.6
    line.inject(20, 'silence')
    with pytest.raises(NoResponse):
        transport.execute(20, AsciiRequest('C22'))
    line.inject(20, 'garbage')
    with pytest.raises(BadFrame, match='invalid reply'):
        transport.execute(20, AsciiRequest('C22'))
    assert transport.execute(20, AsciiRequest('C22')) & 0x0F == 1


def test_address_lrc_setting_must_match_the_device(line):
    line.lrc_includes_eot = False  # a device that leaves EOT out of the address LRC
    settings = LinkSettings(protocol='ap_ascii', port=line.pty_path, parity='N',
                            timeout_s=0.25)
    wrong = ApAsciiTransport(settings, nak_retries=0)
    wrong.connect()
    with pytest.raises(BadFrame, match='NAK'):
        wrong.execute(20, AsciiRequest('C22'))
    wrong.close()
    right = ApAsciiTransport(settings, address_lrc_includes_eot=False)
    right.connect()
    assert right.execute(20, AsciiRequest('C22')) & 0x0F == 1
    right.close()


def test_bus_with_two_starters_and_a_dead_address(line):
    config = build_config(
        {'protocol': 'ap_ascii', 'port': line.pty_path, 'parity': 'N', 'timeout': 0.25,
         'devices': ['crusher', 'press', 'dead']},
        {'crusher': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 5.0},
         'press': {'family': 'mcd', 'model': 'mcd3000', 'address': 21, 'poll_rate': 5.0},
         'dead': {'family': 'mcd', 'address': 22, 'poll_rate': 5.0}})
    bus = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                    config.timing).start()
    try:
        assert wait_until(lambda: bus.snapshot('dead').online is False, 5.0)
        assert wait_until(lambda: bus.snapshot('crusher').online, 3.0)
        assert bus.submit_command('crusher', 'start').result(3)
        assert wait_until(lambda: bus.snapshot('crusher').reading.state == 'running', 3.0)
        line.devices[21].trip(1, time.monotonic())
        assert wait_until(lambda: (bus.snapshot('press').reading or 0) and
                          bus.snapshot('press').reading.trip_name == 'Excess start time', 3.0)
        line.devices[20].hand_on = True
        with pytest.raises(CommandRefused, match='refused by the starter'):
            bus.submit_command('crusher', 'stop').result(3)
    finally:
        bus.shutdown(stop_motors=False)


@pytest.mark.realtime  # a reading within 0.25 s of its reply: the threads must run on time
def test_a_dead_address_does_not_hold_back_the_readings_of_a_live_starter(line):
    # The bus gives its listener each reading while a request is on the wire: on AP ASCII
    # with the address fragment, so also while a dead address's ACK is awaited (0.5 s each).
    config = build_config(
        {'protocol': 'ap_ascii', 'port': line.pty_path, 'parity': 'N', 'timeout': 0.5,
         'backoff_max': 1.0, 'devices': ['crusher', 'dead']},
        {'crusher': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 5.0},
         'dead': {'family': 'mcd', 'address': 22, 'poll_rate': 5.0}})
    delays = []

    def listener(event):
        if kind(event) == 'reading':
            delays.append(time.monotonic() - event.stamp_s)
    bus = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                    config.timing, listener=listener).start()
    try:
        assert wait_until(lambda: bus.snapshot('dead').online is False and len(delays) > 10,
                          10.0)
    finally:
        bus.shutdown(stop_motors=False)
    assert max(delays) < 0.25, sorted(delays)[-3:]  # never a dead address's timeout
