"""
One device's ROS interface: its topics, its ``speed_reference`` and its Trigger services.

Like ros2_canopen's per-axis ``ChannelContext``: the node builds one :class:`DeviceInterface`
per configured device, in a loop, under the device's name, and destroys them when it closes
the bus. The services are coroutines that submit the command and await the bus's answer
(:mod:`drive_bridge.ros.node.service_calls`); ``speed_reference`` only hands the value to the bus.
Both ask the :class:`~drive_bridge.ros.node.gate.CommandGate` first, so an inactive node sends
nothing but stops, and a closed bus nothing at all. A service that is still answering a call
when the bus closes is destroyed only a grace time after that answer went out
(:meth:`~drive_bridge.ros.node.service_calls.ServiceCalls.destroy_later`): a destroyed service
cannot send it, and its DDS writer deleted right after sending may not have delivered it.
"""

from dataclasses import dataclass
import functools
import threading
import time

from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.master import DeviceSnapshot
from drive_bridge.config import model as cfg
from drive_bridge.errors import CommandRefused, DriveBridgeError
from drive_bridge.protocol.commands import Command
from drive_bridge.ros.node.bus_events import publish_event
from drive_bridge.ros.node.cdr import MalformedMessage, read_float32
from drive_bridge.ros.node.command_inputs import CommandInputs
from drive_bridge.ros.node.gate import CommandGate
from drive_bridge.ros.node.publishers import DevicePublishers
from drive_bridge.ros.node.service_calls import ServiceCalls
from drive_bridge.ros.node.throttle import Throttle
from rclpy.lifecycle import LifecycleNode
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float32
from std_srvs.srv import Trigger

SERVICE_COMMANDS = (Command.START, Command.STOP, Command.QUICK_STOP, Command.COAST_STOP,
                    Command.RESET)


@dataclass(frozen=True)
class CommandPaths:
    """What every device's interface shares with the node for its commands."""

    gate: CommandGate
    calls: ServiceCalls
    inputs: CommandInputs
    give_up_s: float  # a service gives up waiting for the bus after this


class DeviceInterface:
    """The publishers, the speed_reference subscription and the services of one device."""

    def __init__(self, node: LifecycleNode, snapshot: DeviceSnapshot, paths: CommandPaths):
        self.name = snapshot.name
        self._node = node
        self._logger = node.get_logger()
        self._paths = paths
        self._warn = Throttle(lambda text: self._logger.warning(text), time.monotonic)
        self.publishers = DevicePublishers(node, self.name, snapshot.reading_fields)
        self.publishers.publish_state('unknown')
        self._speed_reference = None
        self._deserialize = functools.partial(deserialize_message, message_type=Float32)
        if cfg.FAMILIES[snapshot.family].reference:
            self._speed_reference = paths.inputs.speed_reference(self.name,
                                                                 self._on_speed_reference)
        self._lock = threading.Lock()
        self._calls_in_progress = 0
        self._closing = False
        self._services = [
            node.create_service(Trigger, f'{self.name}/{command.value}',
                                functools.partial(self._on_trigger, command),
                                callback_group=paths.calls.callback_group)
            for command in SERVICE_COMMANDS if command in snapshot.commands]

    def show(self, event: BusEvent) -> None:
        """Publish or log a bus event of this device (bus thread)."""
        publish_event(self.publishers, self._logger, event)

    def destroy_publishers(self) -> None:
        """Destroy the device's publishers (nothing publishes any more)."""
        self.publishers.destroy()

    def destroy_endpoints(self) -> None:
        """Destroy the speed_reference subscription, and the services once they answered."""
        if self._speed_reference is not None:
            self._paths.inputs.destroy(self._speed_reference)
            self._speed_reference = None
        with self._lock:
            self._closing = True
            answering = self._calls_in_progress > 0
        if not answering:
            self._destroy_services()

    def _destroy_services(self) -> None:
        with self._lock:
            services, self._services = self._services, []
        for service in services:
            self._node.destroy_service(service)

    def _call_ended(self) -> None:
        """Count a call out; the last one of a closed interface has its services retired."""
        with self._lock:
            self._calls_in_progress -= 1
            last = self._closing and self._calls_in_progress == 0
        if last:  # once its response has had time to reach the client
            self._paths.calls.destroy_later(self._destroy_services)

    async def _on_trigger(self, command: Command, request: Trigger.Request,
                          response: Trigger.Response) -> Trigger.Response:
        """Send ``command`` and answer once the device acknowledged it or it failed."""
        with self._lock:
            self._calls_in_progress += 1
        try:
            response.message = await self._command(command)
            response.success = True
        except DriveBridgeError as error:
            response.success, response.message = False, str(error)
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            response.success = False
            response.message = f'{command.value} failed: internal error ' \
                f'{type(error).__name__}: {error}'
        finally:
            self._call_ended()
        if response.success:  # one logging call site per severity (rclpy caches them)
            self._logger.info(f'{self.name}/{command.value}: {response.message}')
        else:
            self._logger.warning(f'{self.name}/{command.value}: {response.message}')
        return response

    async def _command(self, command: Command) -> str:
        gate = self._paths.gate
        bus = gate.bus_for(command)
        future = bus.submit_command(self.name, command)
        if future.done() and future.exception() is not None and not gate.active:
            raise CommandRefused(f'{gate.inactive_reason()} ({future.exception()})')
        return await self._paths.calls.answer_of(future, command.value, self._paths.give_up_s)

    def _on_speed_reference(self, data: bytes) -> None:
        """Hand the reference to the bus (the commands thread); a refusal is logged throttled."""
        try:
            percent = read_float32(data, self._deserialize)
        except MalformedMessage as error:
            reason = str(error)
            self._warn('malformed', lambda: f'{self.name}/speed_reference: not a '
                       f'std_msgs/Float32 ({reason}): ignored, nothing sent')
            bus = self._paths.gate.bus
            if bus is not None:
                bus.count_rejected_reference(self.name)
            return
        gate = self._paths.gate
        bus = gate.bus
        if not gate.active or bus is None:
            self._warn('inactive', lambda: f'{self.name}/speed_reference: '
                       f'{gate.inactive_reason()}')
            return
        try:
            bus.set_speed_reference(self.name, percent, from_topic=True)
        except CommandRefused as error:
            reason = str(error)
            self._warn('refused', lambda: f'{self.name}/speed_reference: {reason}')
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            self._logger.error(f'{self.name}/speed_reference: internal error '
                               f'{type(error).__name__}: {error}')
