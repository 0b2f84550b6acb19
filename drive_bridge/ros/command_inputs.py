"""
Where the node's high-rate command subscriptions are made, and nowhere else.

``~/joint_commands`` (ros2_control at controller rates) and each ``<name>/speed_reference``
can arrive at 100 Hz or more; their callbacks only hand a value to the bus (they never wait
for it). Every one of them is created and destroyed through :class:`CommandInputs`, so
they can be moved together onto a node or executor of their own (issue 29) without
touching the device interfaces or the joints. Such a node would have to keep the topic
names as they resolve now: ``~/joint_commands`` is private to the ``drive_bridge`` node.
"""

from typing import Callable

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32

JOINT_COMMANDS_TOPIC = '~/joint_commands'
# Reliable, as JointStateTopicSystem and ros2 topic pub publish them.
JOINT_COMMANDS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
SPEED_REFERENCE_DEPTH = 10


class CommandInputs:
    """Makes and destroys the high-rate command subscriptions (executor thread)."""

    def __init__(self, node: Node):
        self._node = node

    def speed_reference(self, device: str,
                        callback: Callable[[Float32], None]) -> Subscription:
        """Subscribe ``<device>/speed_reference`` (percent of the drive's reference)."""
        return self._node.create_subscription(Float32, f'{device}/speed_reference', callback,
                                              SPEED_REFERENCE_DEPTH)

    def joint_commands(self, callback: Callable[[JointState], None]) -> Subscription:
        """Subscribe ``~/joint_commands`` (ros2_control velocities, rad/s)."""
        return self._node.create_subscription(JointState, JOINT_COMMANDS_TOPIC, callback,
                                              JOINT_COMMANDS_QOS)

    def destroy(self, subscription: Subscription) -> None:
        """Destroy a subscription made here."""
        self._node.destroy_subscription(subscription)
