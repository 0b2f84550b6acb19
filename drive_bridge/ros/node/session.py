"""
A configured bus and its ROS side: what exists from *configure* until the bus is closed.

:class:`BusSession` builds the bus (:class:`drive_bridge.bus.master.BusMaster`), one
:class:`~drive_bridge.ros.node.device_interface.DeviceInterface` per device, in a loop, and the
joints (:mod:`drive_bridge.ros.node.joints`), and hands each bus event to them.

Locking: the bus calls :meth:`BusSession._on_bus_event` from its own thread, without the
bus's lock (while its next request is on the wire), and holds the session's lock while it
hands the event on (the joints may then read a bus snapshot or submit an automatic start or
stop: the bus takes its own lock after the session's, never before). The executor takes the
session's lock only to keep the interfaces whole against an event: activation republishes
under it, deactivation withdraws the latched state and disables the publishers under it
(:meth:`BusSession.withdrawn`), and closing destroys the publishers under it; it calls
nothing of the bus while holding it.
"""

from contextlib import contextmanager
import threading
from typing import Dict, Iterator, List, Optional, TYPE_CHECKING

from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.master import BusMaster
from drive_bridge.config import model as cfg
from drive_bridge.ros.node.device_interface import CommandPaths, DeviceInterface
from drive_bridge.ros.node.device_parameters.nodes import DeviceParameterNodes
from rclpy.lifecycle import LifecycleNode

if TYPE_CHECKING:
    from drive_bridge.ros.node import joints

STOP_ALL_TIMEOUT_S = 3.0


def give_up_s(config: cfg.BridgeConfig) -> float:
    """Return how long a service waits for the bus's answer before it gives up."""
    return config.timing.command_deadline_s + 4 * config.link.timeout_s + 1.0


class BusSession:
    """The bus of one configuration, its devices' interfaces and its joints."""

    def __init__(self, node: LifecycleNode, config: cfg.BridgeConfig):
        """Build the bus, not started, commands off; :meth:`add_interfaces` comes next."""
        self.config = config
        self._logger = node.get_logger()
        self._lock = threading.Lock()
        self._devices: Dict[str, DeviceInterface] = {}
        self.joints: Optional['joints.JointInterface'] = None
        self.parameters: Optional[DeviceParameterNodes] = None  # each device's parameter node
        self.bus = BusMaster(config.make_transport(),
                             [device.make_spec() for device in config.devices],
                             config.timing, listener=self._on_bus_event)
        self.bus.set_commands_enabled(False)

    def add_interfaces(self, node: LifecycleNode, paths: CommandPaths) -> None:
        """Build each device's interface, in a loop, and the joints' (before :meth:`start`)."""
        for device in self.config.devices:
            interface = DeviceInterface(node, self.bus.snapshot(device.name), paths)
            with self._lock:
                self._devices[device.name] = interface
        self.parameters = DeviceParameterNodes(node, self.config, self.bus, paths.gate,
                                               paths.give_up_s)
        if not any(device.is_joint for device in self.config.devices):
            return
        # Imported by nodes with joints only: sensor_msgs brings numpy, 0.1 s of CPU a start.
        from drive_bridge.ros.node import joints
        with self._lock:
            self.joints = joints.attach(node, self.bus, self.config.devices,
                                        paths.gate.is_active, paths.inputs)

    @property
    def joint_bridge(self) -> Optional['joints.JointBridge']:
        """Return the joints' bridge, or None without joints."""
        interface = self.joints
        return interface.bridge if interface is not None else None

    def start(self) -> None:
        """Start the bus thread: reading begins."""
        self.bus.start()
        if self.parameters is not None:
            self.parameters.start()
        self._logger.info(
            f'bus {self.config.link.describe()}: '
            + ', '.join(f'{d.name} ({d.family} {d.model} @ {d.address}'
                        + ('' if d.allow_control else ', monitor only') + ')'
                        for d in self.config.devices))

    def activate(self) -> None:
        """Take commands on the bus; publish again what the bus told last."""
        self.bus.set_commands_enabled(True)
        with self._lock:  # in the order of the bus's events: see republish
            for device in self._devices.values():
                device.publishers.republish()

    def stop_all(self, when: str) -> List[str]:
        """
        Stop every motor that may run because of this node; log each outcome.

        Returns the devices that may still run because of it: their stop failed (refused,
        unanswered, no time left), and the bus still holds their run.
        """
        self._report_stops(self.bus.stop_all(when, STOP_ALL_TIMEOUT_S), when)
        return [name for name in self.bus.device_names if self.bus.snapshot(name).holds_run]

    @contextmanager
    def withdrawn(self) -> Iterator[None]:
        """
        Leave ``unknown`` on every latched state; hand no bus event on until the block ends.

        A subscriber that joins while the node is inactive gets the latched state: 'unknown'
        there, not the last state (say 'running' of a motor just stopped). The caller
        deactivates the publishers inside the block, so no event gets in between.
        """
        with self._lock:
            for device in self._devices.values():
                device.publishers.withdraw()
            yield

    def close(self) -> None:
        """Stop what may run because of this node, close the bus, destroy the interfaces."""
        self._report_stops(self.bus.shutdown(stop_motors=True, timeout_s=STOP_ALL_TIMEOUT_S),
                           'shutdown')
        with self._lock:  # the bus thread has ended: nothing publishes any more
            devices = list(self._devices.values())
            for device in devices:
                device.destroy_publishers()
            self._devices.clear()
            if self.joints is not None:
                self.joints.destroy()
                self.joints = None
        for device in devices:
            device.destroy_endpoints()
        if self.parameters is not None:
            self.parameters.destroy()
            self.parameters = None

    def _report_stops(self, outcomes: List[str], when: str) -> None:
        for outcome in outcomes:
            if 'acknowledged' in outcome:
                self._logger.info(f'{when}: {outcome}')
            else:
                self._logger.error(f'{when}: {outcome}')

    def _on_bus_event(self, event: BusEvent) -> None:
        """Publish a reading, or log a change, as the bus thread reports it."""
        with self._lock:
            device = self._devices.get(event.device)
            if device is None:  # an event of a bus closed since
                return
            try:
                device.show(event)
                if self.joints is not None:
                    self.joints.bridge.on_bus_event(event)
            except Exception as error:  # noqa: B902 - a bug must not kill the bus thread
                self._logger.error(f'cannot publish {type(event).__name__} of '
                                   f'{event.device}: {type(error).__name__}: {error}')
