"""
The node's ``/diagnostics``: one ``DiagnosticArray`` a period, from what each part tells.

As diagnostic_updater separates its tasks from the updater, the array is put together here
from sources that know nothing of it: each device's status from its bus snapshot
(:func:`drive_bridge.ros.node.diagnostics.diagnostic_status`), then the runtime change of its
``allow_control`` (:class:`drive_bridge.ros.node.parameters.RuntimeSettings`) and its joint
values, then one status for ``~/joint_commands`` (:mod:`drive_bridge.ros.node.joints`). While no
bus is open (unconfigured, or closing) the array is empty; while no subscription is matched
to ``/diagnostics`` nothing is built. Executor thread only.
"""

from dataclasses import dataclass
from typing import List, Mapping, Optional, Protocol

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from drive_bridge.bus.master import BusMaster
from drive_bridge.ros.naming import status_name
from drive_bridge.ros.node.command_inputs import JOINT_COMMANDS_TOPIC
from drive_bridge.ros.node.diagnostics import diagnostic_status
from rclpy.node import Node

INACTIVE_COMMANDS = 'refused (node inactive; stops taken while a motor may run)'


class JointDiagnostics(Protocol):
    """What the joints add to /diagnostics (:class:`drive_bridge.ros.node.joints.JointBridge`)."""

    def device_values(self, device: str) -> List[KeyValue]:
        """Return the joint values of one device (none if it is not a joint)."""

    def commands_status(self, name: str) -> DiagnosticStatus:
        """Return the status of ``~/joint_commands`` under ``name``."""


@dataclass(frozen=True)
class DiagnosticSources:
    """What one array is built from."""

    bus: BusMaster
    link: str  # the link, described
    active: bool  # the node takes commands
    runtime_changes: Mapping[str, str]  # device -> its allow_control changed, in words
    joints: Optional[JointDiagnostics]


def device_statuses(sources: DiagnosticSources, fqn: str) -> List[DiagnosticStatus]:
    """Return the status of every device, with its runtime change and joint values."""
    bus = sources.bus
    commands = 'enabled' if sources.active else INACTIVE_COMMANDS
    statuses = [diagnostic_status(bus.snapshot(name), status_name(fqn, name), sources.link,
                                  commands)
                for name in bus.device_names]
    for status, name in zip(statuses, bus.device_names):
        if name in sources.runtime_changes:
            status.values.append(KeyValue(key='allow_control_changed',
                                          value=sources.runtime_changes[name]))
    if sources.joints is not None:
        for status, name in zip(statuses, bus.device_names):
            status.values.extend(sources.joints.device_values(name))
    return statuses


class DiagnosticsPublisher:
    """The node's /diagnostics publisher (created with the node, published by a timer)."""

    def __init__(self, node: Node):
        self._node = node
        self._publisher = node.create_publisher(DiagnosticArray, '/diagnostics', 10)

    def publish(self, sources: Optional[DiagnosticSources]) -> None:
        """
        Publish the array of ``sources`` (None: no bus, an empty array); never raise.

        Only while a subscription is matched (an aggregator, ``ros2 topic echo``, a bag):
        the topic is volatile, so an array nobody receives is lost anyway, and building it
        (some 50 values a device) was about a quarter of the executor's CPU with 8 devices
        and 4 service calls a second (cProfile).
        """
        try:
            if self._publisher.get_subscription_count() == 0:
                return
            self._publisher.publish(self.array(sources))
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            self._node.get_logger().error(f'cannot publish diagnostics: '
                                          f'{type(error).__name__}: {error}')

    def array(self, sources: Optional[DiagnosticSources]) -> DiagnosticArray:
        """Return the DiagnosticArray of ``sources``, stamped now."""
        array = DiagnosticArray()
        array.header.stamp = self._node.get_clock().now().to_msg()
        if sources is None:
            return array
        fqn = self._node.get_fully_qualified_name()
        array.status = device_statuses(sources, fqn)
        if sources.joints is not None:
            array.status.append(sources.joints.commands_status(
                status_name(fqn, JOINT_COMMANDS_TOPIC)))
        return array
