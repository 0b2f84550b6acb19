"""
Record topics into an MCAP file laid out as Jazzy's ``ros2 bag record`` writes it.

Profile ``ros2``, schema encoding ``ros2msg`` (the ``.msg`` text with the dependent types
appended after ``====`` separator lines, as rosbag2 does), message encoding ``cdr`` (the
serialized bytes exactly as received, subscribed with ``raw=True``), one channel per topic.
For machines without rosbag2 (ROS from PyPI); ``ros2 bag record`` writes the same layout.
"""

import os
import re
import time
from typing import Dict, List, Optional, Set

from ament_index_python.packages import get_package_share_directory
from mcap.writer import Writer
from rclpy.node import Node
from rclpy.qos import QoSProfile

SEPARATOR = '=' * 80
PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
              'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'}


def type_name(message_type) -> str:
    """Return ``pkg/msg/Name`` of a message class."""
    package = message_type.__module__.split('.')[0]
    return f'{package}/msg/{message_type.__name__}'


def _msg_text(package: str, name: str) -> str:
    path = os.path.join(get_package_share_directory(package), 'msg', f'{name}.msg')
    with open(path) as stream:
        return stream.read()


def _field_types(text: str, package: str) -> List[str]:
    """Return the non-primitive field types of a .msg text as ``pkg/Name``."""
    types = []
    for line in text.splitlines():
        tokens = line.split('#', 1)[0].split()
        if len(tokens) < 2:
            continue
        base = re.sub(r'\[[^\]]*\]$', '', tokens[0])  # arrays: T[], T[3], T[<=3]
        base = re.sub(r'<=\d+$', '', base)  # bounded strings
        if base in PRIMITIVES:  # constants are always primitive
            continue
        if '/' not in base:
            base = 'std_msgs/Header' if base == 'Header' else f'{package}/{base}'
        types.append(base)
    return types


def message_definition(message_type) -> str:
    """Return the ros2msg schema text of a message class, dependencies appended."""
    package, _, name = type_name(message_type).split('/')
    text = _msg_text(package, name)
    seen: Set[str] = set()
    parts = [text.rstrip('\n')]
    pending = _field_types(text, package)
    while pending:
        dependency = pending.pop(0)
        if dependency in seen:
            continue
        seen.add(dependency)
        dep_package, dep_name = dependency.split('/')
        dep_text = _msg_text(dep_package, dep_name)
        parts.append(f'{SEPARATOR}\nMSG: {dependency}\n{dep_text.rstrip()}')
        pending += _field_types(dep_text, dep_package)
    return '\n'.join(parts) + '\n'


class McapRecorder:
    """Subscribe to topics and write every message to an MCAP file until :meth:`close`."""

    def __init__(self, node: Node, path: str, topics: Dict[str, type],
                 qos: Optional[Dict[str, QoSProfile]] = None):
        self._stream = open(path, 'wb')
        self._writer = Writer(self._stream)
        self._writer.start(profile='ros2', library='drive_bridge recorder')
        self._sequence = 0
        self.counts: Dict[str, int] = {}
        self._subscriptions = []
        schemas: Dict[str, int] = {}
        for topic, message_type in topics.items():
            name = type_name(message_type)
            if name not in schemas:
                schemas[name] = self._writer.register_schema(
                    name=name, encoding='ros2msg',
                    data=message_definition(message_type).encode())
            channel = self._writer.register_channel(
                topic=topic, message_encoding='cdr', schema_id=schemas[name])
            self.counts[topic] = 0
            profile = (qos or {}).get(topic, QoSProfile(depth=100))
            self._subscriptions.append(node.create_subscription(
                message_type, topic,
                lambda data, c=channel, t=topic: self._write(c, t, data), profile, raw=True))
        self._node = node

    def _write(self, channel: int, topic: str, data: bytes) -> None:
        now_ns = time.time_ns()
        self._sequence += 1
        self.counts[topic] += 1
        self._writer.add_message(channel_id=channel, log_time=now_ns, data=data,
                                 publish_time=now_ns, sequence=self._sequence)

    def close(self) -> None:
        """Stop recording and finish the file."""
        for subscription in self._subscriptions:
            self._node.destroy_subscription(subscription)
        self._subscriptions.clear()
        self._writer.finish()
        self._stream.close()
