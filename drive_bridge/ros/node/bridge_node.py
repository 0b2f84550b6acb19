"""
The ROS 2 node ``drive_bridge``: one bus, several devices, the contract's topics and services.

A managed (lifecycle) node: *configure* validates the parameters, opens the bus and starts
reading (``/diagnostics`` is published from then on, while a subscription listens);
*activate* enables the device topics, the commands and the speed references; *deactivate*
stops every motor that may run because of this node and refuses commands again (a stop is
still taken while a motor may run); *cleanup* closes the port. With ``autostart`` (default)
the node walks itself to active, so
``drive_bridge_node`` just works.

Bus I/O never runs in a ROS callback, and no callback waits for the bus while holding the
executor: the bus thread publishes each reading (while its next request is on the wire: see
:mod:`drive_bridge.bus.master`), and the command services are coroutines that await the
bus's answer (the executor serves topics and timers meanwhile).

The node is a shell over its parts, each in a module of its own: the parameters
(:mod:`~drive_bridge.ros.node.parameters`), the command gate
(:mod:`~drive_bridge.ros.node.gate`), the service calls awaiting the bus
(:mod:`~drive_bridge.ros.node.service_calls`), the high-rate command subscriptions
(:mod:`~drive_bridge.ros.node.command_inputs`), ``/diagnostics``
(:mod:`~drive_bridge.ros.node.diagnostics_publisher`) and, from configure until the bus is
closed, the bus session (:mod:`~drive_bridge.ros.node.session`) with one interface per device
(:mod:`~drive_bridge.ros.node.device_interface`) and the joints
(:mod:`~drive_bridge.ros.node.joints`). The process around it (``main``, the exit signals) is
:mod:`drive_bridge.ros.node.process`.
"""

from typing import Any, Optional

from drive_bridge.config import model as cfg
from drive_bridge.errors import ConfigError
from drive_bridge.ros.node import logs
from drive_bridge.ros.node.command_inputs import CommandInputs
from drive_bridge.ros.node.device_interface import CommandPaths
from drive_bridge.ros.node.diagnostics_publisher import DiagnosticSources, DiagnosticsPublisher
from drive_bridge.ros.node.gate import CommandGate
from drive_bridge.ros.node.parameters import (
    answer_unknown_types, keep_declared_types, ParameterDeclarations, RuntimeSettings)
from drive_bridge.ros.node.service_calls import ServiceCalls
from drive_bridge.ros.node.session import BusSession, give_up_s
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.timer import Timer

NODE_NAME = 'drive_bridge'


class DriveBridgeNode(LifecycleNode):
    """One bus owner; see the module docstring and the manual (docs/ros_api.md)."""

    def __init__(self, **kwargs: Any):
        super().__init__(NODE_NAME, **kwargs)
        self._log_handler = logs.attach(self.get_logger())  # the transports' notes
        self._guard_change_state()
        answer_unknown_types(self)
        self._declarations = ParameterDeclarations(self)
        node_values = self._declarations.node_values()
        self.autostart = bool(node_values['autostart'])
        self.config: Optional[cfg.BridgeConfig] = None
        self.config_error = ''
        self._log_config_error = True  # autostart prints it as the node's one last line
        self._gate = CommandGate(self.lifecycle_state)
        self._session: Optional[BusSession] = None
        self._diagnostics_timer: Optional[Timer] = None
        self._calls = ServiceCalls(self)
        self._inputs = CommandInputs(self)
        self._diagnostics = DiagnosticsPublisher(self)
        self._settings = RuntimeSettings(self.get_logger(),
                                         bool(node_values['allow_runtime_control_enable']))
        self.add_on_set_parameters_callback(self._on_set_parameters)

    def destroy_node(self) -> None:
        """Stop taking the package's log records, then destroy the commands node and this."""
        logs.detach(self._log_handler)
        self._calls.destroy_retired()
        self._inputs.destroy_node()
        super().destroy_node()

    def configure_for_autostart(self) -> TransitionCallbackReturn:
        """Configure; a refused configuration is left in ``config_error``, not logged."""
        self._log_config_error = False
        try:
            return self.trigger_configure()
        finally:
            self._log_config_error = True

    def shutdown_bus(self) -> None:
        """Stop every motor that may run because of this node, then close the bus."""
        self._close_bus()

    def refuse_commands(self, reason: str) -> None:
        """Take only stops from now on (an exit signal came); queued commands are dropped."""
        self._gate.active = False
        bus = self._gate.bus
        if bus is not None:
            bus.refuse_commands(reason)

    def lifecycle_state(self) -> str:
        """Return the label of the node's lifecycle state now (``inactive``, ``active``, ...)."""
        return self._state_machine.current_state[1]

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
            self.config = self._declarations.load_config()
        except ConfigError as error:
            self.config_error = str(error)
            if self._log_config_error:
                self.get_logger().error(f'configuration error: {error}')
            return TransitionCallbackReturn.FAILURE
        self.config_error = ''
        self._calls.destroy_retired()  # the old services first: the new may share their names
        self._session = BusSession(self, self.config)
        self._gate.bus = self._session.bus
        self._session.add_interfaces(self, CommandPaths(
            self._gate, self._calls, self._inputs, give_up_s(self.config)))
        # The steady clock: with use_sim_time and no /clock (a line has none) the node's clock
        # stands still, and /diagnostics and the give-up of waiting calls would stop with it.
        self._diagnostics_timer = self.create_timer(
            self.config.diagnostics_period_s, self._on_diagnostics_timer,
            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._session.start()
        self._inputs.start()
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the device topics, the commands and the speed references."""
        result = super().on_activate(state)
        self._gate.active = True
        self._session.activate()
        self.get_logger().info('active: commands enabled')
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Refuse commands again and stop every motor that may run because of this node."""
        self._gate.active = False
        self._session.stop_all('deactivate')
        with self._session.withdrawn():  # no event between 'unknown' and the deactivation
            result = super().on_deactivate(state)
        self.get_logger().info('inactive: commands refused (a stop is still taken while a '
                               'motor may run because of this node)')
        return result

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Close the bus and remove the device interface, once nothing may run because of it.

        A motor whose stop fails (a starter in Hand On refuses it) still runs because of this
        node: the cleanup is refused and the node stays inactive with the bus open, so that
        a stop, a later cleanup or the node's end sends the stop again.
        """
        if self._may_still_run('cleanup'):
            return TransitionCallbackReturn.FAILURE
        self._close_bus()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Stop every motor that may run because of this node, then close the bus.

        Where a stop fails the node is finalized with the bus open: it still takes a stop,
        and its end (SIGTERM, SIGINT) sends the stop again.
        """
        if not self._may_still_run('shutdown'):
            self._close_bus()
        return TransitionCallbackReturn.SUCCESS

    def _may_still_run(self, when: str) -> bool:
        """Take only stops, stop what may run because of this node; say if any still may."""
        session = self._session
        if session is None:
            return False
        self._gate.active = False
        running = session.stop_all(when)
        if running:
            then = 'cleanup refused: stop it, then clean up again' if when == 'cleanup' else \
                'the bus stays open: the node takes a stop, and its end sends one again'
            self.get_logger().error(f'{when}: {", ".join(running)} may still run because of '
                                    f'this node (the stop failed); {then}')
        return bool(running)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop what may run because of this node and close the bus; back to unconfigured."""
        self._close_bus()
        return TransitionCallbackReturn.SUCCESS

    def _close_bus(self) -> None:
        """
        Close the bus: from the first line on, nothing is submitted to it.

        The commands thread ends (and is waited for) before the bus does anything else, so
        no command callback runs while the motors are stopped or after the bus is closed.
        """
        self._gate.active = False
        session, self._session = self._session, None
        self._gate.bus = None
        self._inputs.stop()
        if session is not None:
            session.close()
        if self._diagnostics_timer is not None:
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = None
        self._calls.answer_all('the bus was closed')

    # -- parameters and diagnostics (executor thread) -------------------------------------
    def set_parameters_atomically(self, parameter_list) -> SetParametersResult:
        """Set as rclpy does; after a refusal, each parameter keeps its declared type."""
        result = super().set_parameters_atomically(parameter_list)
        if not result.successful:
            keep_declared_types(parameter_list, self)
        return result

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        session = self._session
        return self._settings.on_set(parameters, self._gate.bus,
                                     session.joint_bridge if session is not None else None,
                                     self, self.config)

    def _on_diagnostics_timer(self) -> None:
        self._calls.wake()  # answer calls the bus left waiting too long
        self._diagnostics.publish(self._diagnostic_sources())

    def _diagnostic_sources(self) -> Optional[DiagnosticSources]:
        session, bus = self._session, self._gate.bus
        if session is None or bus is None:
            return None
        return DiagnosticSources(bus, session.config.link.describe(), self._gate.active,
                                 self._settings.changes_in_words, session.joint_bridge)
