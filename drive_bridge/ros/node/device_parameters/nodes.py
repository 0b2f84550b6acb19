"""
The parameter nodes of a bus's devices and the thread that spins them.

Made at *configure* (with the bus session) for each device whose family reads and writes
parameters by number, destroyed when the bus is closed. They are spun by a
``SingleThreadedExecutor`` of their own on the ``ros-parameters`` thread, not by the
bridge's executor: a request of ``ros2 param`` or rqt costs the bridge's executor nothing,
and the bridge's services and timers cost these nothing. Their callbacks are coroutines that
await the bus (never block on it), so one slow write holds up no get.
"""

import threading
from typing import Dict, List, Optional

from drive_bridge.bus.master import BusMaster
from drive_bridge.config import model as cfg
from drive_bridge.ros.node.device_parameters.device import has_parameters
from drive_bridge.ros.node.device_parameters.device_node import DeviceParameterNode
from drive_bridge.ros.node.gate import CommandGate
from drive_bridge.ros.node.spin_loop import spin_until_stopped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

THREAD_NAME = 'ros-parameters'
SPIN_TIMEOUT_S = 0.5
JOIN_TIMEOUT_S = 5.0


class DeviceParameterNodes:
    """Every device's parameter node on one bus, and their executor's thread."""

    def __init__(self, bridge: Node, config: cfg.BridgeConfig, bus: BusMaster,
                 gate: CommandGate, give_up_s: float):
        self.nodes: Dict[str, DeviceParameterNode] = {
            device.name: DeviceParameterNode(bridge, device, bus, gate, give_up_s)
            for device in config.devices if has_parameters(device)}
        self._context = bridge.context
        self._executor = SingleThreadedExecutor(context=bridge.context)
        for device in self.nodes.values():
            self._executor.add_node(device.node)
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    @property
    def names(self) -> List[str]:
        """Return the full names of the parameter nodes."""
        return [device.full_name for device in self.nodes.values()]

    def forget(self, device: str) -> None:
        """Forget the values held of ``device`` (it went offline; any thread)."""
        node = self.nodes.get(device)
        if node is not None:
            node.device.forget()

    def start(self) -> None:
        """Spin the parameter nodes on their own thread."""
        if self._thread is None and self.nodes:
            self._thread = threading.Thread(target=self._spin, name=THREAD_NAME, daemon=True)
            self._thread.start()

    def destroy(self, reason: str = 'the bus was closed') -> None:
        """Answer waiting calls, end the thread (waited for), destroy the nodes."""
        for device in self.nodes.values():
            device.close(reason)
        thread, self._thread = self._thread, None
        self._stop.set()
        self._executor.wake()
        if thread is not None:
            thread.join(JOIN_TIMEOUT_S)
        for device in self.nodes.values():
            self._executor.remove_node(device.node)
            device.destroy()
        self.nodes.clear()
        self._executor.shutdown(timeout_sec=0.0)

    def _spin(self) -> None:
        spin_until_stopped(self._executor, self._stop, self._context, THREAD_NAME,
                           SPIN_TIMEOUT_S)
