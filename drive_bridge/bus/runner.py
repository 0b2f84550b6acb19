"""
Running transactions and poll cycles: one place for the bus thread and the CLI.

:class:`TransactionRunner` runs one request on the transport for one device: it keeps the
inter-frame gap, refuses a write to a monitor-only device before anything reaches the wire,
and keeps the device's statistics. :class:`PollRun` is one poll cycle in progress: the bus
runs its steps one at a time, so commands go on the wire between them;
:func:`run_poll` runs a whole cycle at once (the CLI).
"""

import time
from typing import Any, Callable, Optional

from drive_bridge.bus.device import BusDevice
from drive_bridge.devices.contracts import DeviceReading, PollCycle, PollStep
from drive_bridge.errors import (
    BadFrame, DeviceException, LinkDown, MonitorOnly, NoResponse, ProtocolError, TransportError)
from drive_bridge.protocol.requests import Request
from drive_bridge.transport.base import Transport

# What decoding a reply may raise: the poll (or parameter access) failed, the bus goes on.
DECODE_ERRORS = (ProtocolError, ValueError, IndexError, KeyError, TypeError)


class TransactionRunner:
    """Run single requests: gap, monitor-only guard, statistics; see the module docstring."""

    def __init__(self, transport: Transport, frame_gap_s: float = 0.0,
                 slow_reply_s: float = 0.0, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 by_unit: Optional[Callable[[int], Optional[BusDevice]]] = None):
        self.transport = transport
        self.by_unit = by_unit  # the device of a unit, to count its late replies against
        self.frame_gap_s = frame_gap_s
        self.slow_reply_s = slow_reply_s  # a valid reply slower than this counts as slow
        self.clock = clock
        self.sleep = sleep
        self.last_end_s = -float('inf')
        self.in_flight_s = 0.0  # the bus's own work while the last request was on the wire

    @property
    def reports_request_sent(self) -> bool:
        """Return whether the transport reports each request as it leaves (see Transport)."""
        return self.transport.reports_request_sent

    def while_in_flight(self, work: Callable[[], None]) -> Callable[[], None]:
        """Return ``work`` timed as work done while a request is on the wire (not its RTT)."""
        def timed() -> None:
            started = self.clock()
            try:
                work()
            finally:
                self.in_flight_s += self.clock() - started
        return timed

    def gap_left_s(self, now: float) -> float:
        """Return how much longer the line must stay silent before the next frame."""
        return self.last_end_s + self.frame_gap_s - now

    def transact(self, device: BusDevice, request: Request) -> Any:
        """Run ``request`` with ``device``; raise MonitorOnly for a write it may not get."""
        if request.writes and not device.owner.writes_allowed:
            device.stats.refused_writes += 1
            raise MonitorOnly(f'{device.name} is monitor only (allow_control is false): '
                              f'{request.describe()} not sent')
        gap_s = self.gap_left_s(self.clock())
        if gap_s > 0:
            self.sleep(gap_s)
        started = self.clock()
        self.in_flight_s = 0.0
        try:
            result = self.transport.execute(device.spec.unit, request)
        except TransportError as error:
            self._ended(device)
            device.stats.record_error(error)
            raise
        ended_s = self.clock()
        self._ended(device)
        report = self.transport.last_report
        rtt_s = ended_s - report.after_answer_s - report.held_s - started - self.in_flight_s
        device.stats.record_ok(rtt_s, slow=0 < self.slow_reply_s < rtt_s)
        return result

    def _ended(self, device: BusDevice) -> None:
        """
        Note when the line went quiet and count what the transaction recovered or discarded.

        The transport may already have kept part of the gap after the last byte (its end of
        frame check, a quarantine): the gap before the next request counts from the last
        byte. Failures it recovered from itself (AP ASCII NAKs) go to ``device``; each late
        frame it discarded to the device of the unit it names (``device`` where it names
        none, or no device of this bus), and bytes that were no frame to ``device``.
        """
        transport = self.transport
        report = transport.last_report
        self.last_end_s = self.clock() - report.quiet_s
        for kind, count in transport.last_recovered.items():
            device.stats.errors[kind] += count
        for frame in report.late:
            named = None if frame.unit is None or self.by_unit is None else \
                self.by_unit(frame.unit)
            (named or device).stats.late_replies += 1
        device.stats.discarded_bytes += report.noise_bytes

    def explain(self, device: BusDevice, error: TransportError) -> str:
        """Return a failure in words; a refusal with the profile's text and detail read."""
        if not isinstance(error, DeviceException):
            return str(error)
        profile = device.profile
        detail = None
        detail_request = profile.detail_request(error.code)
        if detail_request is not None:
            try:
                detail = self.transact(device, detail_request)[0]
            except (TransportError, MonitorOnly, IndexError, TypeError):
                pass  # explained without the detail
        return profile.explain_exception(error.code, detail)


class PollRun:
    """
    One poll cycle of one device in progress.

    The cycle's next step is asked for only when it is about to be sent
    (:meth:`next_step`), so a write it builds carries what is in force at that moment.
    """

    def __init__(self, device: BusDevice, cycle: PollCycle, started_s: float):
        self.device = device
        self.cycle = cycle
        self.started_s = started_s
        self.step: Optional[PollStep] = None
        self.attempt = 0
        self._result: Any = None
        self._started = False
        self.reading: Optional[DeviceReading] = None
        self.received_s = started_s  # when the reply stamping the reading arrived

    def next_step(self) -> Optional[PollStep]:
        """Return the step to send now (the same one while it is retried), or None when done."""
        if self.step is not None or self.reading is not None:
            return self.step
        try:
            if self._started:
                self.step = self.cycle.send(self._result)
            else:
                self._started = True
                self.step = next(self.cycle)
        except StopIteration as done:
            self.reading = done.value
        self.attempt = 0
        return self.step

    def deliver(self, result: Any, received_s: Optional[float] = None) -> None:
        """Hand the current step's result (or the error of an optional step) to the cycle."""
        if received_s is not None and self.step is not None and self.step.stamps:
            self.received_s = received_s
        self._result = result
        self.step = None

    def abandon(self) -> None:
        """Close the cycle (a step failed or the device went away)."""
        self.step = None
        self.cycle.close()


def optional_failure(step: PollStep, error: TransportError) -> bool:
    """Return whether ``error`` goes back to the cycle as the step's result."""
    if isinstance(error, LinkDown):
        return False
    if isinstance(error, DeviceException):
        return step.optional
    return step.optional and not step.retry  # an optional write: any failure


def retryable(error: TransportError) -> bool:
    """Return whether a read may be sent again after ``error`` (lost or garbled reply)."""
    return isinstance(error, (NoResponse, BadFrame))


def run_poll(runner: TransactionRunner, device: BusDevice, retries: int = 0) -> DeviceReading:
    """Run one whole poll cycle of ``device`` now (no commands in between): the CLI's poll."""
    now_s = runner.clock()
    poll = PollRun(device, device.profile.poll(device.owner, now_s), now_s)
    while True:
        step = poll.next_step()
        if step is None:
            return poll.reading
        try:
            result = runner.transact(device, step.request)
        except MonitorOnly as error:
            if not step.optional:
                poll.abandon()
                raise
            result = error
        except TransportError as error:
            if step.retry and retryable(error) and poll.attempt < retries:
                poll.attempt += 1
                continue
            if not optional_failure(step, error):
                poll.abandon()
                raise
            result = error
        poll.deliver(result)
