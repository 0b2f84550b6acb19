"""
The joint commands (executor thread): each velocity of a known joint becomes its reference.

rad/s -> % by ``velocity_scale``, through :meth:`BusMaster.set_speed_reference` with
``from_topic``, so the rules, the counters and the deadman are those of ``speed_reference``;
the bus writes the latest reference with its next poll, so commands cost no bus traffic of
their own. Unknown names, messages without velocities and messages whose velocities do not
match their names are counted and logged at most once a second per kind.
"""

from dataclasses import dataclass, field
from typing import Callable, Dict

from drive_bridge.bus.master import BusMaster
from drive_bridge.errors import CommandRefused
from drive_bridge.ros.command_inputs import JOINT_COMMANDS_TOPIC as COMMANDS_TOPIC
from drive_bridge.ros.joints.model import Joint, JointTable
from drive_bridge.ros.joints.starter import AutoStarter
from sensor_msgs.msg import JointState

LOG_PERIOD_S = 1.0


class Throttle:
    """Log one line per kind at most once a period, saying how many were left out."""

    def __init__(self, log: Callable[[str], None], clock: Callable[[], float]):
        self._log = log
        self._clock = clock
        self._last: Dict[str, float] = {}
        self._left_out: Dict[str, int] = {}

    def __call__(self, kind: str, text: str) -> None:
        now = self._clock()
        if now - self._last.get(kind, -1e9) < LOG_PERIOD_S:
            self._left_out[kind] = self._left_out.get(kind, 0) + 1
            return
        self._last[kind] = now
        more = self._left_out.pop(kind, 0)
        self._log(text + (f' ({more} more like it in the last {LOG_PERIOD_S:g} s)'
                          if more else ''))


@dataclass
class CommandCounts:
    """What ``~/joint_commands`` received and ignored, for /diagnostics."""

    counters: Dict[str, int] = field(default_factory=lambda: {
        'messages': 0, 'unknown_names': 0, 'without_velocity': 0, 'malformed': 0})
    last_ignored: str = ''
    last_ignored_s: float = -1e9


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
        self.counts = CommandCounts()

    def on_commands(self, message: JointState) -> None:
        """Take a JointState command: velocities of known joints become speed references."""
        self.counts.counters['messages'] += 1
        if not self._is_active():
            self._warn('inactive', f'{COMMANDS_TOPIC}: node is not active (lifecycle): '
                       'activate it first; nothing sent')
            return
        if not len(message.velocity):
            self._ignored('without_velocity', f'{COMMANDS_TOPIC}: a message without '
                          f'velocities (names {list(message.name)}): ignored')
            return
        if len(message.velocity) != len(message.name):
            self._ignored('malformed', f'{COMMANDS_TOPIC}: {len(message.name)} names but '
                          f'{len(message.velocity)} velocities: ignored, nothing sent')
            return
        for name, velocity in zip(message.name, message.velocity):
            joint = self._by_name.get(name)
            if joint is None:
                self._ignored('unknown_names', f'{COMMANDS_TOPIC}: unknown joint {name!r} '
                              f'(joints: {", ".join(self._by_name)}): ignored')
                continue
            self._command(joint, velocity)

    def _ignored(self, counter: str, text: str) -> None:
        self.counts.counters[counter] += 1
        self.counts.last_ignored = text
        self.counts.last_ignored_s = self._clock()
        self._warn(counter, text)

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
            return
        if spec.command_mode == 'auto_start':
            self._starter.on_command(joint, word != 0)
