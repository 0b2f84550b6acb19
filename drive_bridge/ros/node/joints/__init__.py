"""
The drives as ros2_control joints: ``~/joint_states`` and ``~/joint_commands`` in SI units.

The other side of ``joint_state_topic_hardware_interface/JointStateTopicSystem``, or of any
node that takes ``sensor_msgs/JointState`` states and sends ``sensor_msgs/JointState``
commands. A drive is a joint when its ``velocity_scale`` (rad/s of the joint at 100 %
reference) is not 0.

States (bus thread): every reading of a joint drive becomes one ``JointState`` with just
that joint: velocity = speed feedback (percent) x ``velocity_scale`` / 100, position
integrated from it by trapezoids between readings (rad, from 0 at configure), header stamp =
the bus clock of the reading (``BusEvent.stamp_s``, ``time.monotonic``) moved onto the
node's clock by one offset measured at configure. A drive that is offline, unknown, tripped
or not yet read is left out. After an outage the position is held and integration starts
again from the next reading: what the motor did meanwhile is unknown.

Commands (the commands thread of :mod:`drive_bridge.ros.node.command_inputs`): each velocity of
a known joint becomes the speed reference (rad/s -> % by ``velocity_scale``) through
:meth:`BusMaster.set_speed_reference` with ``from_topic``, so the rules, the counters and
the deadman are those of ``speed_reference``; the bus writes the latest reference with its
next poll, so commands cost no bus traffic of their own. Unknown names, messages without
velocities and messages whose velocities do not match their names are counted and logged at
most once a second per kind.

``command_mode: auto_start`` (:mod:`drive_bridge.ros.node.joints.auto_start`): a nonzero
command starts a stopped, untripped drive; a zero command held ``auto_stop_delay`` seconds
ramp-stops it. Never two automatic starts (or stops) in flight for one drive; a failed
automatic start, a trip, a stop the node did not make itself (a stop service, the deadman,
deactivate), a switch to auto_start, the drive seen monitor-only or a refused joint command
keeps automatic starts off until the command goes to zero (and back). A trip is never reset
automatically.

The parts (one module each), composed by :class:`JointBridge` around one
:class:`~drive_bridge.ros.node.joints.model.JointTable`: ``states`` (bus thread), ``commands``
(commands thread), ``auto_start`` (the decisions, no I/O) and ``starter`` (carrying them
out on the bus), ``settings`` (runtime changes), ``values`` (what /diagnostics shows), and
``interface`` (the publisher and the subscription, made through
:class:`drive_bridge.ros.node.command_inputs.CommandInputs`).

Locking: the bus calls the listener from its own thread, without its lock (while a request is
on the wire); the parts change a joint's record only under the table's lock and never call
the bus while holding it.
"""

from drive_bridge.ros.node.command_inputs import (  # noqa: F401 - part of this package's API
    JOINT_COMMANDS_QOS as COMMANDS_QOS, JOINT_COMMANDS_TOPIC as COMMANDS_TOPIC)
from drive_bridge.ros.node.joints.auto_start import AutoStart, DriveFacts  # noqa: F401
from drive_bridge.ros.node.joints.bridge import JointBridge  # noqa: F401
from drive_bridge.ros.node.joints.interface import (  # noqa: F401
    attach, JointInterface, stamp_offset_ns, STATES_QOS, STATES_TOPIC)
from drive_bridge.ros.node.joints.model import Integrator, joint_specs, JointSpec  # noqa: F401
