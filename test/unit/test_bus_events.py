"""Typed bus events: every consumer has a handler for every type, and dispatches by type."""

import dataclasses

from drive_bridge.bus.events import (
    DeviceOffline, DeviceOnline, EVENT_TYPES, handler_table, ignore, Notice, ReadingEvent,
    StateUnknown)
from drive_bridge.devices.contracts import DeviceReading
from drive_bridge.errors import DeviceException, NoResponse
from fakes import run_for
import pytest
from soak_harness import runner as soak
from test_bus_master import make_bus

READING = DeviceReading(state='ready', status_word=0x0201)
EXAMPLES = {ReadingEvent: ReadingEvent(device='d1', stamp_s=1.0, reading=READING),
            DeviceOnline: DeviceOnline(device='d1', stamp_s=1.0, reading=READING),
            DeviceOffline: DeviceOffline(device='d1', stamp_s=2.0, message='no reply'),
            StateUnknown: StateUnknown(device='d1', stamp_s=3.0, message='poll refused'),
            Notice: Notice(device='d1', stamp_s=4.0, message='tripped: the run ended')}


def test_a_handler_table_names_every_event_type_and_nothing_else():
    every = {kind: ignore for kind in EVENT_TYPES}
    assert handler_table(every) == every
    for left_out in EVENT_TYPES:
        with pytest.raises(TypeError, match=f'missing {left_out.__name__}'):
            handler_table({kind: ignore for kind in EVENT_TYPES if kind is not left_out})
    with pytest.raises(TypeError, match='not bus events: str'):
        handler_table({**every, str: ignore})


def test_events_are_frozen_and_name_their_device_and_time():
    assert set(EXAMPLES) == set(EVENT_TYPES)
    for event in EXAMPLES.values():
        with pytest.raises(dataclasses.FrozenInstanceError):
            event.device = 'other'
        assert event.device == 'd1' and event.stamp_s > 0


def test_the_bus_emits_typed_events_in_the_order_they_happened():
    bus, transport, clock, events = make_bus([1])
    run_for(bus, clock, 0.3)
    transport.failures[1] = NoResponse('no reply')  # offline
    run_for(bus, clock, 5.0)
    transport.failures[1] = DeviceException(4)  # answers, refuses every poll: unknown
    run_for(bus, clock, 20.0)
    kinds = [type(event) for event in events]
    assert set(kinds) == {ReadingEvent, DeviceOnline, DeviceOffline, StateUnknown}
    assert kinds[:2] == [DeviceOnline, ReadingEvent]
    assert kinds.index(DeviceOffline) < kinds.index(StateUnknown)
    assert [event.stamp_s for event in events] == sorted(event.stamp_s for event in events)


def test_the_soak_harness_handles_every_event_type():
    listener = soak._Listener()
    assert set(listener.handlers) == set(EVENT_TYPES)
    listener.log = soak.ClientLog(lambda: 0, lambda: 0.0, exact=True)
    for event in EXAMPLES.values():
        listener(event)
    assert listener.offline == {'d1': True} and listener.offline_events == 1


def test_the_node_shows_every_event_type():
    node_events = pytest.importorskip('drive_bridge.ros.node.bus_events',
                                      reason='ROS 2 (rclpy) from PyPI')
    assert set(node_events.HANDLERS) == set(EVENT_TYPES)

    class Publishers:
        def __init__(self):
            self.sent = []

        def publish_reading(self, reading):
            self.sent.append(reading.state)

        def publish_state(self, state):
            self.sent.append(state)

    class Logger:
        def __init__(self):
            self.lines = []

        def __getattr__(self, level):
            return lambda text: self.lines.append((level, text))

    publishers, logger = Publishers(), Logger()
    for event in EXAMPLES.values():
        node_events.publish_event(publishers, logger, event)
    assert publishers.sent == ['ready', 'offline', 'unknown']
    assert logger.lines == [('info', 'd1 online'), ('error', 'd1 offline: no reply'),
                            ('error', 'd1: poll refused'),
                            ('warning', 'd1: tripped: the run ended')]


def test_the_joint_bridge_handles_every_event_type():
    joints = pytest.importorskip('drive_bridge.ros.node.joints', reason='ROS 2 (rclpy) from PyPI')
    bridge = joints.JointBridge(None, [], lambda message: None, None, lambda: True, 0)
    assert set(bridge.event_handlers) == set(EVENT_TYPES)
