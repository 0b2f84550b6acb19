"""
The automatic starts and stops of ``command_mode: auto_start``, carried out on the bus.

:class:`AutoStarter` asks a joint's :class:`~drive_bridge.ros.node.joints.auto_start.AutoStart`
for a decision (under the joint table's lock, with the drive's facts read from a bus snapshot
before it), submits the command it returns (without the lock), and hands the outcome back
when the bus's future resolves. The command goes through
:meth:`BusMaster.submit_command`, so the bus admits it as it admits a service's: nothing is
sent to a monitor-only drive, or while the node takes no commands.
"""

from concurrent.futures import Future
from typing import Callable, List, Optional

from drive_bridge.bus.master import BusMaster
from drive_bridge.errors import CommandRefused
from drive_bridge.protocol.commands import Command
from drive_bridge.ros.node.joints.auto_start import DriveFacts
from drive_bridge.ros.node.joints.model import Joint, JointTable


class AutoStarter:
    """Carries out the automatic starts and stops of the joints in auto_start mode."""

    def __init__(self, bus: BusMaster, table: JointTable, logger,
                 clock: Callable[[], float]):
        self._bus = bus
        self._table = table
        self._logger = logger
        self._clock = clock

    def on_command(self, joint: Joint, nonzero: bool) -> None:
        """Take an accepted joint command, zero or not (commands thread)."""
        facts = DriveFacts.of(self._bus.snapshot(joint.spec.device))
        with self._table.lock:
            decision = joint.auto.command(nonzero, self._clock(), facts)
            notes, joint.auto.log = joint.auto.log, []
        self._carry_out(joint, decision, notes)

    def on_refused(self, joint: Joint, reason: str) -> None:
        """Take a joint command not taken (commands thread): no automatic start from it."""
        with self._table.lock:
            joint.auto.refused(reason)
            notes, joint.auto.log = joint.auto.log, []
        self._carry_out(joint, None, notes)

    def on_reading(self, joint: Joint) -> None:
        """Take a fresh reading of the drive (bus thread): a zero held long enough stops it."""
        facts = DriveFacts.of(self._bus.snapshot(joint.spec.device))
        with self._table.lock:
            decision = joint.auto.reading(self._clock(), facts)
            notes, joint.auto.log = joint.auto.log, []
        self._carry_out(joint, decision, notes)

    def _carry_out(self, joint: Joint, decision: Optional[Command], notes: List[str]) -> None:
        spec = joint.spec
        for note in notes:
            self._logger.warning(f'{spec.device} (joint {spec.name}): {note}')
        if decision is None:
            return
        if decision is Command.START:
            self._logger.info(f'{spec.device} (joint {spec.name}): automatic start (nonzero '
                              'joint command)')
        else:
            self._logger.info(f'{spec.device} (joint {spec.name}): automatic ramp stop (zero '
                              f'joint command held {spec.auto_stop_delay_s:g} s)')
        future = self._bus.submit_command(spec.device, decision)
        future.add_done_callback(lambda done: self._done(joint, decision, done))

    def _done(self, joint: Joint, command: Command, future: Future) -> None:
        error = future.exception() if not future.cancelled() else CommandRefused('cancelled')
        with self._table.lock:
            if command is Command.START:
                joint.auto.start_done(error)
            else:
                joint.auto.stop_done(error)
            notes, joint.auto.log = joint.auto.log, []
        spec = joint.spec
        if error is None:
            self._logger.info(f'{spec.device} (joint {spec.name}): automatic {command.value} '
                              'acknowledged')
        else:
            self._logger.error(f'{spec.device} (joint {spec.name}): automatic '
                               f'{command.value} failed: {error}')
        for note in notes:
            self._logger.warning(f'{spec.device} (joint {spec.name}): {note}')
