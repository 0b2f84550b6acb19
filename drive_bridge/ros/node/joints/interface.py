"""The ROS side of the joints: ``~/joint_states``, ``~/joint_commands`` and the bridge."""

from typing import Callable, Optional, Sequence

from drive_bridge.bus.master import BusMaster
from drive_bridge.config import model as cfg
from drive_bridge.ros.node.command_inputs import CommandInputs
from drive_bridge.ros.node.joints.bridge import JointBridge
from drive_bridge.ros.node.joints.model import joint_specs, JointSpec
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

STATES_TOPIC = '~/joint_states'
# States: reliable, so ros2 topic echo and bag recorders get every one; a best-effort
# subscriber (JointStateTopicSystem's SensorDataQoS) matches it too.
STATES_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def stamp_offset_ns(node, bus_clock: Callable[[], float]) -> int:
    """Return the node clock minus the bus clock, in nanoseconds, measured now."""
    return node.get_clock().now().nanoseconds - int(round(bus_clock() * 1e9))


class JointInterface:
    """The publisher, the subscription (made by ``inputs``) and the bridge."""

    def __init__(self, node: LifecycleNode, bus: BusMaster, specs: Sequence[JointSpec],
                 is_active: Callable[[], bool], inputs: CommandInputs):
        self._node = node
        self._inputs = inputs
        self.publisher = node.create_lifecycle_publisher(JointState, STATES_TOPIC, STATES_QOS)
        self.bridge = JointBridge(bus, specs, self.publisher.publish, node.get_logger(),
                                  is_active, stamp_offset_ns(node, bus.clock))
        self.subscription = inputs.joint_commands(self.bridge.on_serialized_commands)

    def destroy(self) -> None:
        """Destroy the publisher and the subscription."""
        self._inputs.destroy(self.subscription)
        self._node.destroy_lifecycle_publisher(self.publisher)


def attach(node: LifecycleNode, bus: BusMaster, devices: Sequence[cfg.DeviceConfig],
           is_active: Callable[[], bool], inputs: CommandInputs) -> Optional[JointInterface]:
    """Create the joint topics of ``node`` if any device is a joint; else return None."""
    specs = joint_specs(devices)
    if not specs:
        return None
    node.get_logger().info('joints on ~/joint_states and ~/joint_commands: ' + ', '.join(
        f'{spec.name} ({spec.device}, {spec.velocity_scale:g} rad/s at 100 %, '
        f'{spec.command_mode})' for spec in specs))
    return JointInterface(node, bus, specs, is_active, inputs)
