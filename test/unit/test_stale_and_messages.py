"""Stale readings turn /diagnostics WARN; offline and online lines name the address."""

import pytest

# The diagnostics builder needs ROS messages: where they are missing (the pymodbus 3.6.9 venv)
# the module is skipped.
DiagnosticStatus = pytest.importorskip(
    'diagnostic_msgs.msg', reason='ROS messages are not installed here').DiagnosticStatus
from drive_bridge.bus.events import DeviceOffline, DeviceOnline  # noqa: E402, I100
from drive_bridge.ros.node import bus_events  # noqa: E402
from drive_bridge.ros.node.diagnostics import diagnostic_status  # noqa: E402
from fakes import run_for  # noqa: E402
from test_bus_drive import make_bus  # noqa: E402


def status_of(bus):
    return diagnostic_status(bus.snapshot('conv'), 'drive_bridge: conv', '/dev/ttyUSB0')


def test_readings_older_than_three_polls_warn_with_their_age_and_the_likely_cause():
    bus, drive, clock, _ = make_bus()  # poll_rate 10: 3 periods 0.3 s, the floor 0.5 s
    run_for(bus, clock, 0.5)
    fresh = status_of(bus)
    assert fresh.level == DiagnosticStatus.OK and fresh.message == 'ready'
    clock.sleep(0.3)  # the bus does not get to poll (a line too slow): not yet stale
    assert status_of(bus).level == DiagnosticStatus.OK
    clock.sleep(0.5)
    status = status_of(bus)
    assert status.level == DiagnosticStatus.WARN
    age_s = bus.snapshot('conv').reading_age_s
    assert 0.8 <= age_s < 1.0 and status.message.startswith(f'readings are {age_s:.1f} s old')
    assert 'at poll_rate 10 Hz (more than 3 poll periods): the line may be too slow for the ' \
        "poll rates; lower this device's poll_rate or the other devices'" in status.message
    run_for(bus, clock, 0.2)  # polled again: OK
    assert status_of(bus).level == DiagnosticStatus.OK


def test_a_slow_device_is_stale_only_after_three_of_its_periods():
    bus, drive, clock, _ = make_bus()
    for device in bus._devices:
        device.spec.poll_rate_hz = 0.5  # a 2 s period: 6 s before WARN
    run_for(bus, clock, 0.5)
    clock.sleep(5.0)
    assert status_of(bus).level == DiagnosticStatus.OK
    clock.sleep(1.5)
    assert 'at poll_rate 0.5 Hz' in status_of(bus).message


class Logger:
    def __init__(self):
        self.lines = []

    def error(self, text):
        self.lines.append(('error', text))

    def info(self, text):
        self.lines.append(('info', text))


class Publishers:
    def publish_state(self, state):
        pass

    def publish_reading(self, reading):
        pass


def test_offline_and_online_name_the_address():
    bus, drive, clock, events = make_bus()
    run_for(bus, clock, 0.5)
    drive.silent = True
    run_for(bus, clock, 1.0)
    drive.silent = False
    run_for(bus, clock, 3.0)
    logger = Logger()
    for event in events:
        if isinstance(event, (DeviceOffline, DeviceOnline)):
            assert event.address == 1
            bus_events.publish_event(Publishers(), logger, event)
    assert logger.lines[0] == ('info', 'conv (address 1) online')
    assert logger.lines[1][0] == 'error' and \
        logger.lines[1][1].startswith('conv (address 1) offline: ')
    assert logger.lines[2] == ('info', 'conv (address 1) online')
