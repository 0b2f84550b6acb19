"""
The joint commands (commands thread): each velocity of a known joint becomes its reference.

rad/s -> % by ``velocity_scale``, through :meth:`BusMaster.set_speed_reference` with
``from_topic``, so the rules, the counters and the deadman are those of ``speed_reference``;
the bus writes the latest reference with its next poll, so commands cost no bus traffic of
their own. Unknown names, messages without velocities and messages whose velocities do not
match their names are counted and logged at most once a second per kind. A message that
names a joint twice contradicts itself: it is refused whole (counted as malformed), so that
neither of its velocities for that joint, nor any other of its velocities, is sent.
"""

from dataclasses import dataclass, field
import functools
import threading
from typing import Callable, Dict, Sequence, Set, Union

from drive_bridge.bus.master import BusMaster
from drive_bridge.errors import CommandRefused
from drive_bridge.ros.node.command_inputs import JOINT_COMMANDS_TOPIC as COMMANDS_TOPIC
from drive_bridge.ros.node.joints.model import Joint, JointTable
from drive_bridge.ros.node.joints.starter import AutoStarter
from drive_bridge.ros.node.joints.wire import JointCommand, MalformedCommand, read_joint_command
from drive_bridge.ros.node.throttle import Throttle
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

SHOWN_VELOCITIES = 4  # a joint named 10000 times is logged with its first 4 velocities


@dataclass
class CommandCounts:
    """
    What ``~/joint_commands`` received and ignored, for /diagnostics.

    The commands thread counts (:meth:`count`, :meth:`ignored`); /diagnostics reads a copy
    on the executor thread (:meth:`copy`). The lock keeps a copy whole: a message and the
    text of the last ignored one are never from two different moments.
    """

    counters: Dict[str, int] = field(default_factory=lambda: {
        'messages': 0, 'unknown_names': 0, 'without_velocity': 0, 'malformed': 0})
    last_ignored: str = ''
    last_ignored_s: float = -1e9
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def count(self, counter: str) -> None:
        """Count one message of kind ``counter``."""
        with self.lock:
            self.counters[counter] += 1

    def ignored(self, counter: str, text: str, now_s: float) -> None:
        """Count one ignored message of kind ``counter``, with why in words."""
        with self.lock:
            self.counters[counter] += 1
            self.last_ignored = text
            self.last_ignored_s = now_s

    def copy(self) -> 'CommandCounts':
        """Return a copy taken at one moment (any thread)."""
        with self.lock:
            return CommandCounts(dict(self.counters), self.last_ignored, self.last_ignored_s)


def first_repeated(names: Sequence[str]) -> str:
    """Return the first name that ``names`` holds more than once ('' if none)."""
    seen: Set[str] = set()
    for name in names:
        if name in seen:
            return name
        seen.add(name)
    return ''


def repeated_name_text(names: Sequence[str], velocities: Sequence[float]) -> str:
    """Return why a message that names a joint more than once is refused, in one line."""
    name = first_repeated(names)
    given = [velocity for other, velocity in zip(names, velocities) if other == name]
    shown = ', '.join(repr(velocity) for velocity in given[:SHOWN_VELOCITIES])
    more = ', ...' if len(given) > SHOWN_VELOCITIES else ''
    return (f'{COMMANDS_TOPIC}: joint {name!r} named {len(given)} times in one message '
            f'(velocities [{shown}{more}] rad/s): the message contradicts itself: ignored, '
            'nothing sent')


class JointCommands:
    """Takes the JointState commands; ``is_active`` tells whether the node takes commands."""

    def __init__(self, bus: BusMaster, table: JointTable, starter: AutoStarter, logger,
                 is_active: Callable[[], bool], clock: Callable[[], float]):
        self._bus = bus
        self._by_name = table.by_name
        self._starter = starter
        self._is_active = is_active
        self._clock = clock
        self._warn = Throttle(lambda text: logger.warning(text), clock)
        self._deserialize = functools.partial(deserialize_message, message_type=JointState)
        self.counts = CommandCounts()

    def on_serialized(self, data: bytes) -> None:
        """Take a serialized JointState command (:mod:`drive_bridge.ros.node.joints.wire`)."""
        try:
            command = read_joint_command(data, self._deserialize)
        except MalformedCommand as error:
            self.counts.count('messages')
            self._ignored('malformed', f'{COMMANDS_TOPIC}: not a JointState ({error}): '
                          'ignored, nothing sent')
            return
        self.on_commands(command)

    def on_commands(self, message: Union[JointState, JointCommand]) -> None:
        """Take a JointState command: velocities of known joints become speed references."""
        self.counts.count('messages')
        if not self._is_active():
            self._warn('inactive', f'{COMMANDS_TOPIC}: node is not active (lifecycle): '
                       'activate it first; nothing sent')
            self._refused_while_inactive(message.name)
            return
        if not len(message.velocity):
            self._ignored('without_velocity', f'{COMMANDS_TOPIC}: a message without '
                          f'velocities (names {list(message.name)}): ignored')
            return
        if len(message.velocity) != len(message.name):
            self._ignored('malformed', f'{COMMANDS_TOPIC}: {len(message.name)} names but '
                          f'{len(message.velocity)} velocities: ignored, nothing sent')
            return
        if len(message.name) > 1 and len(set(message.name)) < len(message.name):
            self._ignored('malformed', repeated_name_text(message.name, message.velocity),
                          kind='repeated names')
            return
        for name, velocity in zip(message.name, message.velocity):
            joint = self._by_name.get(name)
            if joint is None:
                self._ignored('unknown_names', f'{COMMANDS_TOPIC}: unknown joint {name!r} '
                              f'(joints: {", ".join(self._by_name)}): ignored')
                continue
            self._command(joint, velocity)

    def _refused_while_inactive(self, names) -> None:
        """Block the automatic starts of the joints named: their command came while inactive."""
        for name in names:
            joint = self._by_name.get(name)
            if joint is not None and joint.spec.command_mode == 'auto_start':
                self._starter.on_refused(joint, 'the node was not active')

    def _ignored(self, counter: str, text: str, kind: str = '') -> None:
        """Count an ignored message and log why (throttled per ``kind``, else ``counter``)."""
        self.counts.ignored(counter, text, self._clock())
        self._warn(kind or counter, text)

    def _command(self, joint: Joint, velocity: float) -> None:
        spec = joint.spec
        try:
            percent = velocity / spec.velocity_scale * 100.0
        except (OverflowError, ZeroDivisionError):
            percent = float('inf')
        try:
            word = self._bus.set_speed_reference(spec.device, percent, from_topic=True)
        except CommandRefused as error:
            self._warn(f'refused {spec.name}', f'{COMMANDS_TOPIC}: {spec.name} '
                       f'({spec.device}) velocity {velocity!r} rad/s: {error}')
            if spec.command_mode == 'auto_start':
                self._starter.on_refused(joint, str(error))
            return
        if spec.command_mode == 'auto_start':
            self._starter.on_command(joint, word != 0)
