"""The joints of one node: the parts composed, one object for the node to hold."""

import time
from typing import Callable, Dict, List, Sequence

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.master import BusMaster
from drive_bridge.ros.node.joints.commands import JointCommands
from drive_bridge.ros.node.joints.model import Joint, JointSpec, JointTable
from drive_bridge.ros.node.joints.settings import JointSettings, SettingChanges
from drive_bridge.ros.node.joints.starter import AutoStarter
from drive_bridge.ros.node.joints.states import JointStates
from drive_bridge.ros.node.joints.values import JointValues
from sensor_msgs.msg import JointState


class JointBridge:
    """
    The joints of one node (see :mod:`drive_bridge.ros.node.joints`).

    Its parts share the joint table (:class:`~drive_bridge.ros.node.joints.model.JointTable`):
    the states (bus thread), the commands, the automatic starts, the runtime settings and
    the diagnostics values. ``publish`` sends a JointState; ``is_active`` tells whether the
    node takes commands; ``stamp_offset_ns`` moves the bus clock (seconds) onto the node's
    clock (nanoseconds).
    """

    def __init__(self, bus: BusMaster, specs: Sequence[JointSpec],
                 publish: Callable[[JointState], None], logger,
                 is_active: Callable[[], bool], stamp_offset_ns: int,
                 clock: Callable[[], float] = time.monotonic):
        self.bus = bus
        table = JointTable(specs)
        self.joints: Dict[str, Joint] = table.by_device
        self.by_name: Dict[str, Joint] = table.by_name
        starter = AutoStarter(bus, table, logger, clock)
        self.states = JointStates(table, starter, publish, is_active, stamp_offset_ns)
        self.commands = JointCommands(bus, table, starter, logger, is_active, clock)
        self.settings = JointSettings(bus, table, logger)
        self.values = JointValues(table, self.commands.counts, clock)
        self.counters: Dict[str, int] = self.commands.counts.counters
        self.event_handlers = self.states.event_handlers

    def on_bus_event(self, event: BusEvent) -> None:
        """Publish the joint state of a reading (bus thread); see JointStates."""
        self.states.on_bus_event(event)

    def on_commands(self, message: JointState) -> None:
        """Take a JointState command (commands thread); see JointCommands."""
        self.commands.on_commands(message)

    def on_serialized_commands(self, data: bytes) -> None:
        """Take a serialized JointState command (commands thread); see JointCommands."""
        self.commands.on_serialized(data)

    def check_settings(self, changes: SettingChanges) -> None:
        """Raise ConfigError for a runtime change the joints cannot take (nothing applied)."""
        self.settings.check_settings(changes)

    def apply_settings(self, changes: SettingChanges) -> None:
        """Take runtime changes of command_mode and auto_stop_delay."""
        self.settings.apply_settings(changes)

    def device_values(self, device: str) -> List[KeyValue]:
        """Return the joint values of one device for its /diagnostics status."""
        return self.values.device_values(device)

    def commands_status(self, name: str) -> DiagnosticStatus:
        """Return the status of ``~/joint_commands`` (``name`` from status_name)."""
        return self.values.commands_status(name)
