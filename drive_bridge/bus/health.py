"""
Device health: what the outcome of each poll says about a device, and the events it makes.

:class:`HealthKeeper` keeps each device's :class:`~drive_bridge.bus.device.DeviceHealth`:
online; offline after ``offline_after`` failed transactions in a row (then probed with
backoff); unknown after as many refused polls; misconfigured on a model mismatch. It tells
the motor-state owner what the device reports (a reading, going offline, coming back) and
emits the events (:mod:`.events`). Every change is made under the device table's lock.
"""

import math
from typing import Callable

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.events import DeviceOffline, DeviceOnline, Notice, ReadingEvent, StateUnknown
from drive_bridge.bus.runner import retryable
from drive_bridge.bus.seams import EventSink
from drive_bridge.bus.table import DeviceTable
from drive_bridge.bus.timing import BusTiming
from drive_bridge.devices.contracts import DeviceReading, PollStep
from drive_bridge.errors import (
    DeviceException, ModelMismatch, MonitorOnly, ProtocolError, TransportError)


class HealthKeeper:
    """Keep each device's health from its polls' outcomes; see the module docstring."""

    def __init__(self, devices: DeviceTable, timing: BusTiming, events: EventSink,
                 clock: Callable[[], float]):
        self.devices = devices
        self.timing = timing
        self.events = events
        self.clock = clock

    def answered(self, device: BusDevice) -> None:
        """Note that a transaction of a poll got a valid reply."""
        with self.devices.locked():
            device.health.consecutive_failures = 0

    def retry(self, device: BusDevice, step: PollStep, attempt: int,
              error: TransportError) -> bool:
        """
        Count a failed poll transaction; return whether to send it again (attempt + 1).

        Only a lost or garbled read is sent again, never a write (a command may have gone out
        between the attempts), and not once the device is offline or about to go.
        """
        with self.devices.locked():
            health = device.health
            if not isinstance(error, DeviceException):
                health.consecutive_failures += 1
            retries = self.timing.retries if health.online is not False else 0
            retry = step.retry and not step.request.writes and retryable(error) and \
                attempt < retries and health.consecutive_failures < self.timing.offline_after
            if retry:
                device.stats.retries += 1
            return retry

    def poll_failed(self, device: BusDevice, error: Exception) -> None:
        """
        Note why a poll gave no reading; go offline or unknown after enough in a row.

        A device that keeps refusing (exception replies) is reachable but unreadable: after
        ``offline_after`` refused polls in a row its state is unknown and its values are
        dropped. One that stops answering goes offline after ``offline_after`` failed
        transactions in a row. Either way a single failure is counted, not reported as a
        change of state.
        """
        with self.devices.locked():
            health = device.health
            health.poll_failure = str(error)
            if isinstance(error, (DeviceException, MonitorOnly)):
                self._refused(device, error)
            elif isinstance(error, ProtocolError):
                device.stats.record_error(TransportError(str(error)))
                health.status_text = str(error)
            elif health.online is False:
                health.backoff(self.timing.backoff_initial_s, self.timing.backoff_max_s,
                               self.clock())
                health.status_text = f'no valid reply since going offline: {error}'
            else:
                health.status_text = f'poll failed ({health.consecutive_failures} failed '\
                    f'transactions in a row): {error}'
                if health.consecutive_failures >= self.timing.offline_after or \
                        health.online is None:
                    self.mark_offline(device, str(error))

    def _refused(self, device: BusDevice, error: Exception) -> None:
        health = device.health
        text = device.profile.explain_exception(error.code) \
            if isinstance(error, DeviceException) else str(error)
        health.poll_failure = text
        health.refused_polls += 1
        health.status_text = f'poll refused ({health.refused_polls} in a row): {text}'
        if health.refused_polls == self.timing.offline_after:
            device.reading = None
            self.events.emit(StateUnknown(device=device.name, stamp_s=self.clock(),
                                          message=health.status_text))

    def mark_offline(self, device: BusDevice, reason: str) -> None:
        """Take ``device`` offline: its values are gone, the run image becomes a stop."""
        with self.devices.locked():
            health = device.health
            was_offline = health.online is False
            health.online = False
            device.reading = None
            device.profile.on_offline()
            device.owner.on_offline(self.clock())
            health.status_text = reason
            health.backoff(self.timing.backoff_initial_s, self.timing.backoff_max_s,
                           self.clock(), first=True)
            if not was_offline:
                self.events.emit(DeviceOffline(device=device.name, stamp_s=self.clock(),
                                               message=reason, address=device.spec.unit))

    def mark_all_offline(self, reason: str) -> None:
        """Take every device offline (the link was lost)."""
        with self.devices.locked():
            for device in self.devices:
                self.mark_offline(device, reason)

    def misconfigured(self, device: BusDevice, error: ModelMismatch) -> None:
        """Note the device is not the model configured: it answers, its values are not read."""
        with self.devices.locked():
            health = device.health
            first = health.misconfigured != str(error)
            health.misconfigured = str(error)
            health.online = True
            health.status_text = str(error)
            device.reading = None
            if first:
                self.events.emit(StateUnknown(device=device.name, stamp_s=self.clock(),
                                              message=str(error)))

    def poll_succeeded(self, device: BusDevice, reading: DeviceReading, started_s: float,
                       received_s: float) -> bool:
        """Take a poll's reading; return whether the device's set-up writes are due now."""
        with self.devices.locked():
            came_online = self._online(device)
            device.reading = reading
            device.reading_time_s = started_s
            notices = [device.owner.on_online(self.clock())] if came_online else []
            notices.append(device.owner.on_reading(reading, started_s))
            if came_online:
                self.events.emit(DeviceOnline(device=device.name, stamp_s=received_s,
                                              reading=reading, address=device.spec.unit))
            self.events.emit(ReadingEvent(device=device.name, stamp_s=received_s,
                                          reading=reading))
            for notice in notices:
                if notice:
                    self.events.emit(Notice(device=device.name, stamp_s=self.clock(),
                                            message=notice))
            if came_online or self.clock() >= device.setup_retry_at_s:
                device.setup_retry_at_s = math.inf
                return True
            return False

    @staticmethod
    def _online(device: BusDevice) -> bool:
        """Mark ``device`` healthy; return whether it came online (or out of a mismatch)."""
        health = device.health
        came_online = health.online is not True or bool(health.misconfigured)
        health.online = True
        health.misconfigured = ''
        health.backoff_s = 0.0
        health.refused_polls = 0
        health.poll_failure = ''
        health.status_text = 'ok'
        device.stats.errors.pop('offline_reported', None)
        return came_online
