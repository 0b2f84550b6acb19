"""
The ROS 2 node ``drive_bridge``: one bus, several devices, the contract's topics and services.

A managed (lifecycle) node: *configure* validates the parameters, opens the bus and starts
reading (``/diagnostics`` is published from then on); *activate* enables the device topics,
the commands and the speed references; *deactivate* stops every motor that may run because
of this node and refuses commands again (a stop is still taken while a motor may run);
*cleanup* closes the port. With ``autostart`` (default) the node walks itself to active, so
``drive_bridge_node`` just works.

Bus I/O never runs in a ROS callback, and no callback waits for the bus while holding the
executor: the bus thread publishes each reading (while its next request is on the wire: see
:mod:`drive_bridge.bus.master`), and the command services are coroutines that await the
bus's answer (the executor serves topics and timers meanwhile). SIGINT, SIGTERM and SIGHUP
are taken by the main thread (:func:`main`): the first one stops every motor that may run
because of the node, then the node exits; more signals meanwhile change nothing.
"""

import functools
import signal
import sys
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, KeyValue
from drive_bridge import config as cfg
from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.master import BusMaster
from drive_bridge.errors import CommandRefused, ConfigError, DriveBridgeError
from drive_bridge.protocol.commands import Command
from drive_bridge.ros import joints, logs
from drive_bridge.ros.bus_events import publish_event
from drive_bridge.ros.diagnostics import diagnostic_status, status_name
from drive_bridge.ros.publishers import DevicePublishers
from drive_bridge.settings import check_value, Setting
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future as RosFuture
from std_msgs.msg import Float32
from std_srvs.srv import Trigger

NODE_NAME = 'drive_bridge'
SERVICE_COMMANDS = (Command.START, Command.STOP, Command.QUICK_STOP, Command.COAST_STOP,
                    Command.RESET)
STOP_ALL_TIMEOUT_S = 3.0
NODE_SETTINGS = cfg.NODE_SETTINGS
EXIT_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _descriptor(setting: Setting, label: str) -> ParameterDescriptor:
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


class _PendingCall:
    """A service call waiting for the bus: the bus's future and the one the service awaits."""

    def __init__(self, bus_future, label: str, give_up_at_s: float):
        self.bus_future = bus_future
        self.label = label
        self.give_up_at_s = give_up_at_s
        self.ros_future = RosFuture()


class DriveBridgeNode(LifecycleNode):
    """One bus owner; see the module docstring and the manual (docs/ros_api.md)."""

    def __init__(self, **kwargs: Any):
        super().__init__(NODE_NAME, **kwargs)
        self._log_handler = logs.attach(self.get_logger())  # the transports' notes
        self._guard_change_state()
        node_values = {setting.name: self._declare(setting, setting.name)
                       for setting in cfg.NODE_SETTINGS}
        self.autostart = bool(node_values['autostart'])
        self.allow_runtime_control_enable = bool(node_values['allow_runtime_control_enable'])
        self.config: Optional[cfg.BridgeConfig] = None
        self.config_error = ''
        self._autostarting = False
        self.bus: Optional[BusMaster] = None
        self.active = False
        self._device_publishers: Dict[str, DevicePublishers] = {}
        self._joints: Optional[joints.JointInterface] = None  # ros2_control: ros/joints.py
        self._entities: List[Tuple[Callable[[Any], bool], Any]] = []  # (destroy, entity)
        self._publishing = threading.Lock()
        self._pending: List[_PendingCall] = []
        self._runtime_changes: Dict[str, str] = {}  # device -> allow_control changed, in words
        self._pending_lock = threading.Lock()
        # Service coroutines stay "executing" while they await the bus: they and the guard
        # that hands them the bus's answers must not share a mutually exclusive group.
        self._calls = ReentrantCallbackGroup()
        self._answers = self.create_guard_condition(self._deliver_answers,
                                                    callback_group=self._calls)
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.add_on_set_parameters_callback(self._on_set_parameters)

    def destroy_node(self) -> None:
        """Stop taking the package's log records, then destroy the node."""
        logs.detach(self._log_handler)
        super().destroy_node()

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
        self.bus = BusMaster(self.config.make_transport(),
                             [device.make_spec() for device in self.config.devices],
                             self.config.timing, listener=self._on_bus_event)
        self.bus.set_commands_enabled(False)
        for device in self.config.devices:
            self._create_device_interface(device.name)
        with self._publishing:
            self._joints = joints.attach(self, self.bus, self.config.devices,
                                         lambda: self.active)
        self._entities.append((self.destroy_timer, self.create_timer(
            self.config.diagnostics_period_s, self._on_diagnostics_timer)))
        self.bus.start()
        self.get_logger().info(
            f'bus {self.config.link.describe()}: '
            + ', '.join(f'{d.name} ({d.family} {d.model} @ {d.address}'
                        + ('' if d.allow_control else ', monitor only') + ')'
                        for d in self.config.devices))
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the device topics, the commands and the speed references."""
        result = super().on_activate(state)
        self.active = True
        self.bus.set_commands_enabled(True)
        with self._publishing:  # in the order of the bus's events: see republish
            for publishers in self._device_publishers.values():
                publishers.republish()
        self.get_logger().info('active: commands enabled')
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Refuse commands again and stop every motor that may run because of this node."""
        self.active = False
        self._report_stops(self.bus.stop_all('deactivate', STOP_ALL_TIMEOUT_S), 'deactivate')
        # A subscriber that joins while the node is inactive gets the latched state: leave
        # 'unknown' there, not the last state (say 'running' of a motor just stopped). No
        # event of the bus gets between that and the publishers' deactivation.
        with self._publishing:
            for publishers in self._device_publishers.values():
                publishers.withdraw()
            result = super().on_deactivate(state)
        self.get_logger().info('inactive: commands refused (a stop is still taken while a '
                               'motor may run because of this node)')
        return result

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the bus (stopping what may still run) and remove the device interface."""
        self._close_bus()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop every motor that may run because of this node, then close the bus."""
        self._close_bus()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop what may run because of this node and close the bus; back to unconfigured."""
        self._close_bus()
        return TransitionCallbackReturn.SUCCESS

    def _close_bus(self) -> None:
        self.active = False
        bus, self.bus = self.bus, None
        if bus is not None:
            self._report_stops(bus.shutdown(stop_motors=True, timeout_s=STOP_ALL_TIMEOUT_S),
                               'shutdown')
        with self._publishing:  # the bus thread has ended: nothing publishes any more
            for publishers in self._device_publishers.values():
                publishers.destroy()
            self._device_publishers.clear()
            if self._joints is not None:
                self._joints.destroy()
                self._joints = None
        for destroy, entity in self._entities:
            destroy(entity)
        self._entities.clear()
        self._answer_pending('the bus was closed')

    def _report_stops(self, outcomes: List[str], when: str) -> None:
        logger = self.get_logger()
        for outcome in outcomes:
            if 'acknowledged' in outcome:
                logger.info(f'{when}: {outcome}')
            else:
                logger.error(f'{when}: {outcome}')

    def shutdown_bus(self) -> None:
        """Stop every motor that may run because of this node, then close the bus."""
        self._close_bus()

    def refuse_commands(self, reason: str) -> None:
        """Take only stops from now on (an exit signal came); queued commands are dropped."""
        self.active = False
        bus = self.bus
        if bus is not None:
            bus.refuse_commands(reason)

    # -- configuration ------------------------------------------------------------------
    def _load_config(self) -> cfg.BridgeConfig:
        protocol = self._declare(cfg.BUS_SETTINGS[0], 'protocol')
        settings = {setting.name: setting for setting in cfg.BUS_SETTINGS}
        bus_values = {'protocol': protocol}
        for name in cfg.bus_parameter_names(protocol):
            if name in settings and name != 'protocol':
                bus_values[name] = self._declare(settings[name], name)
        names = bus_values.get('devices') or []
        if not isinstance(names, list):
            raise ConfigError(f"parameter 'devices' = {names!r} has the wrong type: give a "
                              'list of device names')
        cfg.check_device_names(names)
        device_values = {name: self._declare_device(name) for name in names}
        overrides = getattr(self, '_parameter_overrides', {}) or {}
        cfg.check_unknown_parameters(
            overrides, self.has_parameter, names, protocol,
            {name: values['family'] for name, values in device_values.items()})
        return cfg.build_config(bus_values, device_values)

    def _declare_device(self, name: str) -> Dict[str, Any]:
        family_name = self._declare(cfg.COMMON_DEVICE_SETTINGS[0], f'{name}.family')
        check_value(cfg.COMMON_DEVICE_SETTINGS[0], family_name, f'{name}.family')
        family = cfg.FAMILIES[family_name]
        values = {'family': family_name}
        for setting in cfg.device_settings(family)[1:]:
            values[setting.name] = self._declare(setting, f'{name}.{setting.name}')
        return values

    def _declare(self, setting: Setting, label: str) -> Any:
        """Declare (once) and return a parameter; a value rclpy refuses gets our reason."""
        if self.has_parameter(label):  # configured before, cleaned up since
            value = self.get_parameter(label).value
        else:
            try:
                value = self.declare_parameter(label, setting.default,
                                               _descriptor(setting, label)).value
            except Exception:  # noqa: B902 - rclpy's range errors: say it our way
                override = (getattr(self, '_parameter_overrides', {}) or {}).get(label)
                check_value(setting, getattr(override, 'value', None), label)
                raise ConfigError(f'parameter {label!r} is refused: allowed '
                                  f'{setting.allowed()}') from None
        return list(value) if isinstance(value, (list, tuple)) else value

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Check every change first, then apply them all at once on the bus, or none."""
        bus = self.bus
        if bus is None:  # declaring at configure: build_config validates them
            return SetParametersResult(successful=True)
        settings = cfg.all_device_settings()
        changes: Dict[str, Dict[str, Any]] = {}
        try:
            for parameter in parameters:
                device, _, name = parameter.name.partition('.')
                setting = settings.get(name)
                if device not in bus.device_names or setting is None or not setting.runtime:
                    continue
                value = check_value(setting, parameter.value, parameter.name)
                if name == 'allow_control' and value and not \
                        bus.snapshot(device).allow_control and \
                        not self.allow_runtime_control_enable:
                    raise ConfigError(
                        f'{parameter.name} cannot be switched on at runtime here '
                        '(allow_runtime_control_enable is false): restart the node with it '
                        'in the parameters file')
                changes.setdefault(device, {})[name] = value
            enabling = [device for device, change in changes.items()
                        if change.get('allow_control') and not bus.snapshot(device).allow_control]
            if self._joints is not None:
                self._joints.bridge.check_settings(changes)
            bus.apply_settings(changes)
            if self._joints is not None:
                self._joints.bridge.apply_settings(changes)
        except (ConfigError, CommandRefused) as error:
            return SetParametersResult(successful=False, reason=str(error))
        for device in enabling:
            stamp = time.strftime('%Y-%m-%dT%H:%M:%S%z')
            self._runtime_changes[device] = f'control enabled at runtime at {stamp}'
            self.get_logger().warning(f'{device}: control ENABLED at runtime (allow_control '
                                      'set true): commands and writes are taken from now on')
        for device, change in changes.items():
            if change.get('allow_control') is False:
                self._runtime_changes[device] = 'monitor only since a runtime change at ' + \
                    time.strftime('%Y-%m-%dT%H:%M:%S%z')
        return SetParametersResult(successful=True)

    # -- interface ----------------------------------------------------------------------
    def _create_device_interface(self, name: str) -> None:
        snapshot = self.bus.snapshot(name)
        publishers = DevicePublishers(self, name, snapshot.reading_fields)
        publishers.publish_state('unknown')
        with self._publishing:
            self._device_publishers[name] = publishers
        if cfg.FAMILIES[snapshot.family].reference:
            self._entities.append((self.destroy_subscription, self.create_subscription(
                Float32, f'{name}/speed_reference',
                lambda message, n=name: self._on_speed_reference(n, message), 10)))
        for command in SERVICE_COMMANDS:
            if command in snapshot.commands:
                self._entities.append((self.destroy_service, self.create_service(
                    Trigger, f'{name}/{command.value}',
                    functools.partial(self._on_trigger, name, command),
                    callback_group=self._calls)))

    def _inactive_reason(self) -> str:
        label = self._state_machine.current_state[1]
        return f'node is {label} (lifecycle): activate it first; nothing sent'

    async def _on_trigger(self, name: str, command: Command, request: Trigger.Request,
                          response: Trigger.Response):
        """Send ``command`` and answer once the device acknowledged it or it failed."""
        try:
            response.message = await self._command(name, command)
            response.success = True
        except DriveBridgeError as error:
            response.success, response.message = False, str(error)
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            response.success = False
            response.message = f'{command.value} failed: internal error ' \
                f'{type(error).__name__}: {error}'
        if response.success:  # one logging call site per severity (rclpy caches them)
            self.get_logger().info(f'{name}/{command.value}: {response.message}')
        else:
            self.get_logger().warning(f'{name}/{command.value}: {response.message}')
        return response

    async def _command(self, name: str, command: Command) -> str:
        bus = self.bus
        if bus is None or (not self.active and not command.stops):
            raise CommandRefused(self._inactive_reason())
        future = bus.submit_command(name, command)
        if future.done() and future.exception() is not None and not self.active:
            raise CommandRefused(f'{self._inactive_reason()} ({future.exception()})')
        give_up_s = self.config.timing.command_deadline_s + \
            4 * self.config.link.timeout_s + 1.0
        call = _PendingCall(future, command.value, time.monotonic() + give_up_s)
        with self._pending_lock:
            self._pending.append(call)
        future.add_done_callback(lambda done: self._answers.trigger())
        if future.done():
            self._answers.trigger()
        result = await call.ros_future
        if isinstance(result, BaseException):
            raise result
        return result

    def _deliver_answers(self) -> None:
        """Hand the bus's answers to the waiting services (executor thread)."""
        now = time.monotonic()
        with self._pending_lock:
            pending, self._pending = self._pending, []
        for call in pending:
            if call.bus_future.done():
                error = call.bus_future.exception()
                call.ros_future.set_result(error if error is not None
                                           else call.bus_future.result())
            elif now > call.give_up_at_s:
                self._give_up(call)
            else:
                with self._pending_lock:
                    self._pending.append(call)

    @staticmethod
    def _give_up(call: _PendingCall) -> None:
        """Answer a call the bus did not resolve in time; a command not yet sent never is."""
        if call.bus_future.cancel():
            call.ros_future.set_result(CommandRefused(
                f'{call.label} not sent: the bus did not take it in time; it is never sent'))
        else:
            call.ros_future.set_result(DriveBridgeError(
                f'{call.label} not confirmed: the bus did not answer in time; it may be on '
                'the wire (see /diagnostics)'))

    def _answer_pending(self, reason: str) -> None:
        with self._pending_lock:
            pending, self._pending = self._pending, []
        for call in pending:
            if not call.ros_future.done():
                call.bus_future.cancel()
                call.ros_future.set_result(CommandRefused(f'{call.label}: {reason}'))

    def _on_speed_reference(self, name: str, message: Float32) -> None:
        bus = self.bus
        if not self.active or bus is None:
            self.get_logger().warning(f'{name}/speed_reference: {self._inactive_reason()}',
                                      throttle_duration_sec=1.0)
            return
        try:
            bus.set_speed_reference(name, message.data, from_topic=True)
        except CommandRefused as error:
            self.get_logger().warning(f'{name}/speed_reference: {error}',
                                      throttle_duration_sec=1.0)
        except Exception as error:  # noqa: B902 - a bug must not kill the node
            self.get_logger().error(f'{name}/speed_reference: internal error '
                                    f'{type(error).__name__}: {error}')

    # -- bus events (bus thread) ----------------------------------------------------------
    def _on_bus_event(self, event: BusEvent) -> None:
        """Publish a reading, or log a change, as the bus thread reports it."""
        with self._publishing:
            publishers = self._device_publishers.get(event.device)
            if publishers is None:  # an event of a bus closed since
                return
            try:
                self._publish_event(publishers, event)
                if self._joints is not None:
                    self._joints.bridge.on_bus_event(event)
            except Exception as error:  # noqa: B902 - a bug must not kill the bus thread
                self.get_logger().error(f'cannot publish {type(event).__name__} of '
                                        f'{event.device}: {type(error).__name__}: {error}')

    def _publish_event(self, publishers: DevicePublishers, event: BusEvent) -> None:
        publish_event(publishers, self.get_logger(), event)

    # -- diagnostics and overdue calls --------------------------------------------------
    def _on_diagnostics_timer(self) -> None:
        self._answers.trigger()  # answer calls the bus left waiting too long
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
        commands = 'enabled' if self.active else 'refused (node inactive; stops taken ' \
            'while a motor may run)'
        fqn = self.get_fully_qualified_name()
        array.status = [diagnostic_status(bus.snapshot(name), status_name(fqn, name),
                                          self.config.link.describe(), commands)
                        for name in bus.device_names]
        for status, name in zip(array.status, bus.device_names):
            if name in self._runtime_changes:
                status.values.append(KeyValue(key='allow_control_changed',
                                              value=self._runtime_changes[name]))
        joint_interface = self._joints
        if joint_interface is not None:
            for status, name in zip(array.status, bus.device_names):
                status.values.extend(joint_interface.bridge.device_values(name))
            array.status.append(joint_interface.bridge.commands_status(
                status_name(fqn, joints.COMMANDS_TOPIC)))
        return array


def autostart(node: DriveBridgeNode) -> None:
    """Walk the node to active; raise ConfigError if the configuration is refused."""
    node._autostarting = True
    try:
        configured = node.trigger_configure()
    finally:
        node._autostarting = False
    if configured != TransitionCallbackReturn.SUCCESS:
        raise ConfigError(node.config_error or 'configure failed (see the log above)')
    if node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
        raise ConfigError('activate failed (see the log above)')


def _spin(executor: SingleThreadedExecutor, stop: threading.Event) -> None:
    """Spin until ``stop``; a context shut down under the executor ends it quietly."""
    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=0.5)
        except (ExternalShutdownException, KeyboardInterrupt):
            return
        except Exception as error:  # noqa: B902 - rclpy#398: the context went away
            if stop.is_set() or not rclpy.ok():
                return
            print(f'[drive_bridge] executor: {type(error).__name__}: {error}', file=sys.stderr,
                  flush=True)


# Exit signals that reached a thread which did not block them (a thread started before
# main() blocked them, when the node runs as ``python -m drive_bridge.ros.node`` rather than
# through drive_bridge.ros.entry): Python runs the handler below in the main thread.
_stray_signals: List[int] = []


def _take_stray_signal(number: int, _frame) -> None:
    """Record an exit signal that a thread without the mask took; never raise."""
    if _stray_signals:
        _say_again(number)
    _stray_signals.append(number)


def _say_again(number: int) -> None:
    print(f'[drive_bridge] {signal.Signals(number).name} again: already stopping the '
          'motors, then exiting', file=sys.stderr, flush=True)


def _wait_for_signal(stop: threading.Event) -> int:
    """Wait in the main thread for an exit signal (they are blocked); return its number."""
    while not stop.is_set() and not _stray_signals:
        received = signal.sigtimedwait(EXIT_SIGNALS, 0.5)
        if received is not None:
            _stray_signals.append(received.si_signo)  # later ones are "again"
            return received.si_signo
    return _stray_signals[0] if _stray_signals else 0


def _ignore_more_signals(done: threading.Event) -> None:
    """During shutdown, take further exit signals and say they change nothing."""
    while not done.is_set():
        received = signal.sigtimedwait(EXIT_SIGNALS, 0.2)
        if received is not None:
            _say_again(received.si_signo)


def _block_exit_signals() -> None:
    """Block the exit signals here and in later threads; take strays from earlier ones."""
    signal.pthread_sigmask(signal.SIG_BLOCK, EXIT_SIGNALS)
    for number in EXIT_SIGNALS:
        signal.signal(number, _take_stray_signal)


def main(args: Optional[List[str]] = None) -> int:
    """Run the node until SIGINT/SIGTERM/SIGHUP; exit 2 with one line on a configuration error."""
    argv = sys.argv if args is None else args
    if '-h' in argv[1:] or '--help' in argv[1:]:
        print(USAGE)
        return 0
    try:
        cfg.check_params_files(argv)
    except ConfigError as error:
        print(f'[drive_bridge] configuration error: {error}', file=sys.stderr, flush=True)
        return 2
    # Block the exit signals in every thread from here on (threads inherit the mask): the
    # main thread takes them with sigtimedwait, so no KeyboardInterrupt ever lands inside a
    # stop, and a second signal cannot cut the stops short.
    _block_exit_signals()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as error:  # noqa: B902 - rcl refuses its arguments: say why in one line
        reason = str(error).split(', at ')[0]
        print(f'[drive_bridge] configuration error: ROS could not take the arguments: '
              f'{reason}', file=sys.stderr, flush=True)
        return 2
    node: Optional[DriveBridgeNode] = None
    stop = threading.Event()
    spinner: Optional[threading.Thread] = None
    executor = SingleThreadedExecutor()
    exit_code = 0
    try:
        node = DriveBridgeNode()
        if node.autostart:
            autostart(node)
        executor.add_node(node)
        spinner = threading.Thread(target=_spin, args=(executor, stop), name='ros-executor',
                                   daemon=True)
        spinner.start()
        received = _wait_for_signal(stop)
        signal_name = signal.Signals(received).name
        node.refuse_commands(signal_name)
        node.get_logger().info(f'{signal_name}: stopping the motors that may run because of '
                               'this node, then exiting')
    except ConfigError as error:
        print(f'[drive_bridge] configuration error: {error}', file=sys.stderr, flush=True)
        exit_code = 2
    finally:
        done = threading.Event()
        threading.Thread(target=_ignore_more_signals, args=(done,), daemon=True).start()
        if node is not None:
            node.shutdown_bus()
        stop.set()
        executor.shutdown(timeout_sec=1.0)
        if spinner is not None:
            spinner.join(timeout=2.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        done.set()
    return exit_code


USAGE = """usage: drive_bridge_node [--ros-args --params-file FILE [-r __ns:=/line1] ...]

The drive_bridge node: one RS-485 bus (or Modbus gateway) with its soft starters and drives,
as ROS 2 topics, services and parameters. Settings come from a ROS 2 parameters file; see
docs/configuration.md and config/*.yaml. Exit status: 0 after a signal, 2 on a configuration
error."""


if __name__ == '__main__':
    sys.exit(main())
