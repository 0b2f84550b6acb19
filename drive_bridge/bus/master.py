"""
The bus master: one thread owns one bus and everything that happens on it.

Each device is polled at its own rate; a command goes before any waiting poll; a device
that stops answering is marked offline after ``offline_after`` failed transactions in a
row and is then probed once per backoff period (doubling up to ``backoff_max_s``), so a
dead device costs at most one timeout per period and never stalls the others. A lost
link (port gone, connection refused) marks every device offline at once and is reopened
with backoff. Commands are never repeated: a command whose reply did not come back may
have been executed, and the caller is told so.

:meth:`BusMaster.run_once` is one scheduling step with no waiting of its own, so unit
tests drive it with a fake clock and a fake transport; :meth:`start` runs it on a thread.
"""

from collections import Counter, deque
from concurrent.futures import Future
from dataclasses import dataclass, field
import threading
import time
from typing import Callable, Deque, Dict, List, Optional

from drive_bridge.devices.base import DeviceReading, PollItem
from drive_bridge.errors import (
    BadFrame, CommandRefused, DeviceException, FAILURE_KINDS, LinkDown, ModelMismatch,
    NoResponse, ProtocolError, TransportError)


@dataclass
class BusTiming:
    """Retry and timing policy of one bus; times in seconds."""

    retries: int = 2
    offline_after: int = 3
    backoff_initial_s: float = 1.0
    backoff_max_s: float = 10.0
    frame_gap_s: float = 0.0
    command_timeout_s: float = 5.0
    slow_reply_s: float = 0.0  # a valid reply slower than this counts as slow; 0 = off


@dataclass
class DeviceSpec:
    """One device on the bus as configured."""

    name: str
    unit: int
    profile: object
    poll_rate_hz: float = 5.0
    allow_control: bool = True
    stop_on_shutdown: bool = True
    reference_timeout_s: float = 0.0  # drives: deadman on speed_reference messages; 0 = off


@dataclass
class DeviceStats:
    """Transaction statistics of one device; round-trip times in seconds."""

    transactions: int = 0
    errors: Counter = field(default_factory=Counter)
    retries: int = 0
    slow_replies: int = 0
    last_error: str = ''
    rtt_last_s: float = 0.0
    rtt_avg_s: float = 0.0
    rtt_max_s: float = 0.0

    def record_ok(self, rtt_s: float, slow: bool = False) -> None:
        """Count a transaction that got a valid reply (``slow``: later than the bus's limit)."""
        self.transactions += 1
        self.slow_replies += slow
        self.rtt_last_s = rtt_s
        self.rtt_max_s = max(self.rtt_max_s, rtt_s)
        weight = 0.1 if self.rtt_avg_s else 1.0
        self.rtt_avg_s += (rtt_s - self.rtt_avg_s) * weight

    def record_error(self, error: TransportError) -> None:
        """Count a failed transaction by the kind of failure."""
        self.transactions += 1
        self.errors[error.kind] += 1
        self.last_error = str(error)

    def as_dict(self) -> Dict[str, str]:
        """Return the statistics as text key/values for /diagnostics."""
        values = {
            'transactions': str(self.transactions),
            'errors': str(sum(self.errors.values())),
            'retries': str(self.retries),
            'slow_replies': str(self.slow_replies),
            'last_error': self.last_error,
            'rtt_last_ms': f'{self.rtt_last_s * 1000:.1f}',
            'rtt_avg_ms': f'{self.rtt_avg_s * 1000:.1f}',
            'rtt_max_ms': f'{self.rtt_max_s * 1000:.1f}',
        }
        for kind in FAILURE_KINDS:
            values[f'errors_{kind}'] = str(self.errors.get(kind, 0))
        return values


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
    stats: Dict[str, str]
    started_by_bridge: bool
    allow_control: bool


@dataclass
class BusEvent:
    """What the bus tells its listener: a new reading, or a change of link status."""

    device: str
    kind: str  # 'reading', 'offline', 'online', 'error' (state unknown), 'notice' (a log line)
    reading: Optional[DeviceReading] = None
    message: str = ''


class _Device:
    """The bus thread's bookkeeping of one device."""

    def __init__(self, spec: DeviceSpec, now_s: float):
        self.spec = spec
        self.online: Optional[bool] = None  # None: not heard from yet
        self.misconfigured = ''
        self.status_text = 'waiting for first reply'
        self.consecutive_failures = 0
        self.backoff_s = 0.0
        self.next_due_s = now_s
        self.reading: Optional[DeviceReading] = None
        self.started_by_bridge = False
        self.stats = DeviceStats()
        self.reference_deadline_s = float('inf')
        self.rejected_references = 0
        self.deadman_stops = 0
        self.setup_error = ''

    @property
    def poll_period_s(self) -> float:
        return 1.0 / self.spec.poll_rate_hz


@dataclass
class _Job:
    device: _Device
    command: str
    transactions: tuple
    future: Future
    decode: Optional[Callable[[list], object]] = None
    on_acknowledged: Optional[Callable[[], None]] = None
    on_failed: Optional[Callable[[], None]] = None


class BusMaster:
    """Own one bus: poll, command, track links; see the module docstring."""

    def __init__(self, transport, devices: List[DeviceSpec], timing: Optional[BusTiming] = None,
                 listener: Optional[Callable[[BusEvent], None]] = None,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep):
        self.transport = transport
        self.timing = timing or BusTiming()
        self.listener = listener or (lambda event: None)
        self.clock = clock
        self.sleep = sleep
        now = clock()
        self._devices: Dict[str, _Device] = {spec.name: _Device(spec, now) for spec in devices}
        self._jobs: Deque[_Job] = deque()
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._running = False
        self._link_retry_at_s = now
        self._link_backoff_s = 0.0
        self._link_error = ''
        self._last_transaction_end_s = 0.0
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
        return self._link_error

    def snapshot(self, name: str) -> DeviceSnapshot:
        """Return a copy of one device's state."""
        with self._lock:
            device = self._devices[name]
            profile = device.spec.profile
            return DeviceSnapshot(
                name=name, unit=device.spec.unit, family=profile.family,
                model=getattr(profile, 'model', None) or profile.configured_model,
                online=device.online, status_text=device.status_text,
                reading=device.reading, stats=self._device_stats(device),
                started_by_bridge=device.started_by_bridge,
                allow_control=device.spec.allow_control)

    @staticmethod
    def _device_stats(device: _Device) -> Dict[str, str]:
        stats = device.stats.as_dict()
        if device.setup_error:
            stats['setup_error'] = device.setup_error
        if hasattr(device.spec.profile, 'set_reference'):
            stats['rejected_references'] = str(device.rejected_references)
            stats['deadman_stops'] = str(device.deadman_stops)
            stats['reference_timeout_s'] = f'{device.spec.reference_timeout_s:g}'
        return stats

    def transaction_count(self) -> int:
        """Return the transactions run on this bus so far, every device together."""
        with self._lock:
            return sum(device.stats.transactions for device in self._devices.values())

    def set_allow_control(self, name: str, allow: bool) -> None:
        """Switch a device between controlled and monitor-only."""
        with self._lock:
            self._devices[name].spec.allow_control = allow

    def set_stop_on_shutdown(self, name: str, stop: bool) -> None:
        """Choose whether a clean shutdown stops this device if the bridge started it."""
        with self._lock:
            self._devices[name].spec.stop_on_shutdown = stop

    def set_poll_rate(self, name: str, rate_hz: float) -> None:
        """Change how often a device is polled."""
        with self._lock:
            self._devices[name].spec.poll_rate_hz = rate_hz

    def submit_command(self, name: str, command: str) -> Future:
        """
        Queue ``command`` for device ``name``; the future gives the outcome in words.

        A command that is refused before sending resolves at once with CommandRefused.
        """
        future: Future = Future()
        try:
            with self._lock:
                device = self._checked_device(name, command, control=True)
                profile = device.spec.profile
                if hasattr(profile, 'check_command'):
                    profile.check_command(command, device.reading)
                self._enqueue_command(device, command, future)
        except CommandRefused as error:
            future.set_exception(error)
        return future

    def read_parameter(self, name: str, number: int, **options) -> Future:
        """
        Queue a read of parameter ``number``; the future gives its value.

        ``options`` go to the profile's ``parameter_plan`` (drives: data_type, conversion,
        index).
        """
        return self._parameter_job(name, number, None, options)

    def write_parameter(self, name: str, number: int, value, **options) -> Future:
        """Queue a write of parameter ``number``; the future resolves on acknowledgement."""
        return self._parameter_job(name, number, value, options)

    def _parameter_job(self, name: str, number: int, value, options: dict) -> Future:
        future: Future = Future()
        try:
            with self._lock:
                write = value is not None
                device = self._checked_device(name, 'parameter write' if write else '',
                                              control=write)
                plan = device.spec.profile.parameter_plan(number, value, **options)
                self._enqueue(_Job(device, plan.label, plan.transactions, future,
                                   decode=plan.decode))
        except CommandRefused as error:
            future.set_exception(error)
        return future

    def set_speed_reference(self, name: str, percent: float, from_topic: bool = False) -> int:
        """
        Set a drive's speed reference; it goes out with the next process-data write.

        ``from_topic`` feeds the deadman (``reference_timeout_s``). Raises CommandRefused
        (nothing sent) for a device without a reference or a value that is not finite or
        outside [-200, 200) %; returns the 16-bit reference word.
        """
        with self._lock:
            device = self._known_device(name)
            profile = device.spec.profile
            if not hasattr(profile, 'set_reference'):
                raise CommandRefused(f'{name} ({profile.family}) takes no speed reference')
            try:
                word = profile.set_reference(percent)
            except CommandRefused:
                device.rejected_references += 1
                raise
            if from_topic:
                device.reference_deadline_s = self.clock() + device.spec.reference_timeout_s
            if getattr(profile, 'control_word', None) is not None:
                device.next_due_s = self.clock()  # write it with the next cycle, now
        self._wake.set()
        return word

    def set_reference_timeout(self, name: str, timeout_s: float) -> None:
        """Change a drive's deadman time (0 = off)."""
        with self._lock:
            device = self._devices[name]
            device.spec.reference_timeout_s = timeout_s
            device.reference_deadline_s = self.clock() + timeout_s

    def _known_device(self, name: str) -> _Device:
        device = self._devices.get(name)
        if device is None:
            raise CommandRefused(
                f'unknown device {name!r}: this bus has {", ".join(self._devices)}')
        return device

    def _checked_device(self, name: str, command: str, control: bool) -> _Device:
        device = self._known_device(name)
        if control and not device.spec.allow_control:
            raise CommandRefused(f'{name} is monitor only (allow_control is false): '
                                 'nothing sent')
        if self._link_error:
            raise CommandRefused(f'{self._link_error}: nothing sent')
        if device.misconfigured:
            raise CommandRefused(f'{name}: {device.misconfigured}: nothing sent')
        if device.online is not True:
            raise CommandRefused(f'{name} is offline ({device.status_text}): nothing sent')
        reading = device.reading
        if command == 'start' and reading is not None and reading.state == 'tripped':
            raise CommandRefused(f'{name} is tripped ({reading.trip_name or "no trip name"}):'
                                 ' reset it first; nothing sent')
        return device

    def _enqueue_command(self, device: _Device, command: str, future: Future) -> None:
        """Queue the writes of the profile's plan for ``command``."""
        plan = device.spec.profile.command_plan(command)
        self._enqueue(_Job(device, command, plan.writes, future,
                           on_acknowledged=plan.on_acknowledged,
                           on_failed=plan.on_failed))

    def _enqueue(self, job: _Job) -> None:
        self._jobs.append(job)
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
            self._link_lost(f'bus offline: internal error ({self.last_internal_error}); '
                            'reopening the link', self.clock())
        except Exception:  # noqa: B902 - the bus thread must never die
            pass
        return 0.1

    def shutdown(self, stop_motors: bool = True, timeout_s: float = 3.0) -> List[str]:
        """
        Stop the motors this bridge started (if asked), stop the thread, close the link.

        Returns what happened to each stop, in words.
        """
        outcomes = []
        if stop_motors and self._thread is not None:
            outcomes = self.stop_started_motors(timeout_s)
        self._running = False
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout_s + 1.0)
        self.transport.close()
        return outcomes

    def stop_started_motors(self, timeout_s: float = 3.0) -> List[str]:
        """Stop the motors this bridge started (stop_on_shutdown); return the outcomes."""
        with self._lock:
            names = [name for name, device in self._devices.items()
                     if device.started_by_bridge and device.spec.stop_on_shutdown]
        futures = {name: self.submit_command(name, 'stop') for name in names}
        deadline = self.clock() + timeout_s
        outcomes = []
        for name, future in futures.items():
            try:
                outcomes.append(future.result(timeout=max(0.0, deadline - self.clock())))
            except Exception as error:  # noqa: B902 - every failure is reported in words
                outcomes.append(f'{name}: stop on shutdown failed: {error}')
        return outcomes

    # -- one scheduling step ------------------------------------------------------------
    def run_once(self) -> float:
        """Do the next piece of bus work; return how long to wait before the next one."""
        now = self.clock()
        if not self.transport.connected:
            if now < self._link_retry_at_s:
                self._fail_queued_jobs()
                return self._link_retry_at_s - now
            if not self._open_link(now):
                return self._link_retry_at_s - self.clock()
        self._check_deadman(now)
        if self._jobs:
            self._run_job(self._jobs.popleft())
            return 0.0
        device = self._next_due_device()
        if device is None:
            return 0.1
        wait_s = device.next_due_s - now
        if wait_s > 0:
            return wait_s
        self._poll(device)
        return 0.0

    def _check_deadman(self, now: float) -> None:
        """Ramp-stop a drive whose speed_reference messages stopped (reference_timeout_s)."""
        with self._lock:
            for device in self._devices.values():
                if device.spec.reference_timeout_s <= 0 or now < device.reference_deadline_s \
                        or not getattr(device.spec.profile, 'commanded_run', False) \
                        or device.online is not True:
                    continue
                device.reference_deadline_s = float('inf')
                device.deadman_stops += 1
                future: Future = Future()
                future.add_done_callback(lambda done, d=device: self._deadman_done(d, done))
                self._enqueue_command(device, 'stop', future)

    def _deadman_done(self, device: _Device, future: Future) -> None:
        error = future.exception()
        text = (f'reference timeout ({device.spec.reference_timeout_s:g} s without a '
                f'speed_reference message): ramp stop '
                + (f'failed: {error}' if error else 'sent'))
        with self._lock:
            device.stats.last_error = text
        self._emit(BusEvent(device.spec.name, 'notice', message=text))

    def _next_due_device(self) -> Optional[_Device]:
        with self._lock:
            if not self._devices:
                return None
            return min(self._devices.values(), key=lambda device: device.next_due_s)

    # -- link ---------------------------------------------------------------------------
    def _open_link(self, now: float) -> bool:
        try:
            self.transport.connect()
        except LinkDown as error:
            self._link_lost(str(error), now)
            return False
        with self._lock:
            self._link_error = ''
            self._link_backoff_s = 0.0
            for device in self._devices.values():
                device.next_due_s = now
        return True

    def _link_lost(self, reason: str, now: float) -> None:
        self.transport.close()
        self._link_backoff_s = min(max(self._link_backoff_s * 2, self.timing.backoff_initial_s),
                                   self.timing.backoff_max_s)
        self._link_retry_at_s = now + self._link_backoff_s
        self._link_error = reason
        with self._lock:
            for device in self._devices.values():
                self._mark_offline(device, reason)
        self._fail_queued_jobs()

    def _fail_queued_jobs(self) -> None:
        while self._jobs:
            job = self._jobs.popleft()
            job.future.set_exception(CommandRefused(f'{self._link_error}: nothing sent'))

    # -- transactions -------------------------------------------------------------------
    def _transact(self, device: _Device, transaction):
        gap_s = self._last_transaction_end_s + self.timing.frame_gap_s - self.clock()
        if gap_s > 0:
            self.sleep(gap_s)
        started = self.clock()
        try:
            result = self.transport.execute(device.spec.unit, transaction)
        except TransportError as error:
            self._last_transaction_end_s = self.clock()
            with self._lock:
                self._count_recovered(device)
                device.stats.record_error(error)
            raise
        self._last_transaction_end_s = self.clock()
        rtt_s = self._last_transaction_end_s - started
        slow_s = self.timing.slow_reply_s
        with self._lock:
            self._count_recovered(device)
            device.stats.record_ok(rtt_s, slow=0 < slow_s < rtt_s)
        return result

    def _count_recovered(self, device: _Device) -> None:
        """Add the failures the transport recovered from itself (AP ASCII NAKs) to the stats."""
        for kind, count in getattr(self.transport, 'last_recovered', {}).items():
            device.stats.errors[kind] += count

    def _poll(self, device: _Device) -> None:
        now = self.clock()
        with self._lock:
            device.next_due_s = max(device.next_due_s + device.poll_period_s, now)
        retries = self.timing.retries if device.online is not False else 0
        profile = device.spec.profile
        results: list = []
        try:
            self._run_poll_items(device, profile.poll_plan(), retries, results)
            if hasattr(profile, 'follow_up_plan'):
                self._run_poll_items(device, profile.follow_up_plan(results), retries, results)
        except LinkDown as error:
            self._link_lost(str(error), self.clock())
            return
        except TransportError as error:
            self._poll_failed(device, error)
            return
        self._poll_succeeded(device, results)

    def _run_poll_items(self, device: _Device, items: list, retries: int,
                        results: list) -> None:
        """Run a poll's transactions in order, appending each result to ``results``."""
        for item in items:
            if not isinstance(item, PollItem):
                item = PollItem(item)
            try:
                results.append(self._read_with_retries(device, item.transaction, retries))
            except DeviceException as error:
                if not item.optional:
                    raise
                results.append(error)

    def _read_with_retries(self, device: _Device, transaction, retries: int):
        attempt = 0
        while True:
            try:
                result = self._transact(device, transaction)
            except (NoResponse, BadFrame) as error:
                with self._lock:
                    device.consecutive_failures += 1
                    give_up = attempt >= retries or \
                        device.consecutive_failures >= self.timing.offline_after
                if give_up:
                    raise error
                attempt += 1
                with self._lock:
                    device.stats.retries += 1
                continue
            with self._lock:
                device.consecutive_failures = 0
            return result

    def _poll_failed(self, device: _Device, error: TransportError) -> None:
        with self._lock:
            if isinstance(error, DeviceException):
                text = device.spec.profile.explain_exception(error.code)
                device.status_text = f'poll refused: {text}'
                self._emit(BusEvent(device.spec.name, 'error', message=device.status_text))
                return
            if device.online is False:
                device.backoff_s = min(device.backoff_s * 2, self.timing.backoff_max_s)
                device.next_due_s = self.clock() + device.backoff_s
                device.status_text = f'no reply since going offline: {error}'
                return
            if device.consecutive_failures >= self.timing.offline_after or \
                    device.online is None:
                self._mark_offline(device, str(error))

    def _mark_offline(self, device: _Device, reason: str) -> None:
        was_offline = device.online is False
        device.online = False
        device.reading = None
        if hasattr(device.spec.profile, 'on_offline'):
            device.spec.profile.on_offline()  # a drive forgets its command: no keepalive
        device.status_text = reason
        device.backoff_s = self.timing.backoff_initial_s
        device.next_due_s = self.clock() + device.backoff_s
        if not was_offline:
            self._emit(BusEvent(device.spec.name, 'offline', message=reason))

    def _poll_succeeded(self, device: _Device, blocks: list) -> None:
        try:
            reading = device.spec.profile.decode(blocks)
        except ModelMismatch as error:
            with self._lock:
                first = device.misconfigured != str(error)
                device.misconfigured = str(error)
                device.online = True
                device.status_text = str(error)
                device.reading = None
                if first:
                    self._emit(BusEvent(device.spec.name, 'error', message=str(error)))
            return
        except (ProtocolError, ValueError, IndexError, KeyError) as error:
            with self._lock:
                device.stats.record_error(BadFrame(f'cannot decode reply: {error}'))
                device.status_text = f'cannot decode reply: {error}'
            return
        with self._lock:
            came_online = device.online is not True
            device.online = True
            device.misconfigured = ''
            device.backoff_s = 0.0
            device.status_text = 'ok'
            device.reading = reading
            device.stats.errors.pop('offline_reported', None)
            if came_online:
                self._emit(BusEvent(device.spec.name, 'online', reading=reading))
            self._emit(BusEvent(device.spec.name, 'reading', reading=reading))
        if came_online:
            self._run_setup(device)

    def _run_setup(self, device: _Device) -> None:
        """Send the set-up writes (drives: their comms timeout) each time a device is back."""
        writes = device.spec.profile.setup_plan() if \
            hasattr(device.spec.profile, 'setup_plan') else []
        try:
            for write in writes:
                self._transact(device, write)
        except LinkDown as error:
            self._link_lost(str(error), self.clock())
            return
        except TransportError as error:
            text = self._explain(device, error)
            with self._lock:
                device.setup_error = f'set-up write {write} failed: {text}'
            self._emit(BusEvent(device.spec.name, 'notice', message=device.setup_error))
            return
        with self._lock:
            device.setup_error = ''

    def _run_job(self, job: _Job) -> None:
        device = job.device
        name = device.spec.name
        results: list = []
        try:
            for transaction in job.transactions:
                results.append(self._transact(device, transaction))
        except DeviceException as error:
            self._command_failed(job)
            job.future.set_exception(CommandRefused(
                f'rejected by {name}: {self._explain(device, error)}'))
            return
        except TransportError as error:
            self._may_have_started(device, job.command)
            self._command_failed(job)
            if isinstance(error, LinkDown):
                self._link_lost(str(error), self.clock())
            job.future.set_exception(TransportError(
                f'no acknowledgement from {name} for {job.command} ({error}); it may or may '
                'not have been executed and is not repeated'))
            return
        self._may_have_started(device, job.command)
        with self._lock:
            if job.on_acknowledged is not None:
                job.on_acknowledged()
            if job.command in ('stop', 'quick_stop', 'coast_stop'):
                device.started_by_bridge = False
            if job.command == 'start':
                device.reference_deadline_s = self.clock() + device.spec.reference_timeout_s
            device.next_due_s = self.clock()  # read the new state at once
        if job.decode is not None:
            try:
                job.future.set_result(job.decode(results))
            except (ValueError, IndexError, TypeError) as error:
                job.future.set_exception(ProtocolError(f'{job.command}: cannot decode the '
                                                       f'reply: {error}'))
        else:
            job.future.set_result(
                f'{job.command} acknowledged by {name} (address {device.spec.unit})')

    def _command_failed(self, job: _Job) -> None:
        """Let the profile settle what it rewrites each cycle after a failed command."""
        if job.on_failed is not None:
            with self._lock:
                job.on_failed()

    def _explain(self, device: _Device, error: TransportError) -> str:
        """Return a failure in words; a device exception with the profile's text and detail."""
        if not isinstance(error, DeviceException):
            return str(error)
        profile = device.spec.profile
        detail = None
        detail_read = profile.detail_plan(error.code) if hasattr(profile, 'detail_plan') \
            else None
        if detail_read is not None:
            try:
                detail = self._transact(device, detail_read)[0]
            except TransportError:
                pass  # explained without the detail
        return profile.explain_exception(error.code, detail)

    def _may_have_started(self, device: _Device, command: str) -> None:
        """Remember a start that was acknowledged, or may have run without a reply."""
        if command == 'start':
            with self._lock:
                device.started_by_bridge = True

    def _emit(self, event: BusEvent) -> None:
        try:
            self.listener(event)
        except Exception:  # noqa: B902 - a listener bug must not kill the bus thread
            pass
