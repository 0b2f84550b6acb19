"""The device parameter nodes' pure parts: the refresh while watched, forgetting, reasons."""

from concurrent.futures import Future

import pytest

# rclpy is not in the pymodbus 3.6.9 venv (transport tiers only): skipped there.
pytest.importorskip('rcl_interfaces.msg', reason='ROS 2 (rclpy) from PyPI')

from drive_bridge.ros.node.device_parameters import messages  # noqa: E402, I100
from drive_bridge.ros.node.device_parameters.cache import ValueCache  # noqa: E402
from drive_bridge.ros.node.device_parameters.refresher import (  # noqa: E402
    DEFAULT_WATCH_WINDOW_S, Refresher)
from drive_bridge.ros.node.device_parameters.writer import nothing_written  # noqa: E402
from rcl_interfaces.msg import ParameterType, ParameterValue  # noqa: E402


class Parameter:
    def __init__(self, number: int):
        self.number = number
        self.name = f'p{number}'


class Device:
    """A device's parameters as the refresher sees them: reads answered at once."""

    def __init__(self, numbers=(1, 2, 3)):
        self.parameters = [Parameter(number) for number in numbers]
        self.cache = ValueCache()
        self.is_online = True
        self.reads = []

    def online(self) -> bool:
        return self.is_online

    def value(self, parameter):
        return self.cache.value(parameter.number)

    def forget(self) -> None:
        self.cache.forget()

    def read(self, parameter) -> Future:
        self.reads.append(parameter.number)
        self.cache.store(parameter.number, 10 * parameter.number)
        future = Future()
        future.set_result(10 * parameter.number)
        return future


def refresher(device, period_s=0.5, window_s=DEFAULT_WATCH_WINDOW_S):
    now = [100.0]
    return Refresher(device, lambda: period_s, lambda: window_s, clock=lambda: now[0]), now


def run(refresh, now, seconds, step_s=0.1):
    for _ in range(round(seconds / step_s)):
        now[0] += step_s
        refresh.tick()


def test_nothing_is_read_until_someone_looks():
    device = Device()
    refresh, now = refresher(device)
    run(refresh, now, 3600.0, step_s=1.0)
    assert device.reads == []


def test_a_call_refreshes_for_the_window_then_the_refresh_stops_and_forgets():
    device = Device()
    refresh, now = refresher(device, period_s=0.5, window_s=5.0)
    refresh.watched()
    run(refresh, now, 5.0)
    assert 9 <= len(device.reads) <= 11  # one read a period, within the window
    assert device.reads[:3] == [1, 2, 3]  # never read first, then the oldest
    assert len(device.cache) == 3
    reads = len(device.reads)
    run(refresh, now, 60.0)
    assert len(device.reads) == reads  # the window closed: nothing more
    assert len(device.cache) == 0  # and nothing read long ago is held
    refresh.watched()  # someone looks again
    run(refresh, now, 1.0)
    assert len(device.reads) > reads


def test_active_until_the_tick_that_forgets():
    # The parameter node cancels its timer when the refresher is no longer active: that must
    # be the tick that forgot the values, not a look at the clock after it (a window that
    # closed between the two would have left its values held, then served as current).
    device = Device()
    refresh, now = refresher(device, period_s=0.5, window_s=1.0)
    assert not refresh.active  # nobody looked yet: the timer may stop
    refresh.watched()
    assert refresh.active
    run(refresh, now, 1.0)
    assert len(device.cache) > 0 and refresh.active
    now[0] += 0.5  # the window closed, no tick yet
    assert not refresh.is_watched() and refresh.active  # still active: a tick has work
    refresh.tick()
    assert not refresh.active and len(device.cache) == 0


def test_values_not_held_are_read_first():
    device = Device()
    refresh, now = refresher(device, period_s=0.5)
    device.cache.store(1, 10)
    device.cache.store(2, 20)
    refresh.watched()
    run(refresh, now, 0.5)
    assert device.reads == [3]


def test_window_zero_or_period_zero_never_reads_in_the_background():
    for period_s, window_s in ((0.5, 0.0), (0.0, 30.0)):
        device = Device()
        refresh, now = refresher(device, period_s, window_s)
        refresh.watched()
        run(refresh, now, 10.0)
        assert device.reads == [], (period_s, window_s)


def test_nothing_read_while_offline():
    device = Device()
    device.is_online = False
    refresh, now = refresher(device)
    refresh.watched()
    run(refresh, now, 5.0)
    assert device.reads == []


def test_a_value_read_before_a_forgetting_is_not_kept():
    cache = ValueCache()
    generation = cache.generation  # a read queued
    cache.forget()  # the device went offline before its answer came
    assert cache.store(341, 3.0, generation) is None and cache.value(341) is None
    cache.refused(341, 'rejected by conv: no', generation)
    assert cache.error(341) == ''
    assert cache.store(341, 4.0, cache.generation) is None and cache.value(341) == 4.0


def test_an_unknown_type_code_is_refused_not_taken_as_no_value():
    assert messages.type_refusal(ParameterValue(type=99)) == 'unknown parameter type 99'
    assert messages.type_refusal(ParameterValue(type=ParameterType.PARAMETER_NOT_SET)) == ''
    assert messages.type_refusal(ParameterValue(type=ParameterType.PARAMETER_INTEGER)) == ''


def test_values_in_reasons_are_cut():
    value = list(range(100000))
    reason = messages.short_reason(f'p1_23 takes a number, not {value!r}; nothing written',
                                   value)
    assert len(reason) < 200 and reason.endswith('nothing written')
    assert '[0, 1, 2' in reason and '... (100000 items)' in reason
    text = 'x' * 1000
    reason = messages.short_reason(f'Display Text 1: {text!r} is longer than 20 characters',
                                   text)
    assert "'xxx" in reason and '(1000 characters)' in reason and len(reason) < 150
    assert messages.short_reason('short: 5.0; nothing written', 5.0) == \
        'short: 5.0; nothing written'
    long = messages.short_reason('a\nb' + 'z' * 5000 + ' nothing written', 1)
    assert len(long) <= messages.MAX_REASON_CHARS and '\n' not in long
    assert long.endswith('nothing written')


def test_refusals_of_the_bus_end_nothing_written():
    assert nothing_written('fan is offline (no answer): nothing sent') == \
        'fan is offline (no answer): nothing written'
    assert nothing_written('rejected by conv: not possible in the present mode') == \
        'rejected by conv: not possible in the present mode; nothing written'
    assert nothing_written('3-41: nothing written') == '3-41: nothing written'
