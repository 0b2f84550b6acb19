"""
The parameter node of one device: ``<device>_parameters`` in the bridge's namespace.

A plain rclpy node made with ``start_parameter_services=False``, which serves the parameter
services itself (:mod:`.services`) so that ``ros2 param`` and rqt_reconfigure find the
device's parameters on it. It takes no process-wide arguments (a ``-r __node:=...`` renames
the bridge only) and has no ``/rosout`` (it logs through the bridge's logger); it follows the
bridge's ``use_sim_time``. Its own parameters:

- ``refresh_period`` (double, s, default 0.5; 0: off): one parameter read again every
  period in the background, while someone looks (:mod:`.refresher`);
- ``refresh_while_watched`` (double, s, default 30; 0: never in the background): how long
  after the last call of a parameter service the background refresh runs (then it stops
  and the values held are forgotten);
- ``save_to_eeprom`` (bool, default false; drives only): a set is stored in RAM, or with
  true in RAM and EEPROM (it then survives a power cycle);
- ``use_sim_time`` and the read-only ``start_type_description_service``, as every node has.

A value the device reports (a write's read back, a refused write's value held, a change the
refresh sees) goes out on ``/parameter_events`` with this node's full name.
"""

from typing import Any

from drive_bridge.bus.master import BusMaster
from drive_bridge.config import model as cfg
from drive_bridge.devices.remote_parameters import RemoteParameter
from drive_bridge.ros.node.device_parameters import messages
from drive_bridge.ros.node.device_parameters.device import DeviceParameters
from drive_bridge.ros.node.device_parameters.refresher import (
    DEFAULT_REFRESH_PERIOD_S, DEFAULT_WATCH_WINDOW_S, Refresher)
from drive_bridge.ros.node.device_parameters.services import ParameterServices
from drive_bridge.ros.node.device_parameters.writer import DeviceWriter
from drive_bridge.ros.node.gate import CommandGate
from drive_bridge.ros.node.service_calls import ServiceCalls
from rcl_interfaces.msg import (
    FloatingPointRange, Parameter as ParameterMessage, ParameterDescriptor, ParameterEvent)
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_parameter_events

NODE_SUFFIX = '_parameters'
# The refresh and the give-up of waiting calls are looked at this often, while someone looks
# at the parameters or a call waits for the bus; otherwise the timer is cancelled.
TICK_S = 0.1
MAX_REFRESH_PERIOD_S = 3600.0
MAX_WATCH_WINDOW_S = 86400.0


def parameter_node(bridge: Node, device: str) -> Node:
    """Return the bare parameter node of ``device`` beside ``bridge`` (same namespace)."""
    use_sim_time = bridge.get_parameter('use_sim_time').value
    return Node(device + NODE_SUFFIX, namespace=bridge.get_namespace(),
                context=bridge.context, use_global_arguments=False, enable_rosout=False,
                start_parameter_services=False,
                parameter_overrides=[Parameter('use_sim_time', value=use_sim_time),
                                     Parameter('start_type_description_service',
                                               value=False)])


class DeviceParameterNode:
    """One device's parameter node: its parameters, services, refresh and events."""

    def __init__(self, bridge: Node, device: cfg.DeviceConfig, bus: BusMaster,
                 gate: CommandGate, give_up_s: float):
        self.node = parameter_node(bridge, device.name)
        self.logger = bridge.get_logger()
        self._events = self.node.create_publisher(ParameterEvent, '/parameter_events',
                                                  qos_profile_parameter_events)
        self.device = DeviceParameters(device, bus, self.announce)
        self._declare_own()
        self.calls = ServiceCalls(self.node)
        writer = DeviceWriter(self.device, self.calls, gate, give_up_s, self._save_to_eeprom,
                              self.announce)
        self._refresher = Refresher(
            self.device, lambda: float(self.node.get_parameter('refresh_period').value),
            lambda: float(self.node.get_parameter('refresh_while_watched').value))
        ParameterServices(self.node, self.device, writer, self.calls, self._watched)
        # Runs only while needed (see _tick): an idle device costs its executor no wakeups.
        self._timer = self.node.create_timer(
            TICK_S, self._tick, callback_group=self.calls.callback_group,
            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.calls.on_waiting = self._ensure_ticking  # each wait has its give-up looked at

    @property
    def full_name(self) -> str:
        """Return the node's full name (``/line1/feeder_parameters``)."""
        return self.node.get_fully_qualified_name()

    def _declare_own(self) -> None:
        self.node.declare_parameter(
            'refresh_period', DEFAULT_REFRESH_PERIOD_S, ParameterDescriptor(
                description='s between two background reads of one parameter (0: off)',
                floating_point_range=[FloatingPointRange(
                    from_value=0.0, to_value=MAX_REFRESH_PERIOD_S, step=0.0)]))
        self.node.declare_parameter(
            'refresh_while_watched', DEFAULT_WATCH_WINDOW_S, ParameterDescriptor(
                description='s the background refresh runs after the last call of a parameter '
                'service (then it stops and the values held are forgotten; 0: never)',
                floating_point_range=[FloatingPointRange(
                    from_value=0.0, to_value=MAX_WATCH_WINDOW_S, step=0.0)]))
        if self.device.eeprom:
            self.node.declare_parameter('save_to_eeprom', False, ParameterDescriptor(
                description='false: a set is stored in RAM (lost at power off); true: in '
                'RAM and EEPROM'))

    def _save_to_eeprom(self) -> bool:
        return self.device.eeprom and bool(self.node.get_parameter('save_to_eeprom').value)

    def announce(self, parameter: RemoteParameter, value: Any) -> None:
        """Publish the value the device holds on /parameter_events (any thread)."""
        changed = ParameterMessage(name=parameter.name,
                                   value=messages.value_message(parameter, value))
        try:
            self._events.publish(messages.event(
                self.full_name, self.node.get_clock().now().to_msg(), [changed]))
        except Exception as error:  # noqa: B902 - the node is being destroyed: say so
            self.logger.debug(f'{self.full_name}: parameter event not published: {error}')

    def _watched(self) -> None:
        """Note a parameter service call (executor thread): refresh, and tick again."""
        self._refresher.watched()
        self._ensure_ticking()

    def _ensure_ticking(self) -> None:
        """Start the timer again if it was cancelled (executor thread)."""
        if self._timer.is_canceled():
            self._timer.reset()

    def _tick(self) -> None:
        # Calls begin to wait only in callbacks of this thread: none begins during the tick.
        waiting = self.calls.waiting()
        if waiting:
            self.calls.wake()  # answer calls the bus left waiting too long
        self._refresher.tick()
        # The window closed at this tick or before (the refresher forgot its values) and no
        # call waits: nothing to do until the next call or wait, which start the timer
        # again, so no wakeups (10 a second per device cost a node 1.3 % of a core per
        # device, idle). Decided by what this tick found, not by the clock again: a window
        # that closed between the two would leave its values held.
        if not self._refresher.active and not waiting:
            self._timer.cancel()

    def close(self, reason: str) -> None:
        """Answer every call waiting for the bus (it is closed)."""
        self.calls.answer_all(reason)

    def destroy(self) -> None:
        """Destroy the node (its executor no longer spins it)."""
        self.calls.destroy_retired()
        self.node.destroy_node()
