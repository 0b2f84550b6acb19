"""
The motor-state owner of one device: the safety model in code.

Every command for a device passes through its :class:`MotorOwner`, which alone decides

- whether a command may be sent now (:meth:`MotorOwner.admit`),
- what the device's cyclic image carries (``steady``, the keepalive of drives and the LVSG
  gateway image; profiles write what it says), and
- whether a motor may be running because of this bridge (``motion``), which stop-on-shutdown,
  deactivate, the deadman and /diagnostics follow.

The invariants it holds (the manual's safety model, docs/safety.md):

1. Nothing that could start a motor is written unless a start a user asked for is in force:
   the run image is carried only after a start was acknowledged, and is dropped on a trip, on
   offline, on deactivate and by any stop request.
2. A command answered as failed is never sent later: a start that was refused, expired or
   got no reply is never repeated by the keepalive; a cyclic device gets a stop image
   instead, so it cannot run on a start that was answered as failed.
3. A start whose reply was lost counts as "may be running" (:attr:`Motion.MAY_RUN`) until a
   stop is acknowledged.
4. A stop can always be sent while a motor may be running because of this bridge, whatever
   the lifecycle state; monitor-only cannot be switched on while one may be.

Pure bookkeeping, no I/O; the bus thread calls it under the bus lock.
"""

import enum
from typing import Optional

from drive_bridge.devices.contracts import ControlView, DeviceReading
from drive_bridge.errors import CommandRefused
from drive_bridge.protocol.commands import Command

# States in which a motor is not running (a "may be running" is settled by reading one).
STOPPED_STATES = ('ready', 'not_ready', 'restart_delay')
# A reading settles "may be running" only if taken this long after the unanswered command: a
# starter needs a moment before its status shows a start it executed.
SETTLE_S = 1.0


class Motion(enum.Enum):
    """Whether a motor may be running because of this bridge."""

    IDLE = 'idle'  # nothing this bridge started is running
    RUNNING = 'running'  # a start was acknowledged and is in force
    MAY_RUN = 'may_run'  # a start or stop got no acknowledgement: it may be running

    @property
    def may_be_running(self) -> bool:
        """Return whether a motor may be running because of the bridge."""
        return self is not Motion.IDLE


class MotorOwner(ControlView):
    """The motor state of one device; see the module docstring."""

    def __init__(self, name: str, cyclic: bool, allow_control: bool = True,
                 reference_word: int = 0):
        self.name = name
        self.cyclic = cyclic  # the device is driven by an image rewritten every poll
        self.allow_control = allow_control
        self.motion = Motion.IDLE
        self.in_flight: Optional[Command] = None
        self.note = ''  # why the motion is what it is, for /diagnostics
        self.unsure_since_s = 0.0  # when the motion last became MAY_RUN
        self._lost_run = False  # went offline while a run was held (cyclic devices)
        self._steady: Optional[Command] = None
        self._reference_word = reference_word

    # -- the control view the profiles read ----------------------------------------------
    @property
    def steady(self) -> Optional[Command]:
        """Return what the cyclic image carries (None: no control data is written)."""
        if not self.cyclic or not self.allow_control:
            return None
        return self._steady

    @property
    def reference_word(self) -> int:
        """Return the reference word in force."""
        return self._reference_word

    @property
    def writes_allowed(self) -> bool:
        """Return whether anything may be written to the device (False: monitor only)."""
        return self.allow_control

    @property
    def holds_run(self) -> bool:
        """Return whether the bridge holds a run command (in force, or possibly executed)."""
        return self.motion.may_be_running or self._steady is Command.START

    def set_reference_word(self, word: int) -> None:
        """Take a new reference word (it goes out with the next cyclic write)."""
        self._reference_word = word

    # -- admission ----------------------------------------------------------------------
    def admit(self, command: Command, commands_enabled: bool) -> None:
        """
        Raise CommandRefused (nothing sent) unless ``command`` may be sent now.

        A stop is admitted whenever a motor may be running because of the bridge, even with
        commands disabled (node inactive or shutting down); anything else needs commands
        enabled and control allowed.
        """
        if command.stops and self.holds_run:
            return
        if not self.allow_control:
            raise CommandRefused(f'{self.name} is monitor only (allow_control is false): '
                                 'nothing sent')
        if not commands_enabled:
            raise CommandRefused('commands are disabled (node inactive or shutting down): '
                                 'nothing sent')

    def check_monitor_only(self) -> None:
        """Raise CommandRefused if monitor-only may not be switched on now (a run is held)."""
        if self.holds_run:
            raise CommandRefused(
                f'allow_control cannot be set false while the bridge holds a run command for '
                f'{self.name} ({self.describe()}): stop {self.name} first')

    def set_allow_control(self, allow: bool) -> None:
        """Switch monitor-only off or on (on: check first with :meth:`check_monitor_only`)."""
        if not allow:
            self.check_monitor_only()
            self._steady = None  # monitor only: nothing at all is written
        self.allow_control = allow

    # -- a command's life ---------------------------------------------------------------
    def sending(self, command: Command) -> None:
        """
        Record that ``command``'s first write goes on the wire now.

        On a cyclic device every command but a start writes an image without the run bit,
        so from now on the image carries that stop (a reset leaves a ramp stop), whatever
        the answer: the run image never comes back after it unasked.
        """
        self.in_flight = command
        if command.may_start:
            self.motion = Motion.MAY_RUN
            self.note = ''  # describe() says the start was sent and is not answered yet
        elif self.cyclic:
            self._steady = self._stop_after(command)

    def _stop_after(self, command: Command) -> Command:
        if command is Command.RESET:
            return self._steady if self._steady is not None and self._steady.stops \
                else Command.STOP
        return command

    def acknowledged(self, command: Command) -> None:
        """Record that every write of ``command`` was acknowledged."""
        self.in_flight = None
        if command.may_start:
            if self.cyclic:
                self._steady = Command.START
            self.motion = Motion.RUNNING
            self.note = 'start acknowledged'
        elif command.stops:
            self.motion = Motion.IDLE
            self.note = f'{command.value} acknowledged'
        elif command is Command.RESET and self.cyclic and self.motion is Motion.RUNNING:
            self.motion = Motion.IDLE  # the reset pulse leaves a stop: it never restarts
            self.note = 'reset acknowledged (it leaves a stop)'

    def refused(self, command: Command, motion_before: Motion) -> None:
        """Record that the device refused ``command`` (it did not execute it)."""
        self.in_flight = None
        if command.may_start:
            self.motion = motion_before
            self.note = 'start refused by the device'

    def unanswered(self, command: Command, motion_before: Motion, now_s: float) -> None:
        """
        Record that ``command`` got no valid acknowledgement: it may or may not have run.

        A start is never repeated: a cyclic device gets the stop image from now on, so the
        drive cannot keep running on a start that was answered as failed. A stop leaves the
        motor as "may be running" if it might have been before. ``now_s`` is when the
        failure was reported: the transports raise only after quarantining the line
        (:mod:`drive_bridge.transport.exchange`), so only a reading of a poll begun
        :data:`SETTLE_S` after it (on a clean line) can settle "may be running"; a late
        reply of an earlier read is never one.
        """
        self.in_flight = None
        self.unsure_since_s = now_s
        if command.may_start:
            self.motion = Motion.MAY_RUN
            self.note = 'start not acknowledged'
            if self.cyclic:
                self._steady = Command.STOP
                self.note += '; a stop is written every poll from now on'
        elif (command.stops or self.cyclic) and motion_before.may_be_running:
            self.motion = Motion.MAY_RUN
            self.note = f'{command.value} not acknowledged: the motor may still be running'

    # -- what the device reports ----------------------------------------------------------
    def on_reading(self, reading: DeviceReading, polled_at_s: float) -> Optional[str]:
        """
        Take a reading (its poll began at ``polled_at_s``); return a notice if it ends a run.

        A trip ends the run: the run image is replaced by a stop (a reset at the device must
        not restart the motor), and nothing of the bridge's is running any more. A "may be
        running" is settled by a stopped state read :data:`SETTLE_S` after it arose.
        """
        if not reading.tripped:
            if self.motion is Motion.MAY_RUN and self._steady is not Command.START and \
                    self.in_flight is None and reading.state in STOPPED_STATES and \
                    polled_at_s - self.unsure_since_s >= SETTLE_S:
                self.motion = Motion.IDLE  # the device says so: nothing runs
                self.note = f'the device reads {reading.state}'
            return None
        notice = None
        if self._steady is Command.START:
            self._steady = Command.STOP
            notice = 'tripped: the run command is ended; a stop is written every poll, so a ' \
                'reset does not restart the motor'
        if self.motion.may_be_running:
            self.motion = Motion.IDLE
            self.note = 'tripped: the run ended'
            notice = notice or 'tripped: the run command is ended'
        return notice

    def on_offline(self, now_s: float) -> None:
        """
        Replace the run image by a stop: the device stopped answering.

        Whether the motor still runs is unknown (may be running), and a run it might resume
        was asked for before the outage: the probes that look for the device, and the cycle
        once it is back, carry the stop image, never the run image. Start it again.
        """
        if self.cyclic and self.holds_run:
            if self._steady is Command.START:
                self._steady = Command.STOP
            self.motion = Motion.MAY_RUN
            self.unsure_since_s = now_s
            self.note = 'went offline while the bridge held a run command: it gets a stop ' \
                'as soon as it answers again; start it again when needed'
            self._lost_run = True

    def on_online(self, now_s: float) -> Optional[str]:
        """Note the device answers again; return a notice if it was lost while a run was held."""
        if not self._lost_run:
            return None
        self._lost_run = False
        return 'back online after an outage while a run was held: a stop was written, the ' \
            'run is not resumed; start it again when needed'

    def release(self, reason: str, now_s: float) -> None:
        """Stop carrying any image (stop_on_shutdown false at deactivate): nothing written."""
        if self._steady is not None:
            self._steady = None
            if self.motion is Motion.RUNNING:
                self.motion = Motion.MAY_RUN
                self.unsure_since_s = now_s
            self.note = reason

    def describe(self) -> str:
        """Return the motor state in words, for /diagnostics and refusals."""
        texts = {
            Motion.IDLE: 'no run command held',
            Motion.RUNNING: 'run command in force (start acknowledged)',
            Motion.MAY_RUN: 'may be running because of this bridge',
        }
        text = texts[self.motion]
        if self.in_flight is not None:
            text += f'; {self.in_flight.value} sent, not answered yet'
        return f'{text} ({self.note})' if self.note and self.motion is not Motion.RUNNING \
            else text
