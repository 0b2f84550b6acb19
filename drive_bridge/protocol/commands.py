"""
The command vocabulary of the ROS contract, typed, with what each command does to a motor.

The bus's motor-state owner, the keepalive, the deadman and stop-on-shutdown follow from
these attributes (which command may start a motor, which stops one), never from name checks.
"""

import enum
from typing import Tuple


class Command(enum.Enum):
    """A command to a motor starter or drive; the value is its service name."""

    START = 'start'
    STOP = 'stop'  # soft / ramp stop
    QUICK_STOP = 'quick_stop'  # MCD: coast to stop; drives: quick-stop ramp
    COAST_STOP = 'coast_stop'  # drives: release the motor
    RESET = 'reset'  # reset a trip; never starts a motor
    FORCED_COMMS_TRIP = 'forced_comms_trip'  # MCD Modbus Module: trip the starter (stops it)

    @property
    def may_start(self) -> bool:
        """Return whether this command can make a motor run."""
        return self is Command.START

    @property
    def stops(self) -> bool:
        """Return whether this command stops a motor (always allowed while one may run)."""
        return self in STOP_COMMANDS

    @classmethod
    def parse(cls, name: str) -> 'Command':
        """Return the command named ``name``; raise ValueError with the allowed names."""
        try:
            return cls(name)
        except ValueError:
            allowed = ', '.join(command.value for command in cls)
            raise ValueError(f'unknown command {name!r}: allowed {allowed}') from None


STOP_COMMANDS: Tuple[Command, ...] = (Command.STOP, Command.QUICK_STOP, Command.COAST_STOP,
                                      Command.FORCED_COMMS_TRIP)
