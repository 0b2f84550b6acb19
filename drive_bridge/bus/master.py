"""
The bus master: one thread owns one bus and everything that happens on it.

:class:`BusMaster` is what the node, the CLI and the tests (the soak harness too) hold: the
thread-safe API and the bus thread. It builds the bus's parts and hands each the others it
needs through the interfaces in :mod:`.seams`; every part has one job:

- :mod:`.table`: the devices, the lock over their state, snapshots for other threads;
- :mod:`.outbox`: events (:mod:`.events`) in order, given to the listener later;
- :mod:`.intake`: callers' commands and parameter accesses, admitted, with a deadline;
- :mod:`.parameter_line`: each device's parameter service over the bus (the CLI's);
- :mod:`.jobs`: the job queue (stops first, a stop overtaking starts, deadlines);
- :mod:`.scheduler`: the scheduling step, one transaction or none (see there);
- :mod:`.polling` and :mod:`.health`: poll cycles step by step, and device health;
- :mod:`.link`: the link, lost and reopened with backoff;
- :mod:`.execution`: commands and the stop of everything through each device's
  motor-state owner (:mod:`.motor`, the safety model, docs/safety.md); :mod:`.work`:
  the other jobs;
- :mod:`.runner`: one transaction (gap, monitor-only guard, statistics);
- :mod:`.deadman` and :mod:`.controls`: speed references, their deadman, settings.
"""

from concurrent.futures import Future
import math
import threading
import time
from typing import Any, Callable, List, Mapping, Optional, TypeVar, Union

from drive_bridge.bus.controls import DeviceControls
from drive_bridge.bus.deadman import Deadman
from drive_bridge.bus.device import DeviceSpec
from drive_bridge.bus.events import BusEvent, Listener
from drive_bridge.bus.execution import CommandExecutor
from drive_bridge.bus.health import HealthKeeper
from drive_bridge.bus.intake import JobIntake
from drive_bridge.bus.jobs import JobQueue
from drive_bridge.bus.link import LinkHealth
from drive_bridge.bus.outbox import EventOutbox
from drive_bridge.bus.polling import PollScheduler
from drive_bridge.bus.runner import TransactionRunner
from drive_bridge.bus.scheduler import BusScheduler
from drive_bridge.bus.table import DeviceSnapshot, DeviceTable
from drive_bridge.bus.timing import BusTiming
from drive_bridge.bus.work import JobRunner
from drive_bridge.devices.contracts import ParameterOptions
from drive_bridge.devices.parameter_service import ParameterService
from drive_bridge.protocol.commands import Command
from drive_bridge.transport.base import Transport

__all__ = ['BusEvent', 'BusMaster', 'BusTiming', 'DeviceSnapshot', 'DeviceSpec']

T = TypeVar('T')


class BusMaster:
    """Own one bus: poll, command, track links; see the module docstring."""

    def __init__(self, transport: Transport, devices: List[DeviceSpec],
                 timing: Optional[BusTiming] = None, listener: Optional[Listener] = None,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep):
        self.transport = transport
        self.timing = timing = timing or BusTiming()
        self.clock = clock
        self._devices = table = DeviceTable(devices, clock)
        self._outbox = outbox = EventOutbox(listener)
        self._jobs = jobs = JobQueue()
        runner = TransactionRunner(transport, timing.frame_gap_s, timing.slow_reply_s, clock,
                                   sleep, table.by_unit)
        polls = PollScheduler(runner, table, HealthKeeper(table, timing, outbox, clock),
                              jobs)
        self._link = link = LinkHealth(transport, timing.backoff_initial_s,
                                       timing.backoff_max_s, polls, clock)
        self._commands = commands = CommandExecutor(runner, table, link, clock)
        self._intake = JobIntake(table, commands, jobs, timing, clock)
        self._controls = DeviceControls(table, clock)
        self._scheduler = BusScheduler(
            link, runner, jobs, JobRunner(runner, commands, table, link, outbox, clock),
            polls, Deadman(table, jobs, outbox, timing.command_deadline_s), outbox, clock)
        transport.on_request_sent = runner.while_in_flight(outbox.deliver)
        self._thread: Optional[threading.Thread] = None
        self._running = False
        self.internal_errors = 0
        self.last_internal_error = ''

    # -- public API (any thread) --------------------------------------------------------
    @property
    def listener(self) -> Listener:
        """Return who is given the bus's events (from the bus thread)."""
        return self._outbox.listener

    @listener.setter
    def listener(self, listener: Listener) -> None:
        self._outbox.listener = listener

    @property
    def device_names(self) -> List[str]:
        """Return the configured device names in order."""
        return self._devices.names

    @property
    def link_error(self) -> str:
        """Return why the link is down, or '' when it is up."""
        return self._link.error

    @property
    def commands_enabled(self) -> bool:
        """Return whether commands other than stops are taken (the node is active)."""
        return self._commands.enabled

    def snapshot(self, name: str) -> DeviceSnapshot:
        """Return a copy of one device's state."""
        return self._devices.snapshot(name)

    def transaction_count(self) -> int:
        """Return the transactions run on this bus so far, every device together."""
        return self._devices.transaction_count()

    def submit_command(self, name: str, command: Union[Command, str],
                       deadline_s: Optional[float] = None) -> Future:
        """
        Queue ``command`` for device ``name``; the future gives the outcome in words.

        A command refused before sending resolves at once with CommandRefused. One that is
        not on the wire ``deadline_s`` seconds from now (default: the bus's command
        deadline) resolves with CommandExpired and is never sent.
        """
        return self._intake.command(name, command, deadline_s)

    def run_parameter_service(self, name: str, action: Callable[[ParameterService], T],
                              deadline_s: Optional[float] = None,
                              label: str = 'parameter access') -> 'Future[T]':
        """
        Queue ``action(service)`` on the bus thread; the future gives what it returns.

        ``service`` is device ``name``'s ParameterService over the bus (between two polls;
        its transactions back to back; see :mod:`.parameter_line`): e.g. ``lambda service:
        service.write(341, 2.5)`` checks, writes and reads back. Refused at once (nothing
        sent) without parameter access, while the device is offline or the link down. Not
        begun ``deadline_s`` from now (default: the command deadline and one transaction):
        never begun. ``action`` must only use the service: it runs on the bus thread.
        """
        return self._intake.parameter_service(name, action, deadline_s, label)

    def read_parameter(self, name: str, number: int,
                       options: ParameterOptions = ParameterOptions()) -> Future:
        """Queue a read of parameter ``number``; the future gives its value."""
        return self._intake.parameter(name, number, None, options)

    def write_parameter(self, name: str, number: int, value: Any,
                        options: ParameterOptions = ParameterOptions()) -> Future:
        """Queue a write of ``number`` (no read-back); the future resolves on acknowledgement."""
        return self._intake.parameter(name, number, value, options)

    def set_speed_reference(self, name: str, percent: float, from_topic: bool = False) -> int:
        """
        Set a drive's speed reference; it goes out with the next cyclic write.

        ``from_topic`` feeds the deadman. Raises CommandRefused (nothing sent, counted) for
        a device without a reference, a monitor-only device, or a value that is not finite
        or outside [-200, 200) %; returns the 16-bit reference word.
        """
        return self._controls.set_speed_reference(name, percent, from_topic)

    def count_rejected_reference(self, name: str) -> None:
        """Count a speed reference refused before it became a value (bytes that are none)."""
        self._controls.count_rejected_reference(name)

    def feed_deadman(self, name: str) -> None:
        """Count a command message for the deadman (reference_timeout_s)."""
        self._controls.feed_deadman(name)

    def apply_settings(self, changes: Mapping[str, Mapping[str, Any]]) -> None:
        """
        Apply runtime settings of several devices at once, or none of them.

        ``changes``: device -> {setting: value} with settings ``allow_control``,
        ``poll_rate``, ``stop_on_shutdown``, ``reference_timeout``, ``speed_reference``
        (values already type-checked). Raises CommandRefused with the reason, having
        changed nothing, if any change is refused (a switch to monitor-only while the
        bridge holds a run command; a reference the device cannot take).
        """
        self._controls.apply_settings(changes)
        self._jobs.wake()

    def set_commands_enabled(self, enabled: bool) -> None:
        """Take commands (node active) or only stops of motors that may run (inactive)."""
        self._commands.enabled = enabled

    def begin_stop_all(self, reason: str, timeout_s: float = 3.0) -> Future:
        """
        Stop every motor that may run because of the bridge; the future gives the outcomes.

        From now on only stops are taken; waiting commands that are not stops are dropped
        unsent. The stops go out on the bus thread after the transaction on the wire now,
        so a start in flight is settled first and counted if it may have run. Devices with
        ``stop_on_shutdown`` false are left as they are, but their cyclic image is no
        longer written.
        """
        return self._intake.stop_all(reason, timeout_s)

    def refuse_commands(self, reason: str) -> None:
        """Take only stops from now on; drop waiting commands that are not stops, unsent."""
        self._intake.refuse(reason)

    def stop_all(self, reason: str, timeout_s: float = 3.0) -> List[str]:
        """Stop every motor that may run because of the bridge and wait; see begin_stop_all."""
        future = self.begin_stop_all(reason, timeout_s)
        if self._thread is None or not self._thread.is_alive():
            deadline = self.clock() + timeout_s + self.timing.transaction_timeout_s
            while not future.done() and self.clock() < deadline:
                self.run_step(max_wait_s=0.005)
            self._outbox.deliver()
        try:
            return future.result(timeout=timeout_s + 2 * self.timing.transaction_timeout_s)
        except Exception as error:  # noqa: B902 - reported in words, never raised here
            return [f'stop of every motor ({reason}) did not finish: {error!r}']

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
                self._jobs.wait(wait_s)

    def _internal_error(self, error: Exception) -> float:
        """
        Survive a bug or an unexpected library error: report the bus offline and reopen it.

        Nothing read since is trusted: every device goes offline at once (listeners are
        told) and the link is reopened with backoff, as after a lost port.
        """
        self.internal_errors += 1
        self.last_internal_error = f'{type(error).__name__}: {error}'
        self._scheduler.recover(f'bus offline: internal error ({self.last_internal_error}); '
                                'reopening the link')
        return 0.1

    def shutdown(self, stop_motors: bool = True, timeout_s: float = 3.0) -> List[str]:
        """
        Stop the motors that may run because of the bridge (if asked), then close the bus.

        Returns what happened to each stop, in words.
        """
        outcomes = self.stop_all('shutdown', timeout_s) if stop_motors else []
        self._commands.enabled = False
        self._running = False
        self._jobs.wake()
        if self._thread is not None:
            self._thread.join(timeout=timeout_s + 1.0)
        if self._thread is None or not self._thread.is_alive():  # else it may be delivering
            self._outbox.deliver()
        self.transport.close()
        return outcomes

    # -- one scheduling step (the bus thread, or a caller without it) --------------------
    def run_step(self, max_wait_s: float = math.inf) -> float:
        """
        Do the next piece of bus work, then wait what it asks (at most ``max_wait_s``).

        For callers that drive the bus without its thread (stop_all, the soak harness, the
        benches): the wait is the master's ``sleep``, so a fake clock moves. Returns the wait
        asked.
        """
        return self._scheduler.run_step(max_wait_s)

    def run_once(self) -> float:
        """Do the next piece of bus work; return how long to wait before the next one."""
        return self._scheduler.run_once()
