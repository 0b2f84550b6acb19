"""
The ROS 2 node ``drive_bridge``: one bus, several devices, the contract's topics and services.

A managed (lifecycle) node: *configure* validates the parameters, opens the bus and starts
reading (``/diagnostics`` is published from then on); *activate* enables the device topics,
the command services and the speed references; *deactivate* stops the motors this node
started and refuses commands again; *cleanup* closes the port. With ``autostart`` (default)
the node walks itself to active, so ``drive_bridge_node`` just works.

Bus I/O never runs in a ROS callback: the bus thread reports readings through a queue and
a guard condition (published by the executor), and service callbacks only queue a command
and wait for its outcome on a future, in their own callback group.
"""

import queue
import sys
from typing import Any, Callable, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from drive_bridge import config as cfg
from drive_bridge.bus.master import BusEvent, BusMaster, DeviceSnapshot
from drive_bridge.errors import CommandRefused, ConfigError, DriveBridgeError
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float32, String, UInt16, UInt32
from std_srvs.srv import Trigger

NODE_NAME = 'drive_bridge'
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
SERVICE_COMMANDS = ('start', 'stop', 'quick_stop', 'reset')
DRIVE_SERVICE_COMMANDS = SERVICE_COMMANDS + ('coast_stop',)
SHUTDOWN_STOP_TIMEOUT_S = 3.0


def _descriptor(setting: cfg.Setting, label: str) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(
        name=label, description=f'{setting.description}; allowed {setting.allowed()}',
        read_only=not setting.runtime, dynamic_typing=True)
    if setting.low is not None and setting.kind is float:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(setting.low), to_value=float(setting.high), step=0.0)]
    elif setting.low is not None and setting.kind is int:
        descriptor.integer_range = [IntegerRange(
            from_value=int(setting.low), to_value=int(setting.high), step=1)]
    return descriptor


class _DevicePublishers:
    """The publishers of one device and what was last published on latched topics."""

    def __init__(self, node: LifecycleNode, name: str, is_drive: bool):
        publisher = node.create_lifecycle_publisher  # silent unless the node is active
        self.all = []
        self.state = publisher(String, f'{name}/state', LATCHED)
        self.trip = publisher(String, f'{name}/trip', LATCHED)
        self.status_word = publisher(UInt16, f'{name}/status_word', 10)
        self.motor_current = publisher(Float32, f'{name}/motor_current', 10)
        self.trip_code = publisher(UInt16, f'{name}/trip_code', 10)
        self.motor_temperature = publisher(Float32, f'{name}/motor_temperature', 10)
        self.all = [self.state, self.trip, self.status_word, self.motor_current,
                    self.trip_code, self.motor_temperature]
        self.speed_feedback = self.alarm_word = self.warning_word = None
        if is_drive:
            self.speed_feedback = publisher(Float32, f'{name}/speed_feedback', 10)
            self.alarm_word = publisher(UInt32, f'{name}/alarm_word', 10)
            self.warning_word = publisher(UInt32, f'{name}/warning_word', 10)
            self.all += [self.speed_feedback, self.alarm_word, self.warning_word]
        self.last_state: Optional[str] = None
        self.last_trip: Optional[str] = None

    def forget_latched(self) -> None:
        """Forget what the latched topics carry, so the next values go out (activation)."""
        self.last_state = self.last_trip = None

    def publish_state(self, state: str) -> None:
        if state != self.last_state:
            self.last_state = state
            self.state.publish(String(data=state))

    def publish_trip(self, trip: str) -> None:
        if trip != self.last_trip:
            self.last_trip = trip
            self.trip.publish(String(data=trip))


class DriveBridgeNode(LifecycleNode):
    """One bus owner; see the module docstring and docs in README.md."""

    def __init__(self, **kwargs: Any):
        super().__init__(NODE_NAME, **kwargs)
        self._guard_change_state()
        self.autostart = bool(self.declare_parameter(
            'autostart', True, ParameterDescriptor(
                name='autostart', read_only=True,
                description='walk the lifecycle to active at start (false: wait for '
                            'configure and activate)')).value)
        self.config: Optional[cfg.BridgeConfig] = None
        self.config_error = ''
        self._autostarting = False
        self.bus: Optional[BusMaster] = None
        self.active = False
        self._events: 'queue.SimpleQueue[BusEvent]' = queue.SimpleQueue()
        self._device_publishers: Dict[str, _DevicePublishers] = {}
        self._entities: List[Tuple[Callable[[Any], bool], Any]] = []  # (destroy, entity)
        self._service_group = ReentrantCallbackGroup()
        self._timer_group = MutuallyExclusiveCallbackGroup()
        self._guard = self.create_guard_condition(self._publish_events)
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.add_on_set_parameters_callback(self._on_set_parameters)

    # -- lifecycle ----------------------------------------------------------------------
    def _guard_change_state(self) -> None:
        """
        Refuse a ChangeState request by an id that is not valid now (ros2/rclpy#1209).

        rclpy 7.1.6 raises inside spin for such a request, which kills the node; a request
        by label is checked by rclpy itself.
        """
        service = getattr(self, '_service_change_state', None)
        if service is None:
            return
        original = service.callback

        def guarded(request, response):
            if not request.transition.label:
                valid = [transition[0] for transition in
                         self._state_machine.available_transitions]
                if request.transition.id not in valid:
                    self.get_logger().warning(
                        f'lifecycle transition id {request.transition.id} is not valid in '
                        f'state {self._state_machine.current_state[1]}: refused')
                    response.success = False
                    return response
            return original(request, response)
        service.callback = guarded

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Validate the parameters, open the bus and start reading."""
        try:
            self.config = self._load_config()
        except ConfigError as error:
            self.config_error = str(error)
            if not self._autostarting:  # autostart prints it as the node's one last line
                self.get_logger().error(f'configuration error: {error}')
            return TransitionCallbackReturn.FAILURE
        self.config_error = ''
        specs = [device.make_spec() for device in self.config.devices]
        self.bus = BusMaster(self.config.make_transport(), specs, self.config.timing,
                             listener=self._on_bus_event)
        for device in self.config.devices:
            self._create_device_interface(device.name, device.is_drive)
        self._entities.append((self.destroy_timer, self.create_timer(
            self.config.diagnostics_period_s, self._publish_diagnostics,
            callback_group=self._timer_group)))
        self.bus.start()
        self.get_logger().info(
            f'bus {self.config.link.describe()}: '
            + ', '.join(f'{d.name} ({d.family} {d.model} @ {d.address})'
                        for d in self.config.devices))
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the device topics, the command services and the speed references."""
        result = super().on_activate(state)
        self.active = True
        for name, publishers in self._device_publishers.items():
            publishers.forget_latched()
            snapshot = self.bus.snapshot(name)
            if snapshot.reading is not None:
                self._publish_reading(publishers, snapshot.reading)
            else:
                publishers.publish_state('offline' if snapshot.online is False else 'unknown')
        self.get_logger().info('active: commands enabled')
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Refuse commands again and stop the motors this node started."""
        self.active = False
        self._report_stops(self.bus.stop_started_motors(SHUTDOWN_STOP_TIMEOUT_S), 'deactivate')
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the bus and remove the device interface."""
        self._close_bus(stop_motors=False)
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the motors this node started, then close the bus."""
        self._close_bus(stop_motors=True)
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop what this node started and close the bus; back to unconfigured."""
        self._close_bus(stop_motors=True)
        return TransitionCallbackReturn.SUCCESS

    def _close_bus(self, stop_motors: bool) -> None:
        self.active = False
        if self.bus is not None:
            self._report_stops(self.bus.shutdown(stop_motors=stop_motors,
                                                 timeout_s=SHUTDOWN_STOP_TIMEOUT_S), 'shutdown')
            self.bus = None
        for destroy, entity in self._entities:
            destroy(entity)
        for publishers in self._device_publishers.values():
            for publisher in publishers.all:
                self.destroy_lifecycle_publisher(publisher)
        self._entities.clear()
        self._device_publishers.clear()

    @staticmethod
    def _report_stops(outcomes: List[str], when: str) -> None:
        for outcome in outcomes:
            print(f'[drive_bridge] {when}: {outcome}', file=sys.stderr, flush=True)

    # -- configuration ------------------------------------------------------------------
    def _load_config(self) -> cfg.BridgeConfig:
        bus_values = {setting.name: self._declare(setting, setting.name)
                      for setting in cfg.BUS_SETTINGS}
        names = bus_values.get('devices') or []
        if not isinstance(names, list):
            names = []
        device_values = {}
        for name in names:
            if not isinstance(name, str) or not cfg.DEVICE_NAME.match(name):
                continue
            family = self._declare(cfg.DEVICE_SETTING['family'], f'{name}.family')
            device_values[name] = {
                setting.name: self._declare(setting, f'{name}.{setting.name}')
                for setting in cfg.device_settings(family) if setting.name != 'family'}
            device_values[name]['family'] = family
        self._check_unknown_overrides(names)
        return cfg.build_config(bus_values, device_values)

    def _declare(self, setting: cfg.Setting, label: str) -> Any:
        if self.has_parameter(label):  # configured before, cleaned up since
            parameter = self.get_parameter(label)
        else:
            parameter = self.declare_parameter(label, setting.default,
                                               _descriptor(setting, label))
        value = parameter.value
        return list(value) if isinstance(value, (list, tuple)) else value

    def _check_unknown_overrides(self, names: List[str]) -> None:
        overrides = getattr(self, '_parameter_overrides', {}) or {}
        for key in overrides:
            if self.has_parameter(key) or key.startswith('qos_overrides.'):
                continue
            device, _, setting = key.partition('.')
            if device in names and setting in cfg.DEVICE_SETTING and \
                    cfg.DEVICE_SETTING[setting].families:
                raise ConfigError(f'parameter {key!r} applies to families '
                                  f'{", ".join(cfg.DEVICE_SETTING[setting].families)} only')
            known = ', '.join(s.name for s in cfg.DEVICE_SETTINGS) if device in names \
                else ', '.join(s.name for s in cfg.BUS_SETTINGS)
            raise ConfigError(f'unknown parameter {key!r} in the parameters: known are '
                              f'{known} (device blocks must be listed in devices)')

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        if self.bus is None:  # declaring at configure: build_config validates them
            return SetParametersResult(successful=True)
        for parameter in parameters:
            device, _, setting_name = parameter.name.partition('.')
            setting = cfg.DEVICE_SETTING.get(setting_name)
            if device not in self.bus.device_names or setting is None:
                continue
            try:
                value = cfg.check_value(setting, parameter.value, parameter.name)
            except ConfigError as error:
                return SetParametersResult(successful=False, reason=str(error))
            if setting_name == 'speed_reference':
                try:
                    self.bus.set_speed_reference(device, value)
                except CommandRefused as error:
                    return SetParametersResult(successful=False, reason=str(error))
            elif setting_name == 'reference_timeout':
                self.bus.set_reference_timeout(device, value)
            elif setting_name == 'allow_control':
                self.bus.set_allow_control(device, value)
            elif setting_name == 'poll_rate':
                self.bus.set_poll_rate(device, value)
            elif setting_name == 'stop_on_shutdown':
                self.bus.set_stop_on_shutdown(device, value)
        return SetParametersResult(successful=True)

    # -- interface ----------------------------------------------------------------------
    def _create_device_interface(self, name: str, is_drive: bool) -> None:
        publishers = _DevicePublishers(self, name, is_drive)
        publishers.publish_state('unknown')
        self._device_publishers[name] = publishers
        if is_drive:
            self._entities.append((self.destroy_subscription, self.create_subscription(
                Float32, f'{name}/speed_reference',
                lambda message, n=name: self._on_speed_reference(n, message), 10,
                callback_group=self._timer_group)))
        for command in DRIVE_SERVICE_COMMANDS if is_drive else SERVICE_COMMANDS:
            self._entities.append((self.destroy_service, self.create_service(
                Trigger, f'{name}/{command}',
                lambda request, response, c=command, n=name: self._on_trigger(n, c, response),
                callback_group=self._service_group)))

    def _inactive_reason(self) -> str:
        """Return why commands are refused now, or '' when the node is active."""
        if self.active and self.bus is not None:
            return ''
        label = self._state_machine.current_state[1]
        return f'node is {label} (lifecycle): activate it first; nothing sent'

    def _on_trigger(self, name: str, command: str, response: Trigger.Response):
        inactive = self._inactive_reason()
        if inactive:
            response.success, response.message = False, inactive
            self.get_logger().warning(f'{name}/{command}: {inactive}')
            return response
        try:
            future = self.bus.submit_command(name, command)
            message = future.result(timeout=self.config.timing.command_timeout_s
                                    + self.config.link.timeout_s)
            response.success, response.message = True, str(message)
        except DriveBridgeError as error:
            response.success, response.message = False, str(error)
        except TimeoutError:
            response.success = False
            response.message = f'{command} not confirmed: the bus did not answer in time'
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            response.success = False
            response.message = f'{command} failed: internal error {type(error).__name__}: {error}'
        if response.success:
            self.get_logger().info(f'{name}/{command}: {response.message}')
        else:
            self.get_logger().warning(f'{name}/{command}: {response.message}')
        return response

    def _on_speed_reference(self, name: str, message: Float32) -> None:
        inactive = self._inactive_reason()
        if inactive:
            self.get_logger().warning(f'{name}/speed_reference: {inactive}',
                                      throttle_duration_sec=1.0)
            return
        try:
            self.bus.set_speed_reference(name, message.data, from_topic=True)
        except CommandRefused as error:
            self.get_logger().warning(f'{name}/speed_reference: {error}',
                                      throttle_duration_sec=1.0)
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            self.get_logger().error(f'{name}/speed_reference: internal error '
                                    f'{type(error).__name__}: {error}')

    # -- bus events (bus thread -> executor) --------------------------------------------
    def _on_bus_event(self, event: BusEvent) -> None:
        self._events.put(event)
        self._guard.trigger()

    def _publish_events(self) -> None:
        while True:
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                return
            try:
                self._publish_event(event)
            except Exception as error:  # noqa: B902 - a bug must not kill the node
                self.get_logger().error(f'cannot publish {event.kind} of {event.device}: '
                                        f'{type(error).__name__}: {error}')

    def _publish_event(self, event: BusEvent) -> None:
        publishers = self._device_publishers.get(event.device)
        if publishers is None:  # an event of a bus closed since
            return
        if event.kind == 'offline':
            publishers.publish_state('offline')
            self.get_logger().error(f'{event.device} offline: {event.message}')
        elif event.kind == 'error':
            publishers.publish_state('unknown')
            self.get_logger().error(f'{event.device}: {event.message}')
        elif event.kind == 'notice':
            self.get_logger().warning(f'{event.device}: {event.message}')
        elif event.kind == 'online':
            self.get_logger().info(f'{event.device} online')
        elif event.kind == 'reading' and event.reading is not None:
            self._publish_reading(publishers, event.reading)

    @staticmethod
    def _publish_reading(publishers: _DevicePublishers, reading) -> None:
        publishers.status_word.publish(UInt16(data=int(reading.status_word)))
        publishers.trip_code.publish(UInt16(data=int(reading.trip_code)))
        if reading.motor_current_a is not None:
            publishers.motor_current.publish(Float32(data=float(reading.motor_current_a)))
        if reading.motor_temperature_pct is not None:
            publishers.motor_temperature.publish(
                Float32(data=float(reading.motor_temperature_pct)))
        if publishers.speed_feedback is not None and reading.speed_feedback_pct is not None:
            publishers.speed_feedback.publish(Float32(data=float(reading.speed_feedback_pct)))
        if publishers.alarm_word is not None and reading.alarm_word is not None:
            publishers.alarm_word.publish(UInt32(data=int(reading.alarm_word)))
        if publishers.warning_word is not None and reading.warning_word is not None:
            publishers.warning_word.publish(UInt32(data=int(reading.warning_word)))
        publishers.publish_trip(reading.trip_name)
        publishers.publish_state(reading.state)

    # -- diagnostics --------------------------------------------------------------------
    def _publish_diagnostics(self) -> None:
        try:
            self._diagnostics.publish(self._diagnostic_array())
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            self.get_logger().error(f'cannot publish diagnostics: {type(error).__name__}: '
                                    f'{error}')

    def _diagnostic_array(self) -> DiagnosticArray:
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        bus = self.bus
        if bus is None:
            return array
        array.status = [diagnostic_status(bus.snapshot(name), self.config.link.describe(),
                                          self.active)
                        for name in bus.device_names]
        return array

    # -- shutdown -----------------------------------------------------------------------
    def shutdown_bus(self) -> None:
        """Stop the motors this node started (per stop_on_shutdown), then close the bus."""
        self._close_bus(stop_motors=True)


def diagnostic_status(snapshot: DeviceSnapshot, link: str,
                      active: bool = True) -> DiagnosticStatus:
    """Return the DiagnosticStatus of one device (contract: level, name, values)."""
    status = DiagnosticStatus(
        name=f'{NODE_NAME}: {snapshot.name}',
        hardware_id=f'{snapshot.family} {snapshot.model} address {snapshot.unit}')
    reading = snapshot.reading
    values = {'link': link, 'online': str(snapshot.online),
              'commands': 'enabled' if active else 'refused (node inactive)',
              'allow_control': str(snapshot.allow_control),
              'started_by_bridge': str(snapshot.started_by_bridge)}
    if snapshot.online is not True or reading is None:
        status.level = DiagnosticStatus.ERROR
        prefix = 'offline' if snapshot.online is False else 'no reading'
        status.message = f'{prefix}: {snapshot.status_text}'
    else:
        values.update(_reading_values(reading))
        if reading.fault:
            status.level, status.message = DiagnosticStatus.ERROR, reading.fault
        elif reading.warnings or snapshot.stats.get('setup_error'):
            warnings = reading.warnings + [snapshot.stats.get('setup_error', '')]
            status.level = DiagnosticStatus.WARN
            status.message = '; '.join(warning for warning in warnings if warning)
        else:
            status.level, status.message = DiagnosticStatus.OK, reading.state
    values.update(snapshot.stats)
    status.values = [KeyValue(key=key, value=str(value)) for key, value in values.items()]
    return status


def _reading_values(reading) -> Dict[str, str]:
    values = {'state': reading.state, 'status_word': f'0x{reading.status_word:04X}',
              'trip_code': str(reading.trip_code), 'trip': reading.trip_name}
    if reading.motor_current_a is not None:
        values['motor_current_a'] = f'{reading.motor_current_a:.1f}'
    if reading.motor_temperature_pct is not None:
        values['motor_temperature_pct'] = f'{reading.motor_temperature_pct:.0f}'
    if reading.speed_feedback_pct is not None:
        values['speed_feedback_pct'] = f'{reading.speed_feedback_pct:.2f}'
    for key in ('alarm_word', 'warning_word'):
        if getattr(reading, key) is not None:
            values[key] = f'0x{getattr(reading, key):08X}'
    values.update(reading.details)
    return values


def autostart(node: DriveBridgeNode) -> None:
    """Walk the node to active; raise ConfigError if the configuration is refused."""
    node._autostarting = True
    configured = node.trigger_configure()
    node._autostarting = False
    if configured != TransitionCallbackReturn.SUCCESS:
        raise ConfigError(node.config_error or 'configure failed (see the log above)')
    if node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
        raise ConfigError('activate failed (see the log above)')


def main(args: Optional[List[str]] = None) -> int:
    """Run the node until SIGINT/SIGTERM; exit 2 with one line on a configuration error."""
    try:
        cfg.check_params_files(sys.argv if args is None else args)
    except ConfigError as error:
        print(f'[drive_bridge] configuration error: {error}', file=sys.stderr, flush=True)
        return 2
    rclpy.init(args=args)
    node: Optional[DriveBridgeNode] = None
    exit_code = 0
    try:
        node = DriveBridgeNode()
        if node.autostart:
            autostart(node)
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.5)
    except ConfigError as error:
        print(f'[drive_bridge] configuration error: {error}', file=sys.stderr, flush=True)
        exit_code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.shutdown_bus()
            node.destroy_node()
        rclpy.try_shutdown()
    return exit_code


if __name__ == '__main__':
    sys.exit(main())
