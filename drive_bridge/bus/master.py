"""
The bus master: one thread owns one bus and everything that happens on it.

A thin scheduler over parts with one job each: the link supervisor (:mod:`.link`), each
device's health, statistics and motor-state owner (:mod:`.device`, :mod:`.motor`), the
transaction runner (:mod:`.runner`), the job queue with its deadlines (:mod:`.jobs`) and
the deadman (:mod:`.deadman`).

Each step of :meth:`BusMaster.run_once` is one transaction or none: a waiting job (stops
first, then other commands, parameters and set-up writes), else the next step of the poll
cycle in progress, else the first step of the next device that is due. So a command goes
on the wire between two transactions of a poll, never later than the one on the wire when
it arrived. Commands carry a deadline and are never repeated; the motor-state owner decides
what may be sent (see :mod:`.motor` and the README's "Safety model").

:meth:`run_once` has no waiting of its own, so unit tests drive it with a fake clock and a
fake transport; :meth:`start` runs it on a thread.
"""

from concurrent.futures import Future
from dataclasses import dataclass, field
import math
import threading
import time
from typing import Any, Callable, Dict, FrozenSet, List, Mapping, Optional, Union

from drive_bridge.bus import deadman
from drive_bridge.bus.device import BusDevice, DeviceSpec
from drive_bridge.bus.jobs import (
    CommandJob, Job, JobQueue, ParameterJob, SetupJob, StopAllJob)
from drive_bridge.bus.link import LinkSupervisor
from drive_bridge.bus.motor import Motion
from drive_bridge.bus.runner import optional_failure, PollRun, retryable, TransactionRunner
from drive_bridge.devices.contracts import (
    DeviceReading, ParameterAccess, ParameterOptions, SetupWrites, SpeedReference)
from drive_bridge.errors import (
    CommandExpired, CommandRefused, DeviceException, LinkDown, ModelMismatch, MonitorOnly,
    ProtocolError, TransportError)
from drive_bridge.protocol.commands import Command
from drive_bridge.transport.base import Transport

__all__ = ['BusEvent', 'BusMaster', 'BusTiming', 'DeviceSnapshot', 'DeviceSpec']
DECODE_ERRORS = (ProtocolError, ValueError, IndexError, KeyError, TypeError)
SETUP_RETRY_S = 1.0  # a set-up write whose reply was lost is sent again after this pause


@dataclass
class BusTiming:
    """Retry and timing policy of one bus; times in seconds."""

    retries: int = 2
    offline_after: int = 3
    backoff_initial_s: float = 1.0
    backoff_max_s: float = 10.0
    frame_gap_s: float = 0.0
    command_deadline_s: float = 2.0  # a command not on the wire by then is dropped
    transaction_timeout_s: float = 0.5  # the link's timeout: the longest one transaction waits
    slow_reply_s: float = 0.0  # a valid reply slower than this counts as slow; 0 = off


@dataclass
class DeviceSnapshot:
    """A copy of one device's state for readers outside the bus thread."""

    name: str
    unit: int
    family: str
    model: str
    online: Optional[bool]
    status_text: str
    reading: Optional[DeviceReading]
    reading_age_s: float
    poll_failure: str
    stats: Dict[str, str]
    motor: str  # the motor-state owner's account, in words
    motion: Motion
    holds_run: bool
    allow_control: bool
    commands: FrozenSet[Command] = frozenset()
    reading_fields: FrozenSet[str] = frozenset()
    control: str = ''
    hardware: Dict[str, str] = field(default_factory=dict)


@dataclass
class BusEvent:
    """What the bus tells its listener: a new reading, or a change of link status."""

    device: str
    kind: str  # 'reading', 'offline', 'online', 'error' (state unknown), 'notice' (a log line)
    reading: Optional[DeviceReading] = None
    message: str = ''
    stamp_s: float = 0.0  # the bus clock when the reading's poll began


class BusMaster:
    """Own one bus: poll, command, track links; see the module docstring."""

    def __init__(self, transport: Transport, devices: List[DeviceSpec],
                 timing: Optional[BusTiming] = None,
                 listener: Optional[Callable[[BusEvent], None]] = None,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep):
        self.transport = transport
        self.timing = timing or BusTiming()
        self.listener = listener or (lambda event: None)
        self.clock = clock
        now = clock()
        self._devices: Dict[str, BusDevice] = {spec.name: BusDevice(spec, now)
                                               for spec in devices}
        self._jobs = JobQueue()
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._running = False
        self._commands_enabled = True
        self._poll: Optional[PollRun] = None
        self._link = LinkSupervisor(transport, self.timing.backoff_initial_s,
                                    self.timing.backoff_max_s, clock)
        self._runner = TransactionRunner(transport, self.timing.frame_gap_s,
                                         self.timing.slow_reply_s, clock, sleep)
        self.internal_errors = 0
        self.last_internal_error = ''

    # -- public API (any thread) --------------------------------------------------------
    @property
    def device_names(self) -> List[str]:
        """Return the configured device names in order."""
        return list(self._devices)

    @property
    def link_error(self) -> str:
        """Return why the link is down, or '' when it is up."""
        return self._link.error

    @property
    def commands_enabled(self) -> bool:
        """Return whether commands other than stops are taken (the node is active)."""
        return self._commands_enabled

    def snapshot(self, name: str) -> DeviceSnapshot:
        """Return a copy of one device's state."""
        with self._lock:
            device = self._devices[name]
            profile = device.profile
            owner = device.owner
            return DeviceSnapshot(
                name=name, unit=device.spec.unit, family=profile.family, model=profile.model,
                online=device.health.online, status_text=device.health.status_text,
                reading=device.reading,
                reading_age_s=self.clock() - device.reading_time_s,
                poll_failure=device.health.poll_failure,
                stats=self._device_stats(device), motor=owner.describe(),
                motion=owner.motion, holds_run=owner.holds_run,
                allow_control=owner.allow_control, commands=profile.commands,
                reading_fields=profile.reading_fields,
                control=profile.describe_control(owner))

    @staticmethod
    def _device_stats(device: BusDevice) -> Dict[str, str]:
        stats = device.stats.as_dict()
        if device.setup_error:
            stats['setup_error'] = device.setup_error
        if isinstance(device.profile, SpeedReference):
            stats['rejected_references'] = str(device.rejected_references)
            stats['deadman_stops'] = str(device.deadman_stops)
            stats['reference_timeout_s'] = f'{device.spec.reference_timeout_s:g}'
        return stats

    def transaction_count(self) -> int:
        """Return the transactions run on this bus so far, every device together."""
        with self._lock:
            return sum(device.stats.transactions for device in self._devices.values())

    def submit_command(self, name: str, command: Union[Command, str],
                       deadline_s: Optional[float] = None) -> Future:
        """
        Queue ``command`` for device ``name``; the future gives the outcome in words.

        A command refused before sending resolves at once with CommandRefused. One that is
        not on the wire ``deadline_s`` seconds from now (default: the bus's command
        deadline) resolves with CommandExpired and is never sent.
        """
        future: Future = Future()
        try:
            command = Command.parse(command) if isinstance(command, str) else command
            with self._lock:
                device = self._known_device(name)
                self._admit(device, command)
                deadline = self.clock() + (self.timing.command_deadline_s if deadline_s is None
                                           else deadline_s)
                self._enqueue(CommandJob(device, deadline, future, command))
        except (CommandRefused, ValueError) as error:
            future.set_exception(error if isinstance(error, CommandRefused)
                                 else CommandRefused(str(error)))
        return future

    def read_parameter(self, name: str, number: int,
                       options: ParameterOptions = ParameterOptions()) -> Future:
        """Queue a read of parameter ``number``; the future gives its value."""
        return self._parameter_job(name, number, None, options)

    def write_parameter(self, name: str, number: int, value: Any,
                        options: ParameterOptions = ParameterOptions()) -> Future:
        """Queue a write of parameter ``number``; the future resolves on acknowledgement."""
        return self._parameter_job(name, number, value, options)

    def _parameter_job(self, name: str, number: int, value: Any,
                       options: ParameterOptions) -> Future:
        future: Future = Future()
        try:
            with self._lock:
                device = self._known_device(name)
                profile = device.profile
                if not isinstance(profile, ParameterAccess):
                    raise CommandRefused(f'{name} ({profile.family}) has no parameter access')
                plan = profile.parameter_plan(number, value, options)
                if any(request.writes for request in plan.transactions) and \
                        not device.owner.writes_allowed:
                    raise MonitorOnly(f'{name} is monitor only (allow_control is false): '
                                      f'{plan.label} not sent')
                self._check_reachable(device)
                self._enqueue(ParameterJob(device, self.clock() + self._job_time_s(plan),
                                           future, plan))
        except CommandRefused as error:
            future.set_exception(error)
        return future

    def _job_time_s(self, plan) -> float:
        return self.timing.command_deadline_s + len(plan.transactions) * \
            self.timing.transaction_timeout_s

    def set_speed_reference(self, name: str, percent: float, from_topic: bool = False) -> int:
        """
        Set a drive's speed reference; it goes out with the next cyclic write.

        ``from_topic`` feeds the deadman. Raises CommandRefused (nothing sent, counted) for
        a device without a reference, a monitor-only device, or a value that is not finite
        or outside [-200, 200) %; returns the 16-bit reference word.
        """
        with self._lock:
            device = self._known_device(name)
            word = self._checked_reference(device, percent)
            device.owner.set_reference_word(word)
            device.reference_pct = float(percent)
            if from_topic:
                deadman.feed(device, self.clock())
        return word

    def feed_deadman(self, name: str) -> None:
        """Count a command message for the deadman (reference_timeout_s)."""
        with self._lock:
            deadman.feed(self._known_device(name), self.clock())

    def _checked_reference(self, device: BusDevice, percent: float) -> int:
        profile = device.profile
        if not isinstance(profile, SpeedReference):
            raise CommandRefused(f'{device.name} ({profile.family}) takes no speed reference')
        try:
            if not device.owner.allow_control:
                raise MonitorOnly(f'{device.name} is monitor only (allow_control is false): '
                                  'speed reference not taken')
            return profile.reference_word(percent)
        except CommandRefused:
            device.rejected_references += 1
            raise

    def apply_settings(self, changes: Mapping[str, Mapping[str, Any]]) -> None:
        """
        Apply runtime settings of several devices at once, or none of them.

        ``changes``: device -> {setting: value} with settings ``allow_control``,
        ``poll_rate``, ``stop_on_shutdown``, ``reference_timeout``, ``speed_reference``
        (values already type-checked). Raises CommandRefused with the reason, having
        changed nothing, if any change is refused (a switch to monitor-only while the
        bridge holds a run command; a reference the device cannot take).
        """
        with self._lock:
            words = {}
            for name, settings in changes.items():
                device = self._known_device(name)
                if settings.get('allow_control') is False:
                    device.owner.check_monitor_only()
                if 'speed_reference' in settings:
                    allow = settings.get('allow_control', device.owner.allow_control)
                    if not allow and settings['speed_reference'] != device.reference_pct:
                        raise MonitorOnly(f'{name} is monitor only (allow_control is false): '
                                          'speed reference not taken')
                    words[name] = device.profile.reference_word(settings['speed_reference']) \
                        if isinstance(device.profile, SpeedReference) else None
            for name, settings in changes.items():
                self._apply(self._devices[name], settings, words.get(name))
        self._wake.set()

    def _apply(self, device: BusDevice, settings: Mapping[str, Any],
               reference_word: Optional[int]) -> None:
        spec = device.spec
        if 'allow_control' in settings:
            device.owner.set_allow_control(settings['allow_control'])
            spec.allow_control = settings['allow_control']
        if 'poll_rate' in settings:
            spec.poll_rate_hz = settings['poll_rate']
        if 'stop_on_shutdown' in settings:
            spec.stop_on_shutdown = settings['stop_on_shutdown']
        if 'reference_timeout' in settings:
            spec.reference_timeout_s = settings['reference_timeout']
            deadman.feed(device, self.clock())
        if reference_word is not None:
            device.owner.set_reference_word(reference_word)
            device.reference_pct = float(settings['speed_reference'])

    def set_commands_enabled(self, enabled: bool) -> None:
        """Take commands (node active) or only stops of motors that may run (inactive)."""
        with self._lock:
            self._commands_enabled = enabled

    def begin_stop_all(self, reason: str, timeout_s: float = 3.0) -> Future:
        """
        Stop every motor that may run because of the bridge; the future gives the outcomes.

        From now on only stops are taken; waiting commands that are not stops are dropped
        unsent. The stops go out on the bus thread after the transaction on the wire now,
        so a start in flight is settled first and counted if it may have run. Devices with
        ``stop_on_shutdown`` false are left as they are, but their cyclic image is no
        longer written.
        """
        with self._lock:
            self._commands_enabled = False
            for job in self._jobs.remove(keep=lambda job: job.urgent):
                self._fail(job, CommandRefused(f'{reason}: {job.describe()} not sent'))
            job = StopAllJob(None, self.clock() + timeout_s, reason=reason)
            self._jobs.push_front(job)
        self._wake.set()
        return job.future

    def stop_all(self, reason: str, timeout_s: float = 3.0) -> List[str]:
        """Stop every motor that may run because of the bridge and wait; see begin_stop_all."""
        future = self.begin_stop_all(reason, timeout_s)
        if self._thread is None or not self._thread.is_alive():
            deadline = self.clock() + timeout_s + self.timing.transaction_timeout_s
            while not future.done() and self.clock() < deadline:
                self.run_once()
        try:
            return future.result(timeout=timeout_s + 2 * self.timing.transaction_timeout_s)
        except Exception as error:  # noqa: B902 - reported in words, never raised here
            return [f'stop of every motor ({reason}) did not finish: {error!r}']

    def _known_device(self, name: str) -> BusDevice:
        device = self._devices.get(name)
        if device is None:
            raise CommandRefused(
                f'unknown device {name!r}: this bus has {", ".join(self._devices)}')
        return device

    def _admit(self, device: BusDevice, command: Command) -> None:
        """Raise CommandRefused (nothing sent) unless ``command`` may be sent now."""
        if command not in device.profile.commands:
            raise CommandRefused(f'{device.name} ({device.profile.family}) has no '
                                 f'{command.value} command')
        device.owner.admit(command, self._commands_enabled)
        if command.stops and device.owner.holds_run:
            if self._link.error:
                raise CommandRefused(f'{self._link.error}: nothing sent')
            return
        self._check_reachable(device)
        if device.health.misconfigured:
            raise CommandRefused(f'{device.name}: {device.health.misconfigured}: nothing sent')
        reading = device.reading
        if command.may_start and reading is not None and reading.tripped:
            trip = reading.trip_name or 'no trip name'
            raise CommandRefused(f'{device.name} is tripped ({trip}): reset it first; '
                                 'nothing sent')
        device.profile.check_command(command, reading)

    def _check_reachable(self, device: BusDevice) -> None:
        if self._link.error:
            raise CommandRefused(f'{self._link.error}: nothing sent')
        if device.health.online is not True:
            raise CommandRefused(f'{device.name} is offline ({device.health.status_text}): '
                                 'nothing sent')

    def _enqueue(self, job: Job) -> None:
        self._jobs.push(job)
        self._wake.set()

    # -- thread -------------------------------------------------------------------------
    def start(self) -> 'BusMaster':
        """Run the bus on its own thread."""
        self._running = True
        self._thread = threading.Thread(target=self._run, name='drive-bridge-bus', daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        while self._running:
            try:
                wait_s = self.run_once()
            except Exception as error:  # noqa: B902 - the bus thread must never die
                wait_s = self._internal_error(error)
            if wait_s > 0 and self._running:
                self._wake.wait(wait_s)
                self._wake.clear()

    def _internal_error(self, error: Exception) -> float:
        """
        Survive a bug or an unexpected library error: report the bus offline and reopen it.

        Nothing read since is trusted: every device goes offline at once (listeners are
        told) and the link is reopened with backoff, as after a lost port.
        """
        self.internal_errors += 1
        self.last_internal_error = f'{type(error).__name__}: {error}'
        try:
            self._abandon_poll()
            self._link_lost(f'bus offline: internal error ({self.last_internal_error}); '
                            'reopening the link')
        except Exception:  # noqa: B902 - the bus thread must never die
            pass
        return 0.1

    def shutdown(self, stop_motors: bool = True, timeout_s: float = 3.0) -> List[str]:
        """
        Stop the motors that may run because of the bridge (if asked), then close the bus.

        Returns what happened to each stop, in words.
        """
        outcomes = self.stop_all('shutdown', timeout_s) if stop_motors else []
        with self._lock:
            self._commands_enabled = False
        self._running = False
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout_s + 1.0)
        self.transport.close()
        return outcomes

    # -- one scheduling step ------------------------------------------------------------
    def run_once(self) -> float:
        """Do the next piece of bus work; return how long to wait before the next one."""
        now = self.clock()
        if not self._link.up:
            wait_s = self._link.wait_s(now)
            if wait_s > 0 or not self._open_link():
                self._drain_jobs_while_down()
                return max(self._link.wait_s(self.clock()), 0.001)
        self._expire_jobs(now)
        self._check_deadmen(now)
        with self._lock:
            job = self._jobs.pop()
        if job is not None:
            self._run_job(job)
            return 0.0
        if self._poll is not None:
            self._run_poll_step(self._poll)
            return 0.0
        device = self._next_due_device()
        if device is None:
            return 0.1
        wait_s = device.health.next_due_s - now
        if wait_s > 0:
            return wait_s
        self._begin_poll(device, now)
        return 0.0

    def _next_due_device(self) -> Optional[BusDevice]:
        with self._lock:
            if not self._devices:
                return None
            return min(self._devices.values(), key=lambda device: device.health.next_due_s)

    def _expire_jobs(self, now: float) -> None:
        with self._lock:
            expired = self._jobs.remove(keep=lambda job: now <= job.deadline_s or
                                        isinstance(job, StopAllJob))
        for job in expired:
            self._fail(job, CommandExpired(
                f'{job.describe()} not sent: the bus did not get to it within its deadline '
                f'({job.deadline_s - now:+.2f} s); it is dropped and never sent'))

    def _check_deadmen(self, now: float) -> None:
        with self._lock:
            for device in self._devices.values():
                if deadman.expired(device, now):
                    future: Future = Future()
                    future.add_done_callback(
                        lambda done, d=device: self._deadman_done(d, done))
                    self._jobs.push(CommandJob(device, now + self.timing.command_deadline_s,
                                               future, Command.STOP, internal='deadman'))

    def _deadman_done(self, device: BusDevice, future: Future) -> None:
        error = future.exception()
        text = deadman.message(device) + (f' failed: {error}' if error else ' sent')
        with self._lock:
            device.stats.last_error = text
        self._emit(BusEvent(device.name, 'notice', message=text))

    @staticmethod
    def _fail(job: Job, error: Exception) -> None:
        if job.future.set_running_or_notify_cancel():
            job.future.set_exception(error)

    # -- link ---------------------------------------------------------------------------
    def _open_link(self) -> bool:
        if not self._link.try_open():
            self._mark_all_offline(self._link.error)
            return False
        now = self.clock()
        with self._lock:
            for device in self._devices.values():
                device.health.next_due_s = now
        return True

    def _link_lost(self, reason: str) -> None:
        self._abandon_poll()
        self._link.lost(reason)
        self._mark_all_offline(reason)

    def _mark_all_offline(self, reason: str) -> None:
        with self._lock:
            for device in self._devices.values():
                self._mark_offline(device, reason)

    def _drain_jobs_while_down(self) -> None:
        """While the link is down nothing can be sent: answer every waiting job now."""
        while True:
            with self._lock:
                job = self._jobs.pop()
            if job is None:
                return
            if isinstance(job, StopAllJob):
                self._run_stop_all(job)
            else:
                self._fail(job, CommandRefused(f'{self._link.error}: nothing sent'))

    # -- polls --------------------------------------------------------------------------
    def _begin_poll(self, device: BusDevice, now: float) -> None:
        with self._lock:
            device.health.schedule_next(device.poll_period_s, now)
        self._poll = PollRun(device, device.profile.poll(device.owner), now)
        self._run_poll_step(self._poll)

    def _abandon_poll(self) -> None:
        poll, self._poll = self._poll, None
        if poll is not None:
            poll.abandon()

    def _run_poll_step(self, poll: PollRun) -> None:
        device = poll.device
        try:
            step = poll.next_step()
        except ModelMismatch as error:
            self._poll = None
            self._misconfigured(device, error)
            return
        except DECODE_ERRORS as error:
            self._poll = None
            self._poll_failed(device, ProtocolError(f'cannot decode reply: {error}'))
            return
        if step is None:
            self._poll = None
            self._poll_succeeded(device, poll.reading, poll.started_s)
            return
        try:
            result = self._runner.transact(device, step.request)
        except MonitorOnly as error:
            if step.optional:
                poll.deliver(error)
            else:
                self._abandon_poll()
                self._poll_failed(device, error)
            return
        except LinkDown as error:
            self._link_lost(str(error))
            return
        except TransportError as error:
            self._step_failed(poll, step, error)
            return
        with self._lock:
            device.health.consecutive_failures = 0
        poll.deliver(result)

    def _step_failed(self, poll: PollRun, step, error: TransportError) -> None:
        device = poll.device
        health = device.health
        with self._lock:
            if not isinstance(error, DeviceException):
                health.consecutive_failures += 1
            retries = self.timing.retries if health.online is not False else 0
            retry = step.retry and retryable(error) and poll.attempt < retries and \
                health.consecutive_failures < self.timing.offline_after
            if retry:
                poll.attempt += 1
                device.stats.retries += 1
                return
        if optional_failure(step, error):
            poll.deliver(error)
            return
        self._abandon_poll()
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
        with self._lock:
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
                    self._emit(BusEvent(device.name, 'error', message=health.status_text))
                return
            if isinstance(error, ProtocolError):
                device.stats.record_error(TransportError(str(error)))
                health.status_text = str(error)
                return
            if health.online is False:
                health.backoff(self.timing.backoff_initial_s, self.timing.backoff_max_s,
                               self.clock())
                health.status_text = f'no reply since going offline: {error}'
                return
            health.status_text = f'poll failed ({health.consecutive_failures} failed '\
                f'transactions in a row): {error}'
            if health.consecutive_failures >= limit or health.online is None:
                self._mark_offline(device, str(error))

    def _mark_offline(self, device: BusDevice, reason: str) -> None:
        was_offline = device.health.online is False
        device.health.online = False
        device.reading = None
        device.profile.on_offline()
        device.owner.on_offline(self.clock())
        device.health.status_text = reason
        device.health.backoff(self.timing.backoff_initial_s, self.timing.backoff_max_s,
                              self.clock(), first=True)
        if self._poll is not None and self._poll.device is device:
            self._abandon_poll()
        if not was_offline:
            self._emit(BusEvent(device.name, 'offline', message=reason))

    def _misconfigured(self, device: BusDevice, error: ModelMismatch) -> None:
        with self._lock:
            health = device.health
            first = health.misconfigured != str(error)
            health.misconfigured = str(error)
            health.online = True
            health.status_text = str(error)
            device.reading = None
            if first:
                self._emit(BusEvent(device.name, 'error', message=str(error)))

    def _poll_succeeded(self, device: BusDevice, reading: DeviceReading,
                        started_s: float) -> None:
        notices = []
        with self._lock:
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
                self._emit(BusEvent(device.name, 'online', reading=reading, stamp_s=started_s))
            self._emit(BusEvent(device.name, 'reading', reading=reading, stamp_s=started_s))
            for notice in notices:
                if notice:
                    self._emit(BusEvent(device.name, 'notice', message=notice))
            retry_setup = self.clock() >= device.setup_retry_at_s
            if (came_online or retry_setup) and isinstance(device.profile, SetupWrites) and \
                    device.owner.writes_allowed:
                device.setup_retry_at_s = math.inf
                writes = tuple(device.profile.setup_plan())
                if writes:
                    self._jobs.push(SetupJob(device, math.inf, Future(), writes))

    # -- jobs ---------------------------------------------------------------------------
    def _run_job(self, job: Job) -> None:
        if isinstance(job, StopAllJob):
            self._run_stop_all(job)
        elif isinstance(job, CommandJob):
            self._run_command_job(job)
        elif isinstance(job, ParameterJob):
            self._run_parameter_job(job)
        elif isinstance(job, SetupJob):
            self._run_setup_job(job)

    def _run_command_job(self, job: CommandJob) -> None:
        device = job.device
        try:
            with self._lock:  # the state may have changed since the command was queued
                self._admit(device, job.command)
        except CommandRefused as error:
            self._fail(job, error)
            return
        if not job.future.set_running_or_notify_cancel():
            return  # the caller gave up before it was sent: never sent
        try:
            job.future.set_result(self._execute_command(device, job.command))
        except (CommandRefused, TransportError) as error:
            job.future.set_exception(error)

    def _execute_command(self, device: BusDevice, command: Command) -> str:
        """Send ``command`` now; return the outcome in words or raise with it."""
        owner = device.owner
        with self._lock:
            plan = device.profile.command_plan(command, owner)  # with what is in force now
            motion_before = owner.motion
            owner.sending(command)
            if command.may_start:
                deadman.feed(device, self.clock())
        try:
            for request in plan.writes:
                self._runner.transact(device, request)
        except (DeviceException, MonitorOnly) as error:
            with self._lock:
                owner.refused(command, motion_before)
            text = error if isinstance(error, MonitorOnly) else \
                f'rejected by {device.name}: {self._runner.explain(device, error)}'
            raise CommandRefused(str(text)) from None
        except TransportError as error:
            with self._lock:
                owner.unanswered(command, motion_before, self.clock())
            if isinstance(error, LinkDown):
                self._link_lost(str(error))
            raise TransportError(
                f'no acknowledgement from {device.name} for {command.value} ({error}); it may '
                'or may not have been executed and is not repeated'
                + ('; the motor counts as possibly running' if command.may_start else '')) \
                from None
        with self._lock:
            owner.acknowledged(command)
            if command.may_start:
                deadman.feed(device, self.clock())
            device.health.next_due_s = self.clock()  # read the new state at once
        return f'{command.value} acknowledged by {device.name} (address {device.spec.unit})'

    def _run_stop_all(self, job: StopAllJob) -> None:
        outcomes = []
        for device in list(self._devices.values()):
            with self._lock:
                holds_run = device.owner.holds_run
                if holds_run and not device.spec.stop_on_shutdown:
                    device.owner.release('left as it was (stop_on_shutdown is false): the '
                                         'cyclic image is no longer written', self.clock())
                    outcomes.append(f'{device.name}: left running (stop_on_shutdown is '
                                    'false)')
                    continue
            if not holds_run:
                continue
            if self.clock() > job.deadline_s:
                outcomes.append(f'{device.name}: NOT STOPPED: no time left ({job.reason})')
                continue
            if self._link.error:
                outcomes.append(f'{device.name}: NOT STOPPED: {self._link.error}')
                continue
            try:
                outcomes.append(self._execute_command(device, Command.STOP))
            except (CommandRefused, TransportError) as error:
                outcomes.append(f'{device.name}: stop on {job.reason} failed: {error}')
        if job.future.set_running_or_notify_cancel():
            job.future.set_result(outcomes)

    def _run_parameter_job(self, job: ParameterJob) -> None:
        if not job.future.set_running_or_notify_cancel():
            return
        device = job.device
        results: list = []
        try:
            for request in job.plan.transactions:
                results.append(self._runner.transact(device, request))
        except DeviceException as error:
            job.future.set_exception(CommandRefused(
                f'rejected by {device.name}: {self._runner.explain(device, error)}'))
            return
        except (TransportError, MonitorOnly) as error:
            if isinstance(error, LinkDown):
                self._link_lost(str(error))
            job.future.set_exception(error)
            return
        try:
            job.future.set_result(job.plan.decode(results))
        except DECODE_ERRORS as error:
            job.future.set_exception(ProtocolError(f'{job.plan.label}: cannot decode the '
                                                   f'reply: {error}'))

    def _run_setup_job(self, job: SetupJob) -> None:
        """Send the set-up writes (drives: their comms timeout) each time a device is back."""
        device = job.device
        for write in job.writes:
            try:
                self._runner.transact(device, write)
            except LinkDown as error:
                self._link_lost(str(error))
                return
            except (TransportError, MonitorOnly) as error:
                text = self._runner.explain(device, error) \
                    if isinstance(error, TransportError) else str(error)
                lost = isinstance(error, TransportError) and \
                    not isinstance(error, DeviceException)
                with self._lock:
                    device.setup_error = f'set-up write {write.describe()} failed: {text}' + \
                        ('; it is sent again' if lost else '')
                    if lost:  # a lost reply, not a refusal: try again after a pause
                        device.setup_retry_at_s = self.clock() + SETUP_RETRY_S
                self._emit(BusEvent(device.name, 'notice', message=device.setup_error))
                return
        with self._lock:
            device.setup_error = ''

    def _emit(self, event: BusEvent) -> None:
        try:
            self.listener(event)
        except Exception:  # noqa: B902 - a listener bug must not kill the bus thread
            pass
