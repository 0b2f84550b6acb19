"""
The joint states (bus thread): each reading of a joint drive becomes a ``JointState``.

Velocity = speed feedback (percent) x ``velocity_scale`` / 100; position integrated from it
by trapezoids between readings; header stamp = the bus clock of the reading moved onto the
node's clock by one offset. A tripped drive's reading is not published (the integration goes
on); an outage interrupts the integration, so the next reading adds no area.
"""

from typing import Callable, List, Tuple

from builtin_interfaces.msg import Time
from drive_bridge.bus.events import (
    BusEvent, DeviceOffline, DeviceOnline, handler_table, ignore, Notice, ReadingEvent,
    StateUnknown)
from drive_bridge.ros.node.joints.model import Joint, JointTable
from drive_bridge.ros.node.joints.starter import AutoStarter
from sensor_msgs.msg import JointState

Entry = Tuple[str, float, float]  # joint name, position (rad), velocity (rad/s)


class JointStates:
    """
    Publishes the state of each joint drive as the bus reads it.

    ``publish`` sends a JointState; ``is_active`` tells whether the node takes commands (an
    automatic stop is decided on a reading only then); ``stamp_offset_ns`` moves the bus clock
    (seconds) onto the node's clock (nanoseconds). One message per reading (docs/ros2_control.md,
    "One message per joint, not batched").
    """

    def __init__(self, table: JointTable, starter: AutoStarter,
                 publish: Callable[[JointState], None], is_active: Callable[[], bool],
                 stamp_offset_ns: int):
        self._table = table
        self._starter = starter
        self._publish = publish
        self._is_active = is_active
        self.stamp_offset_ns = stamp_offset_ns
        self.event_handlers = handler_table({
            ReadingEvent: self._on_reading, DeviceOffline: self._interrupt,
            StateUnknown: self._interrupt, DeviceOnline: ignore, Notice: ignore})

    def on_bus_event(self, event: BusEvent) -> None:
        """Publish the joint state of a reading; an outage interrupts the integration."""
        joint = self._table.by_device.get(event.device)
        if joint is not None:
            self.event_handlers[type(event)](joint, event)

    def _interrupt(self, joint: Joint, event: BusEvent) -> None:
        with self._table.lock:
            joint.integrator.interrupt()

    def _on_reading(self, joint: Joint, event: ReadingEvent) -> None:
        reading = event.reading
        if reading.speed_feedback_pct is None:
            return
        velocity = reading.speed_feedback_pct * joint.spec.velocity_scale / 100.0
        with self._table.lock:
            position = joint.integrator.add(event.stamp_s, velocity)
            joint.velocity = velocity
        if joint.spec.command_mode == 'auto_start' and self._is_active():
            self._starter.on_reading(joint)
        if reading.tripped:
            return  # never published while tripped (the integration goes on)
        stamp_ns = int(round(event.stamp_s * 1e9)) + self.stamp_offset_ns
        self._send([(joint.spec.name, position, velocity)], stamp_ns)
        joint.published += 1

    def _send(self, entries: List[Entry], stamp_ns: int) -> None:
        message = JointState()
        message.header.stamp = Time(sec=stamp_ns // 1_000_000_000,
                                    nanosec=stamp_ns % 1_000_000_000)
        message.name = [entry[0] for entry in entries]
        message.position = [float(entry[1]) for entry in entries]
        message.velocity = [float(entry[2]) for entry in entries]
        self._publish(message)
