"""
Where the node's high-rate command subscriptions are made, and nowhere else.

``~/joint_commands`` (ros2_control at controller rates) and each ``<name>/speed_reference``
can arrive at 100 Hz or more; their callbacks only hand a value to the bus (they never wait
for it). They live on a node of their own, ``<node name>_commands`` in the node's
namespace, which has nothing else (no parameter services, no type description service, no
``/rosout``), spun by an executor of its own on its own thread
(:mod:`drive_bridge.ros.node.commands_thread`): a message then costs the same whatever the
number of devices, services and timers of the ``drive_bridge`` node, and a slow service or
``/diagnostics`` on the node's executor never holds a command back.

The topic names are resolved by the ``drive_bridge`` node (its name, namespace and ``-r``
remappings), so they are exactly what they were on the node itself: ``~/joint_commands`` is
``/drive_bridge/joint_commands`` (``/line1/drive_bridge/joint_commands`` in ``/line1``),
and a remapping of either topic applies. The commands node takes no process-wide arguments
(a ``-r __node:=...`` renames the ``drive_bridge`` node only, and the commands node after
it), and has no parameters of its own. Its callbacks log through the ``drive_bridge``
node's logger.

The node makes the subscriptions at configure (through :meth:`CommandInputs.speed_reference`
and :meth:`CommandInputs.joint_commands`), :meth:`CommandInputs.start` spins them, and
:meth:`CommandInputs.stop` ends the thread and waits for it before the node closes the bus,
so no command callback runs once the bus begins to close.
"""

from typing import Callable, Optional

from drive_bridge.ros.naming import COMMANDS_NODE_SUFFIX
from drive_bridge.ros.node.commands_thread import CommandsThread
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from std_msgs.msg import Float32

JOINT_COMMANDS_TOPIC = '~/joint_commands'
# Reliable, as JointStateTopicSystem and ros2 topic pub publish them.
JOINT_COMMANDS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
SPEED_REFERENCE_DEPTH = 10


def commands_node(node: Node) -> Node:
    """Return the lean node of ``node``'s command subscriptions (nothing else on it)."""
    return Node(node.get_name() + COMMANDS_NODE_SUFFIX, namespace=node.get_namespace(),
                context=node.context, use_global_arguments=False, enable_rosout=False,
                start_parameter_services=False,
                parameter_overrides=[Parameter('start_type_description_service',
                                               value=False)])


class CommandInputs:
    """Makes, spins and destroys the high-rate command subscriptions of one node."""

    def __init__(self, node: Node):
        """Make the commands node of ``node`` (the ``drive_bridge`` node), not spun yet."""
        self._node = node
        self.node = commands_node(node)
        self._thread: Optional[CommandsThread] = None

    def speed_reference(self, device: str,
                        callback: Callable[[bytes], None]) -> Subscription:
        """
        Subscribe ``<device>/speed_reference`` (percent of the drive's reference), serialized.

        ``callback`` gets each message as its CDR bytes (:mod:`drive_bridge.ros.node.cdr` reads
        them), so that bytes that are no Float32 get a reason instead of rclpy's silence.
        """
        return self._subscribe(Float32, f'{device}/speed_reference', callback,
                               SPEED_REFERENCE_DEPTH, raw=True)

    def joint_commands(self, callback: Callable[[bytes], None]) -> Subscription:
        """
        Subscribe ``~/joint_commands`` (ros2_control velocities, rad/s), serialized.

        ``callback`` gets each message as its CDR bytes (:mod:`drive_bridge.ros.node.joints.wire`
        reads them): rclpy does not build the message's Python objects. ``sensor_msgs`` is
        imported here, by nodes with joints only: it brings numpy, 0.1 s of CPU at each start.
        """
        from sensor_msgs.msg import JointState
        return self._subscribe(JointState, JOINT_COMMANDS_TOPIC, callback, JOINT_COMMANDS_QOS,
                               raw=True)

    def destroy(self, subscription: Subscription) -> None:
        """Destroy a subscription made here (the thread is stopped: see :meth:`stop`)."""
        self.node.destroy_subscription(subscription)

    def start(self) -> None:
        """Spin the subscriptions made so far on the commands thread."""
        if self._thread is None:
            self._thread = CommandsThread(self.node)

    def stop(self) -> bool:
        """End the commands thread and wait for it; return whether it ended (idempotent)."""
        thread = self._thread
        if thread is None or not thread.stop():
            return thread is None
        self._thread = None
        return True

    def destroy_node(self) -> None:
        """Stop the thread and destroy the commands node."""
        self.stop()
        self.node.destroy_node()

    def _subscribe(self, kind, topic: str, callback, qos, raw: bool = False) -> Subscription:
        """Subscribe ``topic`` as the ``drive_bridge`` node resolves it, on the commands node."""
        name = self._node.resolve_topic_name(topic)
        return self.node.create_subscription(kind, name, callback, qos, raw=raw)
