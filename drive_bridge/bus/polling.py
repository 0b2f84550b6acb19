"""
Poll cycles, step by step, and the health of each device they tell.

:class:`Poller` runs the poll cycle in progress one transaction at a time (the scheduler puts
commands between the steps), retries a lost or garbled read (never a write), and keeps each
device's health: online, offline after ``offline_after`` failed transactions in a row (then
probed with backoff), unknown after as many refused polls, misconfigured on a model
mismatch. It reports readings and changes as events, and a device whose set-up writes are
due (it came online, or a lost set-up reply is to be sent again) through ``setup_due``.
"""

import threading
from typing import Callable, Optional

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.runner import optional_failure, PollRun, retryable, TransactionRunner
from drive_bridge.devices.contracts import DeviceReading
from drive_bridge.errors import (
    DeviceException, LinkDown, ModelMismatch, MonitorOnly, ProtocolError, TransportError)

DECODE_ERRORS = (ProtocolError, ValueError, IndexError, KeyError, TypeError)


class Poller:
    """Run poll cycles and keep device health; see the module docstring."""

    def __init__(self, runner: TransactionRunner, timing, clock: Callable[[], float],
                 lock: threading.RLock, emit: Callable[[BusEvent], None],
                 link_lost: Callable[[str], None], setup_due: Callable[[BusDevice], None]):
        self.runner = runner
        self.timing = timing
        self.clock = clock
        self.lock = lock
        self.emit = emit
        self.link_lost = link_lost
        self.setup_due = setup_due
        self.current: Optional[PollRun] = None  # the poll cycle in progress

    def begin(self, device: BusDevice, now: float) -> None:
        with self.lock:
            device.health.schedule_next(device.poll_period_s, now)
        self.current = PollRun(device, device.profile.poll(device.owner), now)
        self.step(self.current)

    def abandon(self) -> None:
        poll, self.current = self.current, None
        if poll is not None:
            poll.abandon()

    def step(self, poll: PollRun) -> None:
        device = poll.device
        try:
            step = poll.next_step()
        except ModelMismatch as error:
            self.current = None
            self._misconfigured(device, error)
            return
        except DECODE_ERRORS as error:
            self.current = None
            self._poll_failed(device, ProtocolError(f'cannot decode reply: {error}'))
            return
        if step is None:
            self.current = None
            self._poll_succeeded(device, poll.reading, poll.started_s, poll.received_s)
            return
        try:
            result = self.runner.transact(device, step.request)
        except MonitorOnly as error:
            if step.optional:
                poll.deliver(error)
            else:
                self.abandon()
                self._poll_failed(device, error)
            return
        except LinkDown as error:
            self.link_lost(str(error))
            return
        except TransportError as error:
            self._step_failed(poll, step, error)
            return
        with self.lock:
            device.health.consecutive_failures = 0
        poll.deliver(result, self.runner.last_end_s)

    def _step_failed(self, poll: PollRun, step, error: TransportError) -> None:
        device = poll.device
        health = device.health
        with self.lock:
            if not isinstance(error, DeviceException):
                health.consecutive_failures += 1
            retries = self.timing.retries if health.online is not False else 0
            # A write is never sent twice: a command may have gone out between the attempts.
            retry = step.retry and not step.request.writes and retryable(error) and \
                poll.attempt < retries and health.consecutive_failures < self.timing.offline_after
            if retry:
                poll.attempt += 1
                device.stats.retries += 1
                return
        if optional_failure(step, error):
            poll.deliver(error)
            return
        self.abandon()
        self._poll_failed(device, error)

    def _poll_failed(self, device: BusDevice, error: Exception) -> None:
        """
        Note why a poll gave no reading; go offline or unknown after enough in a row.

        A device that keeps refusing (exception replies) is reachable but unreadable: after
        ``offline_after`` refused polls in a row its state is unknown and its values are
        dropped. One that stops answering goes offline after ``offline_after`` failed
        transactions in a row. Either way a single failure is counted, not reported as a
        change of state.
        """
        with self.lock:
            health = device.health
            limit = self.timing.offline_after
            health.poll_failure = str(error)
            if isinstance(error, (DeviceException, MonitorOnly)):
                text = device.profile.explain_exception(error.code) \
                    if isinstance(error, DeviceException) else str(error)
                health.poll_failure = text
                health.refused_polls += 1
                health.status_text = f'poll refused ({health.refused_polls} in a row): {text}'
                if health.refused_polls == limit:
                    device.reading = None
                    self.emit(BusEvent(device.name, 'error', message=health.status_text))
                return
            if isinstance(error, ProtocolError):
                device.stats.record_error(TransportError(str(error)))
                health.status_text = str(error)
                return
            if health.online is False:
                health.backoff(self.timing.backoff_initial_s, self.timing.backoff_max_s,
                               self.clock())
                health.status_text = f'no valid reply since going offline: {error}'
                return
            health.status_text = f'poll failed ({health.consecutive_failures} failed '\
                f'transactions in a row): {error}'
            if health.consecutive_failures >= limit or health.online is None:
                self.mark_offline(device, str(error))

    def mark_offline(self, device: BusDevice, reason: str) -> None:
        was_offline = device.health.online is False
        device.health.online = False
        device.reading = None
        device.profile.on_offline()
        device.owner.on_offline(self.clock())
        device.health.status_text = reason
        device.health.backoff(self.timing.backoff_initial_s, self.timing.backoff_max_s,
                              self.clock(), first=True)
        if self.current is not None and self.current.device is device:
            self.abandon()
        if not was_offline:
            self.emit(BusEvent(device.name, 'offline', message=reason))

    def _misconfigured(self, device: BusDevice, error: ModelMismatch) -> None:
        with self.lock:
            health = device.health
            first = health.misconfigured != str(error)
            health.misconfigured = str(error)
            health.online = True
            health.status_text = str(error)
            device.reading = None
            if first:
                self.emit(BusEvent(device.name, 'error', message=str(error)))

    def _poll_succeeded(self, device: BusDevice, reading: DeviceReading,
                        started_s: float, received_s: float) -> None:
        notices = []
        with self.lock:
            health = device.health
            came_online = health.online is not True or bool(health.misconfigured)
            health.online = True
            health.misconfigured = ''
            health.backoff_s = 0.0
            health.refused_polls = 0
            health.poll_failure = ''
            health.status_text = 'ok'
            device.reading = reading
            device.reading_time_s = started_s
            device.stats.errors.pop('offline_reported', None)
            if came_online:
                notices.append(device.owner.on_online(self.clock()))
            notices.append(device.owner.on_reading(reading, started_s))
            if came_online:
                self.emit(BusEvent(device.name, 'online', reading=reading, stamp_s=received_s))
            self.emit(BusEvent(device.name, 'reading', reading=reading, stamp_s=received_s))
            for notice in notices:
                if notice:
                    self.emit(BusEvent(device.name, 'notice', message=notice))
            if came_online or self.clock() >= device.setup_retry_at_s:
                self.setup_due(device)
