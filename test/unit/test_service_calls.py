"""The node's command paths without a node: the gate, and service calls awaiting the bus."""

from concurrent.futures import Future
import threading
from types import SimpleNamespace

from drive_bridge.errors import CommandRefused, DriveBridgeError
from drive_bridge.protocol.commands import Command
import pytest

# rclpy is not in the pymodbus 3.6.9 venv (transport tiers only): skipped there.
service_calls = pytest.importorskip('drive_bridge.ros.node.service_calls',
                                    reason='ROS 2 (rclpy) from PyPI')
gate_module = pytest.importorskip('drive_bridge.ros.node.gate', reason='ROS 2 (rclpy) from PyPI')
device_interface = pytest.importorskip('drive_bridge.ros.node.device_interface',
                                       reason='ROS 2 (rclpy) from PyPI')


class FakeGuard:
    def __init__(self):
        self.triggered = 0

    def trigger(self):
        self.triggered += 1


class FakeNode:
    """What ServiceCalls needs of the node: a guard condition, timers; callbacks run here."""

    def __init__(self):
        self.timers = []

    def create_guard_condition(self, callback, callback_group=None):
        self.on_guard = callback
        self.guard = FakeGuard()
        return self.guard

    def create_timer(self, period_s, callback, callback_group=None, clock=None):
        self.timers.append((period_s, callback))
        return self.timers[-1]

    def destroy_timer(self, timer):
        self.timers.remove(timer)


class Call:
    """A service coroutine driven by hand, as the executor drives it."""

    def __init__(self, calls, bus_future, give_up_s=5.0):
        self.coroutine = calls.answer_of(bus_future, 'start', give_up_s)
        self.outcome = None
        self.step()

    def step(self):
        try:
            self.coroutine.send(None)
        except StopIteration as done:
            self.outcome = done.value
        except Exception as error:  # noqa: B902 - the outcome under test
            self.outcome = error


def bench():
    node = FakeNode()
    return node, service_calls.ServiceCalls(node)


def test_the_bus_s_answer_reaches_the_awaiting_service_through_the_guard():
    node, calls = bench()
    bus_future = Future()
    call = Call(calls, bus_future)
    assert call.outcome is None and node.guard.triggered == 0
    bus_future.set_result('start acknowledged')  # the bus thread
    assert node.guard.triggered == 1
    node.on_guard()  # the executor thread
    call.step()
    assert call.outcome == 'start acknowledged'


def test_each_call_that_begins_to_wait_is_told():
    # The parameter nodes start their tick timer again on it (the give-up is looked at).
    node, calls = bench()
    told = []
    calls.on_waiting = lambda: told.append(calls.waiting())
    Call(calls, Future())
    Call(calls, Future())
    assert told == [True, True]


def test_a_refusal_is_raised_in_the_service():
    node, calls = bench()
    bus_future = Future()
    bus_future.set_exception(CommandRefused('offline: nothing sent'))
    call = Call(calls, bus_future)
    assert node.guard.triggered >= 1  # done before it was awaited: looked at at once
    node.on_guard()
    call.step()
    assert isinstance(call.outcome, CommandRefused)


def test_a_call_past_its_give_up_time_is_cancelled_before_it_is_sent():
    node, calls = bench()
    bus_future = Future()
    call = Call(calls, bus_future, give_up_s=-1.0)
    calls.wake()  # the diagnostics timer
    node.on_guard()
    call.step()
    assert bus_future.cancelled()
    assert not bus_future.set_running_or_notify_cancel()  # the bus will never send it
    assert isinstance(call.outcome, CommandRefused)
    assert 'never sent' in str(call.outcome)


def test_a_call_already_on_the_wire_when_given_up_is_not_confirmed():
    node, calls = bench()
    bus_future = Future()
    assert bus_future.set_running_or_notify_cancel()  # the bus is sending it
    call = Call(calls, bus_future, give_up_s=-1.0)
    node.on_guard()
    call.step()
    assert type(call.outcome) is DriveBridgeError and 'may be on the wire' in str(call.outcome)


def test_a_call_within_its_time_waits_on():
    node, calls = bench()
    call = Call(calls, Future(), give_up_s=60.0)
    node.on_guard()
    call.step()
    assert call.outcome is None


def test_closing_the_bus_refuses_what_was_not_sent_and_confirms_nothing_on_the_wire():
    # A call on the wire when the bus closes may have been carried out (a start may be
    # running): it is answered "not confirmed", never "refused"; one the bus answered meanwhile
    # keeps its answer.
    node, calls = bench()
    waiting, running, answered = Future(), Future(), Future()
    assert running.set_running_or_notify_cancel()
    first, second, third = Call(calls, waiting), Call(calls, running), Call(calls, answered)
    answered.set_result('start acknowledged')
    calls.answer_all('the bus was closed')
    for call in (first, second, third):
        call.step()
    assert waiting.cancelled() and not running.cancelled()
    assert str(first.outcome) == 'start: the bus was closed'
    assert isinstance(first.outcome, CommandRefused)
    assert type(second.outcome) is DriveBridgeError and 'not confirmed' in str(second.outcome)
    assert third.outcome == 'start acknowledged'


def test_services_that_just_answered_are_destroyed_only_after_the_grace_time():
    node, calls = bench()
    destroyed = []
    calls.destroy_later(lambda: destroyed.append('motor'))
    calls.destroy_later(lambda: destroyed.append('pump'))
    assert destroyed == []  # the answers may still be on their way to the clients
    assert [period_s for period_s, _ in node.timers] == [service_calls.RESPONSE_GRACE_S]
    node.timers[0][1]()  # the grace time passed
    assert destroyed == ['motor', 'pump'] and node.timers == []
    calls.destroy_retired()
    assert destroyed == ['motor', 'pump']  # once


def test_a_new_configuration_destroys_the_retired_services_at_once():
    node, calls = bench()
    destroyed = []
    calls.destroy_later(lambda: destroyed.append('motor'))
    calls.destroy_retired()
    assert destroyed == ['motor'] and node.timers == []


def test_the_last_answer_of_a_closed_device_retires_its_services_for_the_grace_time():
    node, calls = bench()
    destroyed = []
    interface = SimpleNamespace(  # a DeviceInterface whose bus closed during one call
        _lock=threading.Lock(), _calls_in_progress=1, _closing=True,
        _paths=SimpleNamespace(calls=calls), _node=SimpleNamespace(executor=None),
        _destroy_services=lambda: destroyed.append('motor'))
    device_interface.DeviceInterface._call_ended(interface)
    assert destroyed == [] and len(node.timers) == 1  # its answer is still on its way
    node.timers[0][1]()
    assert destroyed == ['motor']


def test_the_gate_takes_stops_only_while_inactive_and_nothing_once_closed():
    gate = gate_module.CommandGate(lambda: 'inactive')
    bus = object()
    with pytest.raises(CommandRefused, match='node is inactive'):
        gate.bus_for(Command.STOP)  # no bus yet
    gate.bus = bus
    assert gate.bus_for(Command.STOP) is bus
    with pytest.raises(CommandRefused, match=r'node is inactive \(lifecycle\): activate it'):
        gate.bus_for(Command.START)
    gate.active = True
    assert gate.bus_for(Command.START) is bus and gate.is_active()
    gate.bus = None  # closing
    for command in (Command.START, Command.STOP):
        with pytest.raises(CommandRefused):
            gate.bus_for(command)
