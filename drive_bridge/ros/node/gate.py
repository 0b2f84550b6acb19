"""
Whether the node takes commands now, and on which bus: what every command path asks first.

The lifecycle sets it (executor thread; the main thread on an exit signal); the Trigger
services and the diagnostics (executor thread), ``speed_reference`` and the joint commands
(the commands thread of :mod:`drive_bridge.ros.node.command_inputs`) read it: each a plain
attribute read, so a reader sees the value before or after a change, never a mix. A
closed bus is None from the moment the node begins to close it, so nothing is submitted to
a bus that is stopping its motors and shutting down.
"""

from typing import Callable, Optional

from drive_bridge.bus.master import BusMaster
from drive_bridge.errors import CommandRefused
from drive_bridge.protocol.commands import Command


class CommandGate:
    """The bus that takes commands (None: closed) and whether the node is active."""

    def __init__(self, lifecycle_label: Callable[[], str]):
        self.bus: Optional[BusMaster] = None
        self.active = False
        self._lifecycle_label = lifecycle_label

    def is_active(self) -> bool:
        """Return whether the node is active (takes commands, not just stops)."""
        return self.active

    def inactive_reason(self) -> str:
        """Return why a command is refused while the node is not active."""
        return f'node is {self._lifecycle_label()} (lifecycle): activate it first; nothing sent'

    def bus_for(self, command: Command) -> BusMaster:
        """Return the bus to send ``command`` on; raise CommandRefused if it is not taken now."""
        bus = self.bus
        if bus is None or (not self.active and not command.stops):
            raise CommandRefused(self.inactive_reason())
        return bus
