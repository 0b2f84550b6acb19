"""
The background refresh: while someone looks, one parameter read at a time, oldest first.

Gets are answered from the values held (rqt_reconfigure gives every call 1 s), so they are
kept fresh here, but only while someone looks at the device's parameters: a call of any of
the node's parameter services (list, describe, get, get types, set) opens a window of
``refresh_while_watched`` seconds (a parameter of the node, default
:data:`DEFAULT_WATCH_WINDOW_S`); within it, every ``refresh_period`` seconds (0 turns the
refresh off) a value not held, else the one asked for longest ago, is read again. When the
window closes the refresh stops and the values held are forgotten (nothing read long ago is
served as current): a get then reads what it asks for on demand, and opens the window again.
With nobody calling, the refresh sends nothing: the line carries only its polls.

One read is in flight at a time, queued on the bus between its transactions, so the refresh
costs at most one transaction a period while watched; nothing is read while the device is
offline. A value that changed (a keypad edit) is announced on ``/parameter_events`` by
:class:`~drive_bridge.ros.node.device_parameters.device.DeviceParameters`.
"""

from concurrent.futures import Future
import time
from typing import Callable, Dict, Optional

from drive_bridge.ros.node.device_parameters.device import DeviceParameters

DEFAULT_REFRESH_PERIOD_S = 0.5
DEFAULT_WATCH_WINDOW_S = 30.0  # the refresh runs this long after the last service call


class Refresher:
    """Reads one parameter of one device every period while watched (executor thread)."""

    def __init__(self, device: DeviceParameters, period_s: Callable[[], float],
                 window_s: Callable[[], float] = lambda: DEFAULT_WATCH_WINDOW_S,
                 clock: Callable[[], float] = time.monotonic):
        self._device = device
        self._period_s = period_s
        self._window_s = window_s
        self._clock = clock
        self._in_flight: Optional[Future] = None
        self._last_s = float('-inf')
        self._watched_s = float('-inf')  # the last service call (never: nobody looks)
        self._watching = False  # within the window at the last tick
        self._asked_s: Dict[int, float] = {}

    def watched(self) -> None:
        """Note a service call: someone looks at the parameters (the window opens again)."""
        self._watched_s = self._clock()
        self._watching = True

    @property
    def active(self) -> bool:
        """Return whether the last tick found the window open (later ticks have work)."""
        return self._watching

    def is_watched(self) -> bool:
        """Return whether the last service call is within the window."""
        return self._clock() - self._watched_s <= self._window_s()

    def tick(self) -> None:
        """Read the next parameter if watched, one period has passed and none is in flight."""
        if not self.is_watched():
            if self._watching:  # the window just closed: values held would only age
                self._watching = False
                self._device.forget()
            return
        period = self._period_s()
        now = self._clock()
        if period <= 0.0 or now - self._last_s < period:
            return
        if self._in_flight is not None and not self._in_flight.done():
            return
        if not self._device.online():
            return
        parameters = self._device.parameters
        if not parameters:
            return
        # A value not held first, then the one asked longest ago (never: first); a value that
        # cannot be read (a VLT text on a monitor-only card needs a write first) does not
        # hold the others up.
        parameter = min(parameters, key=lambda p: (
            self._device.value(p) is not None, self._asked_s.get(p.number, float('-inf'))))
        self._last_s = self._asked_s[parameter.number] = now
        self._in_flight = self._device.read(parameter)
