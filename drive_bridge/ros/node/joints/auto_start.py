"""
``command_mode: auto_start`` of one drive: the decisions, no I/O.

A nonzero command starts a stopped, untripped drive; a zero command held
``auto_stop_delay`` seconds ramp-stops it. Never two automatic starts (or stops) in flight
for one drive; a failed automatic start, a trip, a stop the node did not make itself (a stop
service, the deadman, deactivate), a switch to auto_start, the drive seen monitor-only
(``allow_control`` false) or a joint command refused (one that came while the node was
inactive too) keeps automatic starts off until the command goes to zero (and back), with
the drive untripped and controllable: so a command that was already there when control came
back, or when the node became active, starts nothing. A trip is never reset automatically.
:class:`drive_bridge.ros.node.joints.starter.AutoStarter` carries the decisions out.
"""

from dataclasses import dataclass, field
from typing import List, Optional

from drive_bridge.bus.master import DeviceSnapshot
from drive_bridge.protocol.commands import Command

SWITCHED = 'command_mode switched to auto_start'


@dataclass
class DriveFacts:
    """What an automatic start or stop decision needs to know about the drive now."""

    holds_run: bool
    online: bool
    tripped: bool
    allow_control: bool

    @classmethod
    def of(cls, snapshot: DeviceSnapshot) -> 'DriveFacts':
        """Return the facts of a bus snapshot."""
        reading = snapshot.reading
        return cls(snapshot.holds_run, snapshot.online is True,
                   reading is not None and reading.tripped, snapshot.allow_control)


@dataclass
class AutoStart:
    """
    ``command_mode: auto_start`` of one drive: the decisions, no I/O (see the module doc).

    :meth:`command` and :meth:`reading` return the command to submit (START or STOP) or
    None; :meth:`start_done` and :meth:`stop_done` take the outcome of one submitted.
    """

    delay_s: float
    starting: bool = False  # an automatic start is in flight
    stopping: bool = False  # an automatic stop is in flight
    blocked: str = ''  # why automatic starts wait for the command to go to zero and back
    zero_since_s: Optional[float] = None
    holding: bool = False  # the bridge held a run command when last seen
    expect_stop: bool = False  # our automatic stop, not someone else's, ends the run
    starts: int = 0
    stops: int = 0
    failed_starts: int = 0
    log: List[str] = field(default_factory=list)  # what happened, for the caller to log

    def command(self, nonzero: bool, now_s: float, drive: DriveFacts) -> Optional[Command]:
        """Take one accepted command, zero or not, at ``now_s``."""
        self._observe(drive)
        if not nonzero:
            if self.blocked and not drive.tripped and drive.allow_control:
                self.log.append('zero command: automatic starts are armed again')
                self.blocked = ''  # (a tripped or monitor-only drive stays blocked)
            if self.zero_since_s is None:
                self.zero_since_s = now_s
            return self._stop_if_due(now_s, drive)
        self.zero_since_s = None
        if self.blocked or self.starting or drive.holds_run or drive.tripped or \
                not drive.online or not drive.allow_control:
            return None
        self.starting = True
        self.starts += 1
        return Command.START

    def reading(self, now_s: float, drive: DriveFacts) -> Optional[Command]:
        """Take a fresh reading of the drive; a zero held long enough stops it."""
        self._observe(drive)
        return self._stop_if_due(now_s, drive)

    def refused(self, reason: str) -> None:
        """Block automatic starts after a joint command the bridge did not take."""
        self._block(f'a joint command was refused ({reason})')

    def start_done(self, error: Optional[BaseException]) -> None:
        """Take the outcome of an automatic start (None: acknowledged)."""
        self.starting = False
        if error is not None:
            self.failed_starts += 1
            self._block(f'automatic start failed ({error})')

    def stop_done(self, error: Optional[BaseException]) -> None:
        """Take the outcome of an automatic stop (None: acknowledged)."""
        self.stopping = False
        if error is not None:
            self.expect_stop = False

    def reset(self, delay_s: float, holding: bool, blocked: str = '') -> None:
        """Start afresh: a change of command_mode (``holding``: the bridge holds a run now)."""
        self.delay_s = delay_s
        self.zero_since_s = None
        self.holding = holding
        self.expect_stop = False
        self.blocked = blocked

    def _observe(self, drive: DriveFacts) -> None:
        if drive.tripped:
            self._block('the drive tripped')
        elif not drive.allow_control:
            self._block('the drive is monitor only (allow_control false)')
        elif self.holding and not drive.holds_run and not self.expect_stop:
            self._block('stopped by something else than an automatic stop (a stop service, '
                        'the deadman, deactivate)')
        if not drive.holds_run:
            self.expect_stop = False
        self.holding = drive.holds_run

    def _block(self, reason: str) -> None:
        if not self.blocked:
            self.log.append(f'{reason}: automatic starts wait until the command goes to zero '
                            'and back')
        self.blocked = reason

    def _stop_if_due(self, now_s: float, drive: DriveFacts) -> Optional[Command]:
        if self.zero_since_s is None or self.stopping or self.starting or \
                not drive.holds_run or now_s - self.zero_since_s < self.delay_s:
            return None
        self.stopping = True
        self.expect_stop = True
        self.stops += 1
        return Command.STOP
