"""
The background refresh: one parameter read at a time, at a low rate, the oldest value first.

Gets are answered from the values held (rqt_reconfigure gives every call 1 s), so they are
kept fresh here: every ``refresh_period`` seconds (a parameter of the device's parameter
node; 0 turns the refresh off) the parameter asked for longest ago (never: first) is read
again. One read is in flight at a time, queued on the bus between its transactions, so the
refresh costs at most one transaction a period on the line; nothing is read while the
device is offline. A value that changed (a keypad edit) is announced on
``/parameter_events`` by :class:`~drive_bridge.ros.node.device_parameters.device.
DeviceParameters`.
"""

from concurrent.futures import Future
import time
from typing import Callable, Dict, Optional

from drive_bridge.ros.node.device_parameters.device import DeviceParameters

DEFAULT_REFRESH_PERIOD_S = 0.5


class Refresher:
    """Reads one parameter of one device every period (executor thread, from a timer)."""

    def __init__(self, device: DeviceParameters, period_s: Callable[[], float],
                 clock: Callable[[], float] = time.monotonic):
        self._device = device
        self._period_s = period_s
        self._clock = clock
        self._in_flight: Optional[Future] = None
        self._last_s = float('-inf')
        self._asked_s: Dict[int, float] = {}

    def tick(self) -> None:
        """Read the next parameter if one period has passed and no read is in flight."""
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
        # The one asked longest ago (never: first); a value that cannot be read (a VLT
        # text on a monitor-only card needs a write first) does not hold the others up.
        parameter = min(parameters, key=lambda p: self._asked_s.get(p.number, float('-inf')))
        self._last_s = self._asked_s[parameter.number] = now
        self._in_flight = self._device.read(parameter)
