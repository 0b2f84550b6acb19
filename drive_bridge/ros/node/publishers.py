"""
The topics of one device: lifecycle publishers for the reading fields the device has.

Every device publishes ``state`` and ``trip`` (latched: transient local, depth 1, sent on
change), ``status_word`` and ``trip_code``; the optional fields only where the family and
model report them (``motor_current``, ``motor_temperature``, ``speed_feedback``,
``alarm_word``, ``warning_word``). The volatile topics go out with each reading where a
subscription is matched to them, and are skipped where none is. Publishers carry no
default QoS event handlers: nothing listens to them, and each one would be a waitable the
executor rebuilds its wait set with. Publishing is thread-safe: the bus thread publishes
each reading, while its next request is on the wire (:mod:`drive_bridge.bus.master`).
"""

import threading
from typing import Any, Dict, FrozenSet, Optional, Union

from drive_bridge.devices.contracts import DeviceReading
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.lifecycle import LifecycleNode
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float32, String, UInt16, UInt32

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
READINGS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)
# reading field -> (topic, message type, attribute of DeviceReading, conversion)
OPTIONAL_TOPICS = {
    'motor_current': ('motor_current', Float32, 'motor_current_a', float),
    'motor_temperature': ('motor_temperature', Float32, 'motor_temperature_pct', float),
    'speed_feedback': ('speed_feedback', Float32, 'speed_feedback_pct', float),
    'alarm_word': ('alarm_word', UInt32, 'alarm_word', int),
    'warning_word': ('warning_word', UInt32, 'warning_word', int),
}


def listened(publisher: Publisher) -> bool:
    """Return whether a subscription is matched to ``publisher`` now."""
    return publisher.get_subscription_count() > 0


class DevicePublishers:
    """The publishers of one device and what its latched topics carry."""

    def __init__(self, node: LifecycleNode, name: str, fields: FrozenSet[str]):
        self._node = node
        self._lock = threading.Lock()

        def publisher(kind: Any, topic: str, qos: QoSProfile):
            return node.create_lifecycle_publisher(kind, f'{name}/{topic}', qos,
                                                   event_callbacks=NO_EVENTS)
        self.state = publisher(String, 'state', LATCHED)
        self.trip = publisher(String, 'trip', LATCHED)
        self.status_word = publisher(UInt16, 'status_word', READINGS)
        self.trip_code = publisher(UInt16, 'trip_code', READINGS)
        self.optional: Dict[str, tuple] = {
            field: (publisher(kind, topic, READINGS), attribute, convert)
            for field, (topic, kind, attribute, convert) in OPTIONAL_TOPICS.items()
            if field in fields}
        self._last_state: Optional[str] = None
        self._last_trip: Optional[str] = None
        # What the bus told last: a reading, or a state without one (unknown, offline).
        self._latest: Union[DeviceReading, str] = 'unknown'

    @property
    def every(self) -> list:
        """Return every publisher."""
        return [self.state, self.trip, self.status_word, self.trip_code] + \
            [entry[0] for entry in self.optional.values()]

    def republish(self) -> None:
        """
        Publish again what the bus told last, latched topics included (activation).

        The last thing told, not a fresh snapshot of the bus: events still on their way are
        newer than it, so nothing older can follow what this publishes.
        """
        with self._lock:
            self._last_state = self._last_trip = None
            latest = self._latest
        if isinstance(latest, DeviceReading):
            self.publish_reading(latest)
        else:
            self.publish_state(latest)

    def withdraw(self) -> None:
        """Leave ``unknown`` on the latched state: nothing is told while the node is inactive."""
        self._publish_state('unknown')

    def publish_state(self, state: str) -> None:
        """Publish a state without a reading (unknown, offline) if it changed."""
        with self._lock:
            self._latest = state
        self._publish_state(state)

    def _publish_state(self, state: str) -> None:
        with self._lock:
            if state != self._last_state:
                self._last_state = state
                self.state.publish(String(data=state))

    def publish_reading(self, reading: DeviceReading) -> None:
        """
        Publish every field of a fresh reading (latched topics on change).

        A volatile topic that no subscription is matched to is skipped: it would deliver to
        nobody (a later subscriber gets no history of a volatile topic), and building and
        serializing its message is most of what a reading costs the node.
        """
        with self._lock:
            self._latest = reading
        if listened(self.status_word):
            self.status_word.publish(UInt16(data=int(reading.status_word)))
        if listened(self.trip_code):
            self.trip_code.publish(UInt16(data=int(reading.trip_code)))
        for publisher, attribute, convert in self.optional.values():
            value = getattr(reading, attribute)
            if value is not None and listened(publisher):
                publisher.publish(publisher.msg_type(data=convert(value)))
        with self._lock:
            if reading.trip_name != self._last_trip:
                self._last_trip = reading.trip_name
                self.trip.publish(String(data=reading.trip_name))
        self._publish_state(reading.state)

    def destroy(self) -> None:
        """Destroy every publisher."""
        for publisher in self.every:
            self._node.destroy_lifecycle_publisher(publisher)
