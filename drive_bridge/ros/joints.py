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

Commands (executor thread): each velocity of a known joint becomes the speed reference
(rad/s -> % by ``velocity_scale``) through :meth:`BusMaster.set_speed_reference` with
``from_topic``, so the rules, the counters and the deadman are those of ``speed_reference``;
the bus writes the latest reference with its next poll, so commands cost no bus traffic of
their own. Unknown names, messages without velocities and messages whose velocities do not
match their names are counted and logged at most once a second per kind.

``command_mode: auto_start`` (:class:`AutoStart`): a nonzero command starts a stopped,
untripped drive; a zero command held ``auto_stop_delay`` seconds ramp-stops it. Never two
automatic starts (or stops) in flight for one drive; a failed automatic start, a trip, a
stop the node did not make itself (a stop service, the deadman, deactivate) or a switch to
auto_start keeps automatic starts off until the command goes to zero (and back). A trip is
never reset automatically.

Locking: the bus calls the listener from its own thread, without its lock (while a request is
on the wire), and this module never calls the bus while holding its own lock.
"""

from dataclasses import dataclass, field
import threading
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from drive_bridge import config as cfg
from drive_bridge.bus.events import (
    BusEvent, DeviceOffline, DeviceOnline, handler_table, ignore, Notice, ReadingEvent,
    StateUnknown)
from drive_bridge.bus.master import BusMaster, DeviceSnapshot
from drive_bridge.errors import CommandRefused, ConfigError
from drive_bridge.protocol.commands import Command
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

STATES_TOPIC = '~/joint_states'
COMMANDS_TOPIC = '~/joint_commands'
# States: reliable, so ros2 topic echo and bag recorders get every one; a best-effort
# subscriber (JointStateTopicSystem's SensorDataQoS) matches it too.
STATES_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# Commands: reliable, as JointStateTopicSystem and ros2 topic pub publish them.
COMMANDS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
LOG_PERIOD_S = 1.0
_SWITCHED = 'command_mode switched to auto_start'
RECENT_S = 10.0  # /diagnostics warns while a command was ignored this recently
BATCH_STATES = False  # True: one message per round of every joint (bench/joint_cpu.py)


@dataclass
class JointSpec:
    """One joint as configured: its drive, name, scale and command mode."""

    device: str
    name: str
    velocity_scale: float  # rad/s of the joint at 100 % reference
    command_mode: str = 'reference'
    auto_stop_delay_s: float = 1.0


def joint_specs(devices: Sequence[cfg.DeviceConfig]) -> List[JointSpec]:
    """Return the joints among ``devices``: the drives with a velocity_scale."""
    return [JointSpec(device.name, cfg.joint_name_of(device), device.option('velocity_scale'),
                      device.option('command_mode', 'reference'),
                      device.option('auto_stop_delay', 1.0))
            for device in devices if device.is_drive and device.option('velocity_scale')]


class Integrator:
    """Position from velocity samples: a trapezoid between two consecutive readings."""

    def __init__(self):
        self.position_rad = 0.0
        self._last: Optional[Tuple[float, float]] = None  # (stamp_s, velocity)

    def add(self, stamp_s: float, velocity: float) -> float:
        """Take a sample; return the position at its time."""
        if self._last is not None and stamp_s > self._last[0]:
            last_stamp_s, last_velocity = self._last
            self.position_rad += 0.5 * (last_velocity + velocity) * (stamp_s - last_stamp_s)
        self._last = (stamp_s, velocity)
        return self.position_rad

    def interrupt(self) -> None:
        """Forget the last sample (an outage): the next one adds no area."""
        self._last = None


@dataclass
class DriveFacts:
    """What an automatic start or stop decision needs to know about the drive now."""

    holds_run: bool
    online: bool
    tripped: bool
    allow_control: bool

    @classmethod
    def of(cls, snapshot: DeviceSnapshot) -> 'DriveFacts':
        """Return the facts of a bus snapshot."""
        reading = snapshot.reading
        return cls(snapshot.holds_run, snapshot.online is True,
                   reading is not None and reading.tripped, snapshot.allow_control)


@dataclass
class AutoStart:
    """
    ``command_mode: auto_start`` of one drive: the decisions, no I/O (see the module doc).

    :meth:`command` and :meth:`reading` return the command to submit (START or STOP) or
    None; :meth:`start_done` and :meth:`stop_done` take the outcome of one submitted.
    """

    delay_s: float
    starting: bool = False  # an automatic start is in flight
    stopping: bool = False  # an automatic stop is in flight
    blocked: str = ''  # why automatic starts wait for the command to go to zero and back
    zero_since_s: Optional[float] = None
    holding: bool = False  # the bridge held a run command when last seen
    expect_stop: bool = False  # our automatic stop, not someone else's, ends the run
    starts: int = 0
    stops: int = 0
    failed_starts: int = 0
    log: List[str] = field(default_factory=list)  # what happened, for the caller to log

    def command(self, nonzero: bool, now_s: float, drive: DriveFacts) -> Optional[Command]:
        """Take one accepted command, zero or not, at ``now_s``."""
        self._observe(drive)
        if not nonzero:
            if self.blocked:
                self.log.append('zero command: automatic starts are armed again')
            self.blocked = ''
            if self.zero_since_s is None:
                self.zero_since_s = now_s
            return self._stop_if_due(now_s, drive)
        self.zero_since_s = None
        if self.blocked or self.starting or drive.holds_run or drive.tripped or \
                not drive.online or not drive.allow_control:
            return None
        self.starting = True
        self.starts += 1
        return Command.START

    def reading(self, now_s: float, drive: DriveFacts) -> Optional[Command]:
        """Take a fresh reading of the drive; a zero held long enough stops it."""
        self._observe(drive)
        return self._stop_if_due(now_s, drive)

    def start_done(self, error: Optional[BaseException]) -> None:
        """Take the outcome of an automatic start (None: acknowledged)."""
        self.starting = False
        if error is not None:
            self.failed_starts += 1
            self._block(f'automatic start failed ({error})')

    def stop_done(self, error: Optional[BaseException]) -> None:
        """Take the outcome of an automatic stop (None: acknowledged)."""
        self.stopping = False
        if error is not None:
            self.expect_stop = False

    def reset(self, delay_s: float, holding: bool, blocked: str = '') -> None:
        """Start afresh: a change of command_mode (``holding``: the bridge holds a run now)."""
        self.delay_s = delay_s
        self.zero_since_s = None
        self.holding = holding
        self.expect_stop = False
        self.blocked = blocked

    def _observe(self, drive: DriveFacts) -> None:
        if drive.tripped:
            self._block('the drive tripped')
        elif self.holding and not drive.holds_run and not self.expect_stop:
            self._block('stopped by something else than an automatic stop (a stop service, '
                        'the deadman, deactivate)')
        if not drive.holds_run:
            self.expect_stop = False
        self.holding = drive.holds_run

    def _block(self, reason: str) -> None:
        if not self.blocked:
            self.log.append(f'{reason}: automatic starts wait until the command goes to zero '
                            'and back')
        self.blocked = reason

    def _stop_if_due(self, now_s: float, drive: DriveFacts) -> Optional[Command]:
        if self.zero_since_s is None or self.stopping or self.starting or \
                not drive.holds_run or now_s - self.zero_since_s < self.delay_s:
            return None
        self.stopping = True
        self.expect_stop = True
        self.stops += 1
        return Command.STOP


class _Throttle:
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


class _Joint:
    """The run-time record of one joint."""

    def __init__(self, spec: JointSpec):
        self.spec = spec
        self.integrator = Integrator()
        self.auto = AutoStart(spec.auto_stop_delay_s)
        self.velocity = 0.0
        self.published = 0


class JointBridge:
    """
    The joints of one node (see the module docstring).

    ``publish`` sends a JointState; ``is_active`` tells whether the node takes commands;
    ``stamp_offset_ns`` moves the bus clock (seconds) onto the node's clock (nanoseconds).
    """

    def __init__(self, bus: BusMaster, specs: Sequence[JointSpec],
                 publish: Callable[[JointState], None], logger,
                 is_active: Callable[[], bool], stamp_offset_ns: int,
                 clock: Callable[[], float] = time.monotonic, batch: bool = False):
        self.bus = bus
        self.joints: Dict[str, _Joint] = {spec.device: _Joint(spec) for spec in specs}
        self.by_name: Dict[str, _Joint] = {joint.spec.name: joint
                                           for joint in self.joints.values()}
        self._publish = publish
        self._logger = logger
        self._is_active = is_active
        self.stamp_offset_ns = stamp_offset_ns
        self._clock = clock
        self._batch: Optional[Dict[str, tuple]] = {} if batch else None
        self._lock = threading.Lock()
        self._warn = _Throttle(lambda text: logger.warning(text), clock)
        self.counters = {'messages': 0, 'unknown_names': 0, 'without_velocity': 0,
                         'malformed': 0}
        self.last_ignored = ''
        self.last_ignored_s = -1e9
        self.event_handlers = handler_table({
            ReadingEvent: self._on_reading, DeviceOffline: self._interrupt,
            StateUnknown: self._interrupt, DeviceOnline: ignore, Notice: ignore})

    # -- states (bus thread) ------------------------------------------------------------
    def on_bus_event(self, event: BusEvent) -> None:
        """Publish the joint state of a reading; an outage interrupts the integration."""
        joint = self.joints.get(event.device)
        if joint is not None:
            self.event_handlers[type(event)](joint, event)

    def _interrupt(self, joint: _Joint, event: BusEvent) -> None:
        with self._lock:
            joint.integrator.interrupt()

    def _on_reading(self, joint: _Joint, event: ReadingEvent) -> None:
        reading = event.reading
        if reading.speed_feedback_pct is None:
            return
        velocity = reading.speed_feedback_pct * joint.spec.velocity_scale / 100.0
        with self._lock:
            position = joint.integrator.add(event.stamp_s, velocity)
            joint.velocity = velocity
        if joint.spec.command_mode == 'auto_start' and self._is_active():
            self._auto_reading(joint)
        if reading.tripped:
            return  # never published while tripped (the integration goes on)
        stamp_ns = int(round(event.stamp_s * 1e9)) + self.stamp_offset_ns
        if self._batch is None:
            self._send([(joint.spec.name, position, velocity)], stamp_ns)
            joint.published += 1
        else:
            self._add_to_batch(joint, stamp_ns, position, velocity)

    def _add_to_batch(self, joint: _Joint, stamp_ns: int, position: float,
                      velocity: float) -> None:
        batch = self._batch
        if joint.spec.name in batch:
            self._flush()
        batch[joint.spec.name] = (stamp_ns, position, velocity)
        joint.published += 1
        if len(batch) == len(self.joints):
            self._flush()

    def _flush(self) -> None:
        entries, self._batch = self._batch, {}
        if entries:
            self._send([(name, position, velocity)
                        for name, (_, position, velocity) in entries.items()],
                       max(stamp for stamp, _, _ in entries.values()))

    def _send(self, entries: List[tuple], stamp_ns: int) -> None:
        message = JointState()
        message.header.stamp = Time(sec=stamp_ns // 1_000_000_000,
                                    nanosec=stamp_ns % 1_000_000_000)
        message.name = [entry[0] for entry in entries]
        message.position = [float(entry[1]) for entry in entries]
        message.velocity = [float(entry[2]) for entry in entries]
        self._publish(message)

    # -- commands (executor thread) -----------------------------------------------------
    def on_commands(self, message: JointState) -> None:
        """Take a JointState command: velocities of known joints become speed references."""
        self.counters['messages'] += 1
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
            joint = self.by_name.get(name)
            if joint is None:
                self._ignored('unknown_names', f'{COMMANDS_TOPIC}: unknown joint {name!r} '
                              f'(joints: {", ".join(self.by_name)}): ignored')
                continue
            self._command(joint, velocity)

    def _ignored(self, counter: str, text: str) -> None:
        self.counters[counter] += 1
        self.last_ignored = text
        self.last_ignored_s = self._clock()
        self._warn(counter, text)

    def _command(self, joint: _Joint, velocity: float) -> None:
        spec = joint.spec
        try:
            percent = velocity / spec.velocity_scale * 100.0
        except (OverflowError, ZeroDivisionError):
            percent = float('inf')
        try:
            word = self.bus.set_speed_reference(spec.device, percent, from_topic=True)
        except CommandRefused as error:
            self._warn(f'refused {spec.name}', f'{COMMANDS_TOPIC}: {spec.name} '
                       f'({spec.device}) velocity {velocity!r} rad/s: {error}')
            return
        if spec.command_mode == 'auto_start':
            self._auto_command(joint, word != 0)

    # -- auto_start ---------------------------------------------------------------------
    def _auto_command(self, joint: _Joint, nonzero: bool) -> None:
        facts = DriveFacts.of(self.bus.snapshot(joint.spec.device))
        with self._lock:
            decision = joint.auto.command(nonzero, self._clock(), facts)
            notes, joint.auto.log = joint.auto.log, []
        self._carry_out(joint, decision, notes)

    def _auto_reading(self, joint: _Joint) -> None:
        facts = DriveFacts.of(self.bus.snapshot(joint.spec.device))
        with self._lock:
            decision = joint.auto.reading(self._clock(), facts)
            notes, joint.auto.log = joint.auto.log, []
        self._carry_out(joint, decision, notes)

    def _carry_out(self, joint: _Joint, decision: Optional[Command], notes: List[str]) -> None:
        spec = joint.spec
        for note in notes:
            self._logger.warning(f'{spec.device} (joint {spec.name}): {note}')
        if decision is None:
            return
        if decision is Command.START:
            self._logger.info(f'{spec.device} (joint {spec.name}): automatic start (nonzero '
                              'joint command)')
        else:
            self._logger.info(f'{spec.device} (joint {spec.name}): automatic ramp stop (zero '
                              f'joint command held {spec.auto_stop_delay_s:g} s)')
        future = self.bus.submit_command(spec.device, decision)
        future.add_done_callback(lambda done: self._auto_done(joint, decision, done))

    def _auto_done(self, joint: _Joint, command: Command, future) -> None:
        error = future.exception() if not future.cancelled() else CommandRefused('cancelled')
        with self._lock:
            if command is Command.START:
                joint.auto.start_done(error)
            else:
                joint.auto.stop_done(error)
            notes, joint.auto.log = joint.auto.log, []
        spec = joint.spec
        if error is None:
            self._logger.info(f'{spec.device} (joint {spec.name}): automatic {command.value} '
                              'acknowledged')
        else:
            self._logger.error(f'{spec.device} (joint {spec.name}): automatic '
                               f'{command.value} failed: {error}')
        for note in notes:
            self._logger.warning(f'{spec.device} (joint {spec.name}): {note}')

    # -- settings and diagnostics (executor thread) --------------------------------------
    def check_settings(self, changes: Dict[str, Dict]) -> None:
        """Raise ConfigError for a runtime change the joints cannot take (nothing applied)."""
        for device, settings in changes.items():
            mode = settings.get('command_mode')
            if mode is None:
                continue
            if device not in self.joints:
                if mode != 'reference':
                    raise ConfigError(f'parameter {device + ".command_mode"!r} = {mode!r} '
                                      f'applies to joints only: {device} has no '
                                      'velocity_scale')
                continue
            allow = settings.get('allow_control', self.bus.snapshot(device).allow_control)
            if mode == 'auto_start' and not allow:
                raise ConfigError(f'parameter {device + ".command_mode"!r} = \'auto_start\' '
                                  'is refused: a monitor-only drive (allow_control false) is '
                                  'never started')

    def apply_settings(self, changes: Dict[str, Dict]) -> None:
        """
        Take runtime changes of command_mode and auto_stop_delay.

        A switch to auto_start waits for a zero command before the first automatic start,
        so switching the mode never starts a motor by itself.
        """
        for device, settings in changes.items():
            joint = self.joints.get(device)
            if joint is None or not ({'command_mode', 'auto_stop_delay'} & set(settings)):
                continue
            spec = joint.spec
            holding = self.bus.snapshot(device).holds_run
            before = (spec.command_mode, spec.auto_stop_delay_s)
            with self._lock:
                spec.command_mode = settings.get('command_mode', spec.command_mode)
                spec.auto_stop_delay_s = settings.get('auto_stop_delay', spec.auto_stop_delay_s)
                joint.auto.delay_s = spec.auto_stop_delay_s
                if spec.command_mode != before[0]:
                    joint.auto.reset(spec.auto_stop_delay_s, holding, _SWITCHED
                                     if spec.command_mode == 'auto_start' else '')
            if (spec.command_mode, spec.auto_stop_delay_s) != before:
                waits = '; automatic starts wait for a zero command first' \
                    if spec.command_mode != before[0] == 'reference' else ''
                self._logger.info(f'{device} (joint {spec.name}): command_mode '
                                  f'{spec.command_mode}, auto_stop_delay '
                                  f'{spec.auto_stop_delay_s:g} s{waits}')

    def device_values(self, device: str) -> List[KeyValue]:
        """Return the joint values of one device for its /diagnostics status."""
        joint = self.joints.get(device)
        if joint is None:
            return []
        spec, auto = joint.spec, joint.auto
        with self._lock:
            values = {
                'joint_name': spec.name, 'velocity_scale_rad_s': f'{spec.velocity_scale:g}',
                'joint_velocity_rad_s': f'{joint.velocity:.4f}',
                'joint_position_rad': f'{joint.integrator.position_rad:.4f}',
                'joint_states_published': str(joint.published),
                'command_mode': spec.command_mode}
            if spec.command_mode == 'auto_start' or auto.starts or auto.stops:
                values.update({
                    'auto_stop_delay_s': f'{spec.auto_stop_delay_s:g}',
                    'auto_starts': str(auto.starts), 'auto_stops': str(auto.stops),
                    'auto_start_failures': str(auto.failed_starts),
                    'auto_start': f'waits for a zero command: {auto.blocked}'
                    if auto.blocked else 'armed'})
        return [KeyValue(key=key, value=value) for key, value in values.items()]

    def commands_status(self, name: str) -> DiagnosticStatus:
        """Return the status of ``~/joint_commands`` (``name`` from status_name)."""
        counters = self.counters
        status = DiagnosticStatus(name=name, hardware_id='ros2_control joint commands')
        recent = self._clock() - self.last_ignored_s < RECENT_S
        status.level = DiagnosticStatus.WARN if recent else DiagnosticStatus.OK
        status.message = self.last_ignored if recent else \
            f'{len(self.joints)} joints: {", ".join(self.by_name)}'
        values = {'joints': ', '.join(f'{joint.spec.name} ({device})'
                                      for device, joint in self.joints.items()),
                  'messages': counters['messages'],
                  'unknown_joint_names': counters['unknown_names'],
                  'messages_without_velocity': counters['without_velocity'],
                  'messages_malformed': counters['malformed'],
                  'last_ignored': self.last_ignored}
        status.values = [KeyValue(key=key, value=str(value)) for key, value in values.items()]
        return status


def stamp_offset_ns(node, bus_clock: Callable[[], float]) -> int:
    """Return the node clock minus the bus clock, in nanoseconds, measured now."""
    return node.get_clock().now().nanoseconds - int(round(bus_clock() * 1e9))


class JointInterface:
    """The ROS side of the joints: the publisher, the subscription and the bridge."""

    def __init__(self, node, bus: BusMaster, specs: Sequence[JointSpec],
                 is_active: Callable[[], bool]):
        self._node = node
        self.publisher = node.create_lifecycle_publisher(JointState, STATES_TOPIC, STATES_QOS)
        self.bridge = JointBridge(bus, specs, self.publisher.publish, node.get_logger(),
                                  is_active, stamp_offset_ns(node, bus.clock),
                                  batch=BATCH_STATES)
        self.subscription = node.create_subscription(
            JointState, COMMANDS_TOPIC, self.bridge.on_commands, COMMANDS_QOS)

    def destroy(self) -> None:
        """Destroy the publisher and the subscription."""
        self._node.destroy_subscription(self.subscription)
        self._node.destroy_lifecycle_publisher(self.publisher)


def attach(node, bus: BusMaster, devices: Sequence[cfg.DeviceConfig],
           is_active: Callable[[], bool]) -> Optional[JointInterface]:
    """Create the joint topics of ``node`` if any device is a joint; else return None."""
    specs = joint_specs(devices)
    if not specs:
        return None
    node.get_logger().info('joints on ~/joint_states and ~/joint_commands: ' + ', '.join(
        f'{spec.name} ({spec.device}, {spec.velocity_scale:g} rad/s at 100 %, '
        f'{spec.command_mode})' for spec in specs))
    return JointInterface(node, bus, specs, is_active)
