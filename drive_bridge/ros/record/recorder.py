"""
Record topics into a rosbag2 bag with MCAP storage, written by the ``rosbags`` library.

The bag is what ``ros2 bag record`` (Jazzy) writes, as far as rosbags writes it: a directory
with ``metadata.yaml`` (version 9) and one ``.mcap`` file (profile ``ros2``, ``ros2msg``
schemas, CDR messages kept as received through ``raw=True`` subscriptions). Each topic
carries the QoS profiles its publishers offer, taken from the ROS graph as rosbag2 takes
them, so ``ros2 bag play`` replays the latched ``<device>/state`` and ``<device>/trip``
(transient local, depth 1) as latched, and its RIHS01 type hash. Like rosbag2, the recorder
asks for transient local only when every publisher of a topic offers it, and for reliable
only when every publisher is reliable.
"""

import functools
import importlib
import time
from typing import Dict, List, Optional

from drive_bridge.errors import RecordingError
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import (
    Connection, Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import get_typestore, Stores

SUBSCRIPTION_DEPTH = 100  # rosbag2 asks for 10; a busy machine can run behind a 10 Hz poll
NANOSECONDS_PER_SECOND = 1_000_000_000
BAG_VERSION = 9  # what Jazzy's rosbag2 writes


def rosbags_qos(profile: QoSProfile) -> Qos:
    """Return an rclpy QoS profile (as the graph reports an offer) as rosbags' ``Qos``."""
    def duration(value) -> QosTime:
        seconds, nanoseconds = divmod(value.nanoseconds, NANOSECONDS_PER_SECOND)
        return QosTime(seconds, nanoseconds)
    return Qos(QosHistory(int(profile.history)), int(profile.depth),
               QosReliability(int(profile.reliability)), QosDurability(int(profile.durability)),
               duration(profile.deadline), duration(profile.lifespan),
               QosLiveliness(int(profile.liveliness)),
               duration(profile.liveliness_lease_duration),
               bool(profile.avoid_ros_namespace_conventions))


def request_qos(offers: List[QoSProfile]) -> QoSProfile:
    """Return the subscription QoS that receives from every offer (rosbag2's rule)."""
    profile = QoSProfile(depth=SUBSCRIPTION_DEPTH)
    if offers and not all(offer.reliability == ReliabilityPolicy.RELIABLE for offer in offers):
        profile.reliability = ReliabilityPolicy.BEST_EFFORT
    if offers and all(offer.durability == DurabilityPolicy.TRANSIENT_LOCAL for offer in offers):
        profile.durability = DurabilityPolicy.TRANSIENT_LOCAL
    return profile


@functools.lru_cache(maxsize=1)
def jazzy_typestore():
    """Return rosbags' store of the ROS 2 Jazzy message types (definitions and hashes)."""
    return get_typestore(Stores.ROS2_JAZZY)


def is_recordable(type_name: str) -> bool:
    """Return whether rosbags knows ``type_name`` (``pkg/msg/Name``) as a Jazzy type."""
    return type_name in jazzy_typestore().fielddefs


class BagRecorder:
    """Write every message of the added topics into a new bag until :meth:`close`."""

    def __init__(self, node: Node, output: str):
        self._node = node
        self._typestore = jazzy_typestore()
        self._writer = Writer(output, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except (WriterError, OSError) as error:
            raise RecordingError(f'cannot create the bag: {error}') from None
        self.path = output
        self._started_s = time.monotonic()
        self._stopped_s: Optional[float] = None
        self.counts: Dict[str, int] = {}
        self._types: Dict[str, str] = {}
        self._connections: Dict[str, Connection] = {}
        self._subscriptions = {}

    @property
    def topics(self) -> Dict[str, str]:
        """Return topic -> type name of every topic being recorded."""
        return dict(self._types)

    def matched(self) -> bool:
        """Return whether every subscription is connected to every publisher the graph shows."""
        return all(subscription.get_publisher_count()
                   >= len(self._node.get_publishers_info_by_topic(topic))
                   for topic, subscription in self._subscriptions.items())

    def restart_clock(self) -> None:
        """Count :meth:`elapsed_s` from now (once the subscriptions are matched)."""
        self._started_s = time.monotonic()

    def elapsed_s(self) -> float:
        """Return the seconds recorded so far (until :meth:`close`)."""
        return (self._stopped_s or time.monotonic()) - self._started_s

    def set_custom_data(self, key: str, value: str) -> None:
        """Keep ``key: value`` in the bag's metadata.yaml (``custom_data``, as rosbag2 does)."""
        self._writer.set_custom_data(key, value)

    def add_topic(self, topic: str, type_name: str) -> None:
        """Subscribe to ``topic`` (a full name) of ``type_name`` (``pkg/msg/Name``)."""
        if topic in self._types:
            return
        if not is_recordable(type_name):
            raise RecordingError(f'{topic}: type {type_name} is not a ROS 2 Jazzy type that '
                                 'rosbags knows')
        message_type = _message_class(type_name)
        offers = [info.qos_profile for info in self._node.get_publishers_info_by_topic(topic)]
        self._types[topic] = type_name
        self.counts[topic] = 0
        self._subscriptions[topic] = self._node.create_subscription(
            message_type, topic, lambda data, t=topic: self._write(t, data),
            request_qos(offers), raw=True)

    def _connection(self, topic: str) -> Connection:
        """Return the bag connection of ``topic``, made with the offers the graph shows now."""
        connection = self._connections.get(topic)
        if connection is None:
            offers = [rosbags_qos(info.qos_profile)
                      for info in self._node.get_publishers_info_by_topic(topic)]
            connection = self._writer.add_connection(
                topic, self._types[topic], typestore=self._typestore,
                offered_qos_profiles=offers)
            self._connections[topic] = connection
        return connection

    def _write(self, topic: str, data: bytes) -> None:
        connection = self._connection(topic)  # at the first message: its publisher is known
        self._writer.write(connection, self._node.get_clock().now().nanoseconds, data)
        self.counts[topic] += 1

    def close(self) -> None:
        """Stop recording, list the topics without messages too, write metadata.yaml."""
        self._stopped_s = time.monotonic()
        for subscription in self._subscriptions.values():
            self._node.destroy_subscription(subscription)
        self._subscriptions.clear()
        for topic in self._types:
            self._connection(topic)
        self._writer.close()


def _message_class(type_name: str) -> type:
    """Import the Python class of ``pkg/msg/Name`` (rosidl_runtime_py is not on PyPI)."""
    package, _, name = type_name.split('/')
    try:
        return getattr(importlib.import_module(f'{package}.msg'), name)
    except (ImportError, AttributeError):
        raise RecordingError(f'type {type_name} is not installed here') from None


def count_summary(counts: Dict[str, int], duration_s: Optional[float] = None) -> str:
    """Return 'N messages on M topics' (and the duration) for a one-line report."""
    text = f'{sum(counts.values())} messages on {len(counts)} topics'
    return f'{text} in {duration_s:.1f} s' if duration_s is not None else text
