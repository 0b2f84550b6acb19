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
it arrived: the next step is chosen only :data:`CHOICE_LEAD_S` before the inter-frame gap
ends, so a command that comes in the gap goes first. Commands carry a deadline and are
never repeated; the motor-state owner decides what may be sent (see :mod:`.motor` and the
the manual's safety model, docs/safety.md).

:meth:`run_once` has no waiting of its own (it returns how long to wait), so unit tests
drive it with a fake clock and a fake transport; :meth:`start` runs it on a thread.

Events (readings, changes of state) go to the listener in the order they happened, from the
bus thread, while the next request is on the wire (the transport reports it sent), or
before the bus waits for anything but the inter-frame gap: the listener's work (publishing)
never delays the next frame. Events that a step did not carry out (it sent nothing), and
with a transport that does not report its requests every event, go after the step.
"""

from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
import math
import threading
import time
from typing import Any, Callable, Deque, Dict, FrozenSet, List, Mapping, Optional, Union

from drive_bridge.bus import deadman
from drive_bridge.bus.device import BusDevice, DeviceSpec
from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.execution import fail, JobRunner
from drive_bridge.bus.jobs import (
    CommandJob, Job, JobQueue, ParameterJob, SetupJob, StopAllJob)
from drive_bridge.bus.link import LinkSupervisor
from drive_bridge.bus.motor import Motion
from drive_bridge.bus.polling import Poller
from drive_bridge.bus.runner import TransactionRunner
from drive_bridge.devices.contracts import (
    DeviceReading, ParameterAccess, ParameterOptions, SetupWrites, SpeedReference)
from drive_bridge.errors import CommandExpired, CommandRefused, MonitorOnly
from drive_bridge.protocol.commands import Command
from drive_bridge.transport.base import Transport

__all__ = ['BusEvent', 'BusMaster', 'BusTiming', 'DeviceSnapshot', 'DeviceSpec']

CHOICE_LEAD_S = 0.0005  # the next frame is chosen this long before the gap ends (its build)
MIN_WAIT_S = 1e-6  # a shorter wait is none (below any timer's resolution)


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
        self._link = LinkSupervisor(transport, self.timing.backoff_initial_s,
                                    self.timing.backoff_max_s, clock)
        self._runner = TransactionRunner(transport, self.timing.frame_gap_s,
                                         self.timing.slow_reply_s, clock, sleep)
        self._poller = Poller(self._runner, self.timing, clock, self._lock, self._emit,
                              self._link_lost, self._setup_due)
        self._work = JobRunner(self._runner, self._link, clock, self._lock, self._emit,
                               self._link_lost, self._devices.values,
                               lambda: self._commands_enabled)
        self.internal_errors = 0
        self.last_internal_error = ''
        self._events: Deque[BusEvent] = deque()  # emitted, not given to the listener yet
        self._delivered = 0  # events given to the listener so far
        self._delivering = threading.Lock()  # one thread gives them at a time, in order
        transport.on_request_sent = self._runner.while_in_flight(self._deliver_events)

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
                self._work.admit(device, command)
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
                self._work.check_reachable(device)
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
            self._refuse_commands(reason)
            job = StopAllJob(None, self.clock() + timeout_s, reason=reason)
            self._jobs.push_front(job)
        self._wake.set()
        return job.future

    def refuse_commands(self, reason: str) -> None:
        """Take only stops from now on; drop waiting commands that are not stops, unsent."""
        with self._lock:
            self._refuse_commands(reason)

    def _refuse_commands(self, reason: str) -> None:
        self._commands_enabled = False
        for job in self._jobs.remove(keep=lambda job: job.urgent):
            fail(job, CommandRefused(f'{job.describe()} not sent: {reason} came first, and from '
                                     'then on only stops are taken'))

    def stop_all(self, reason: str, timeout_s: float = 3.0) -> List[str]:
        """Stop every motor that may run because of the bridge and wait; see begin_stop_all."""
        future = self.begin_stop_all(reason, timeout_s)
        if self._thread is None or not self._thread.is_alive():
            deadline = self.clock() + timeout_s + self.timing.transaction_timeout_s
            while not future.done() and self.clock() < deadline:
                self.run_step(max_wait_s=0.005)
            self._deliver_events()
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

    def _enqueue(self, job: Job) -> None:
        if isinstance(job, CommandJob) and job.command.stops:
            self._drop_starts_overtaken_by(job)
        self._jobs.push(job)
        self._wake.set()

    def _drop_starts_overtaken_by(self, stop: CommandJob) -> None:
        """
        Answer a device's waiting starts as not sent when a stop for it comes.

        Stops go before other jobs: a start queued before the stop would otherwise go out
        after it and run the motor that the later stop was meant to stop.
        """
        def overtaken(job: Job) -> bool:
            return isinstance(job, CommandJob) and job.device is stop.device and \
                job.command.may_start

        for job in self._jobs.remove(keep=lambda job: not overtaken(job)):
            fail(job, CommandRefused(f'{job.describe()} not sent: a {stop.describe()} for '
                                     f'{stop.device.name} came after it'))

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
            self._poller.abandon()
            self._link_lost(f'bus offline: internal error ({self.last_internal_error}); '
                            'reopening the link')
        except Exception:  # noqa: B902 - the bus thread must never die
            pass
        self._deliver_events()
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
        if self._thread is None or not self._thread.is_alive():  # else it may be delivering
            self._deliver_events()
        self.transport.close()
        return outcomes

    # -- one scheduling step ------------------------------------------------------------
    def run_step(self, max_wait_s: float = math.inf) -> float:
        """
        Do the next piece of bus work, then wait what it asks (at most ``max_wait_s``).

        For callers that drive the bus without its thread (stop_all, the soak, the benches):
        the wait is the master's ``sleep``, so a fake clock moves. Returns the wait asked.
        """
        wait_s = self.run_once()
        if wait_s > 0:
            self._runner.sleep(min(wait_s, max_wait_s))
        return wait_s

    def run_once(self) -> float:
        """Do the next piece of bus work; return how long to wait before the next one."""
        now = self.clock()
        if not self._link.up:
            wait_s = self._link.wait_s(now)
            if wait_s > 0 or not self._open_link():
                self._drain_jobs_while_down()
                self._deliver_events()
                return max(self._link.wait_s(self.clock()), 0.001)
        # What goes next is chosen just before it can go, so that a command that comes in
        # the gap goes before the poll step that was next (the rest of the gap is slept in
        # the transaction). The events wait for the next request to leave.
        choose_in_s = self._runner.gap_left_s(now) - CHOICE_LEAD_S
        if choose_in_s > MIN_WAIT_S:
            return choose_in_s
        self._expire_jobs(now)
        self._check_deadmen(now)
        queued = self._delivered + len(self._events)
        wait_s = self._run_next(now)
        # Also events that a step did not carry out (it sent nothing, or failed before).
        if wait_s > 0 or not self.transport.reports_request_sent or self._delivered < queued:
            self._deliver_events()
            if wait_s > 0:  # the wait started before the delivery
                wait_s = max(0.0, wait_s - (self.clock() - now))
        return wait_s

    def _run_next(self, now: float) -> float:
        """Run a job or a poll step; else return how long until a poll is due."""
        with self._lock:
            job = self._jobs.pop()
        if job is not None:
            self._work.run(job)
            return 0.0
        if self._poller.current is not None:
            self._poller.step(self._poller.current)
            return 0.0
        device = self._next_due_device()
        if device is None:
            return 0.1
        wait_s = device.health.next_due_s - now
        if wait_s > 0:
            return wait_s
        self._poller.begin(device, now)
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
            fail(job, CommandExpired(
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
        self._poller.abandon()
        self._link.lost(reason)
        self._mark_all_offline(reason)

    def _mark_all_offline(self, reason: str) -> None:
        with self._lock:
            for device in self._devices.values():
                self._poller.mark_offline(device, reason)

    def _drain_jobs_while_down(self) -> None:
        """While the link is down nothing can be sent: answer every waiting job now."""
        while True:
            with self._lock:
                job = self._jobs.pop()
            if job is None:
                return
            if isinstance(job, StopAllJob):
                self._work.run(job)  # each motor that may run: NOT STOPPED, with the reason
            else:
                fail(job, CommandRefused(f'{self._link.error}: nothing sent'))

    # -- polls --------------------------------------------------------------------------
    def _setup_due(self, device: BusDevice) -> None:
        """Queue the set-up writes of a device (not for a monitor-only one)."""
        device.setup_retry_at_s = math.inf
        if isinstance(device.profile, SetupWrites) and device.owner.writes_allowed:
            writes = tuple(device.profile.setup_plan())
            if writes:
                self._jobs.push(SetupJob(device, math.inf, Future(), writes))

    # -- jobs ---------------------------------------------------------------------------
    def _emit(self, event: BusEvent) -> None:
        """Queue ``event`` for the listener (any thread); see the module docstring."""
        self._events.append(event)

    def _deliver_events(self) -> None:
        """Give the listener every event queued so far, oldest first; never raise."""
        with self._delivering:
            while self._events:
                event = self._events.popleft()
                self._delivered += 1
                try:
                    self.listener(event)
                except Exception:  # noqa: B902 - a listener bug must not kill the bus thread
                    pass
