"""
The node's parameters: declared from the settings (:mod:`drive_bridge.config`), changed at runtime.

:class:`ParameterDeclarations` declares the node's own settings at construction and the
bus's and devices' settings at configure (each once; a later configure reads them back), and
builds the typed configuration from them; a value rclpy refuses gets the setting's reason.
:class:`RuntimeSettings` is the on-set-parameters callback: it checks every change first and
then applies them all at once, on the bus and on the joints, or none of them. Without a bus
(unconfigured, or after a cleanup) a change is kept for the next configure, which reads it
back: it is checked then as now, and ``allow_control`` is switched on only where it could be
with a bus (``allow_runtime_control_enable``), so that no lifecycle round trip turns a
monitor-only device into one that takes commands.
"""

import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Protocol

from drive_bridge.bus.master import BusMaster
from drive_bridge.config import model as cfg
from drive_bridge.config.node_parameters import bus_parameter_names, check_unknown_parameters
from drive_bridge.errors import CommandRefused, ConfigError
from drive_bridge.settings import check_value, Setting
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
from rclpy.node import Node
from rclpy.parameter import Parameter

SettingChanges = Dict[str, Dict[str, Any]]  # device -> setting name -> checked value


def descriptor(setting: Setting, label: str) -> ParameterDescriptor:
    """Return the parameter descriptor of a setting: its text, range and whether it is runtime."""
    result = ParameterDescriptor(
        name=label, description=f'{setting.description}; allowed {setting.allowed()}',
        read_only=not setting.runtime, dynamic_typing=True)
    if setting.low is not None and setting.kind is float:
        result.floating_point_range = [FloatingPointRange(
            from_value=float(setting.low), to_value=float(setting.high), step=0.0)]
    elif setting.low is not None and setting.kind is int:
        result.integer_range = [IntegerRange(
            from_value=int(setting.low), to_value=int(setting.high), step=1)]
    return result


class ParameterDeclarations:
    """Declares the node's parameters and builds the configuration from them."""

    def __init__(self, node: Node):
        self._node = node

    def node_values(self) -> Dict[str, Any]:
        """Declare the node's own settings (autostart, ...) and return their checked values."""
        return {setting.name: check_value(setting, self._declare(setting, setting.name),
                                          setting.name)
                for setting in cfg.NODE_SETTINGS}

    def load_config(self) -> cfg.BridgeConfig:
        """Declare the bus's and devices' parameters; return the checked configuration."""
        protocol = self._declare(cfg.BUS_SETTINGS[0], 'protocol')
        settings = {setting.name: setting for setting in cfg.BUS_SETTINGS}
        bus_values = {'protocol': protocol}
        for name in bus_parameter_names(protocol):
            if name in settings and name != 'protocol':
                bus_values[name] = self._declare(settings[name], name)
        names = bus_values.get('devices') or []
        if not isinstance(names, list):
            raise ConfigError(f"parameter 'devices' = {names!r} has the wrong type: give a "
                              'list of device names')
        cfg.check_device_names(names)
        device_values = {name: self._declare_device(name) for name in names}
        check_unknown_parameters(
            self._overrides(), self._node.has_parameter, names, protocol,
            {name: values['family'] for name, values in device_values.items()})
        return cfg.build_config(bus_values, device_values)

    def _overrides(self) -> Mapping[str, Parameter]:
        """Return the parameters given at start (rclpy 7.1 has no public accessor)."""
        return getattr(self._node, '_parameter_overrides', {}) or {}

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
        node = self._node
        if node.has_parameter(label):  # configured before, cleaned up since
            value = node.get_parameter(label).value
        else:
            default, given = setting.default, self._overrides().get(label)
            as_double = setting.kind is float and type(getattr(given, 'value', None)) is int
            if as_double:  # 'poll_rate: 10' in the file: declared a double all the same
                default = float(given.value)
            try:
                value = node.declare_parameter(label, default, descriptor(setting, label),
                                               ignore_override=as_double).value
            except Exception:  # noqa: B902 - rclpy's range errors: say it our way
                check_value(setting, getattr(given, 'value', None), label)
                raise ConfigError(f'parameter {label!r} is refused: allowed '
                                  f'{setting.allowed()}') from None
        return list(value) if isinstance(value, (list, tuple)) else value


class TakesJointSettings(Protocol):
    """
    What runtime changes ask of the joints.

    The joints' side is :class:`drive_bridge.ros.node.joints.JointBridge`.
    """

    def check_settings(self, changes: SettingChanges) -> None:
        """Raise ConfigError for a change the joints cannot take."""

    def apply_settings(self, changes: SettingChanges) -> None:
        """Take changes already applied on the bus."""


def checked_value(setting: Setting, parameter: Parameter) -> Any:
    """
    Return a runtime change's value checked against its setting, or raise ConfigError.

    An integer for a double is refused, as rclpy refuses a value of another type for a
    statically typed parameter: ``ros2 param set`` types ``10`` as an integer.
    """
    if setting.kind is float and parameter.type_ == Parameter.Type.INTEGER:
        raise ConfigError(f'parameter {parameter.name!r} = {parameter.value} is an integer: '
                          f'give a double ({parameter.value}.0)')
    return check_value(setting, parameter.value, parameter.name)


def keep_declared_types(parameters: List[Parameter], declared: 'DeclaredParameters') -> None:
    """
    After a refused change, give each parameter back the type of the value it kept.

    The parameters are dynamically typed (:func:`descriptor`), and rclpy writes a value's
    type into the stored descriptor before it or the on-set callback may refuse the value
    (another parameter of the same atomic change can be the one refused): a refused
    ``'fast'`` for ``poll_rate`` would leave it described as a string parameter, and
    ``drive_bridge_ctl`` types what it sends as the node describes it. The node calls this
    after every refused ``set_parameters_atomically``, which rclpy's parameter services use.
    """
    settings = cfg.all_device_settings()
    for parameter in parameters:
        setting = settings.get(parameter.name.partition('.')[2])
        if setting is not None and setting.runtime and declared.has_parameter(parameter.name):
            declared.set_descriptor(parameter.name, descriptor(setting, parameter.name))


KNOWN_TYPES = frozenset(kind.value for kind in Parameter.Type)


def answer_unknown_types(node: Node) -> None:
    """
    Make the node's set-parameters services answer a value of no known type.

    rclpy 7.1.6's services build each parameter from its message before anything else, and a
    type number that does not exist (a hand-built request) raises there: the executor logs
    it, and the caller waits for an answer that never comes. The services now refuse such a
    parameter in one line and take the others as rclpy does.
    """
    for service in node.services:
        if service.srv_name.endswith('/set_parameters'):
            service.callback = _one_by_one(service.callback, service.srv_type)
        elif service.srv_name.endswith('/set_parameters_atomically'):
            service.callback = _all_or_none(service.callback)


def _type_refused(parameter) -> SetParametersResult:
    return SetParametersResult(
        successful=False, reason=f'parameter {parameter.name!r} has type '
        f'{parameter.value.type}, which does not exist: nothing set')


def _one_by_one(callback, srv_type):
    """Return a SetParameters callback that refuses the parameters of no known type."""
    def guarded(request, response):
        for parameter in request.parameters:
            if parameter.value.type not in KNOWN_TYPES:
                response.results.append(_type_refused(parameter))
            else:
                one = callback(srv_type.Request(parameters=[parameter]), srv_type.Response())
                response.results.extend(one.results)
        return response
    return guarded


def _all_or_none(callback):
    """Return a SetParametersAtomically callback that refuses a change with such a type."""
    def guarded(request, response):
        unknown = [p for p in request.parameters if p.value.type not in KNOWN_TYPES]
        if unknown:
            response.result = _type_refused(unknown[0])
            return response
        return callback(request, response)
    return guarded


class DeclaredParameters(Protocol):
    """The node's parameters as they are before a change (:class:`rclpy.node.Node`)."""

    def has_parameter(self, name: str) -> bool:
        """Return whether ``name`` is declared."""

    def get_parameter(self, name: str) -> Parameter:
        """Return the declared parameter ``name``."""

    def set_descriptor(self, name: str, descriptor: ParameterDescriptor) -> Any:
        """Give the declared parameter ``name`` this descriptor (its value is kept)."""


class RuntimeSettings:
    """The on-set-parameters callback: every change checked, then all applied or none."""

    def __init__(self, logger, allow_runtime_control_enable: bool):
        self._logger = logger
        self.allow_runtime_control_enable = allow_runtime_control_enable
        self.changes_in_words: Dict[str, str] = {}  # device -> allow_control changed, in words

    def on_set(self, parameters: List[Parameter], bus: Optional[BusMaster],
               joints: Optional[TakesJointSettings], declared: DeclaredParameters,
               config: Optional[cfg.BridgeConfig] = None) -> SetParametersResult:
        """
        Check every change first, then apply them all at once on the bus, or none.

        ``config``: the bus's configuration, whose poll rates follow the changes taken (the
        keepalive rule is checked against them).
        """
        return self._kept_for_configure(parameters, declared) if bus is None else \
            self._applied(parameters, bus, joints, config)

    def _applied(self, parameters: List[Parameter], bus: BusMaster,
                 joints: Optional[TakesJointSettings],
                 config: Optional[cfg.BridgeConfig]) -> SetParametersResult:
        """Check every change, then apply them all on the bus and the joints, or none."""
        def allowed_now(device: str) -> bool:
            return bus.snapshot(device).allow_control
        try:
            changes = self._checked(
                parameters, lambda parameter: parameter.name.partition('.')[0] in
                bus.device_names, allowed_now)
            enabling = self._enabling(changes, allowed_now)  # before the bus takes them
            poll_rates = {device: change['poll_rate'] for device, change in changes.items()
                          if 'poll_rate' in change}
            if config is not None:
                cfg.check_poll_rate_changes(config, poll_rates)
            if joints is not None:
                joints.check_settings(changes)
            bus.apply_settings(changes)
            if joints is not None:
                joints.apply_settings(changes)
        except (ConfigError, CommandRefused) as error:
            return SetParametersResult(successful=False, reason=str(error))
        if config is not None:
            for device in config.devices:
                device.poll_rate = poll_rates.get(device.name, device.poll_rate)
        self._record(changes, enabling, '(allow_control set true): commands and writes are '
                     'taken from now on')
        return SetParametersResult(successful=True)

    def _kept_for_configure(self, parameters: List[Parameter],
                            declared: DeclaredParameters) -> SetParametersResult:
        """
        Check changes made without a bus; the next configure reads them back.

        A parameter not declared yet is being declared by the configure itself, from the
        parameters file: the configuration built from them checks those.
        """
        def allowed_now(device: str) -> bool:
            return bool(declared.get_parameter(f'{device}.allow_control').value)
        try:
            changes = self._checked(
                parameters, lambda parameter: declared.has_parameter(parameter.name),
                allowed_now)
        except ConfigError as error:
            return SetParametersResult(successful=False, reason=str(error))
        self._record(changes, self._enabling(changes, allowed_now), '(allow_control set true '
                     'while the node has no bus): commands and writes are taken from the next '
                     'configure')
        return SetParametersResult(successful=True)

    @staticmethod
    def _enabling_refused(label: str) -> str:
        """Return why ``label`` (an allow_control) may not be switched on at runtime."""
        return (f'{label} cannot be switched on at runtime here '
                '(allow_runtime_control_enable is false): restart the node with it '
                'in the parameters file')

    def _checked(self, parameters: List[Parameter], taken: Callable[[Parameter], bool],
                 allowed_now: Callable[[str], bool]) -> SettingChanges:
        """
        Return the runtime changes checked (``taken``: those of a device there is), or raise.

        ``allowed_now`` says whether a device takes commands before the change.
        """
        settings = cfg.all_device_settings()
        changes: SettingChanges = {}
        for parameter in parameters:
            device, _, name = parameter.name.partition('.')
            setting = settings.get(name)
            if setting is None or not setting.runtime or not taken(parameter):
                continue
            value = checked_value(setting, parameter)
            if name == 'allow_control' and value and not allowed_now(device) \
                    and not self.allow_runtime_control_enable:
                raise ConfigError(self._enabling_refused(parameter.name))
            changes.setdefault(device, {})[name] = value
        return changes

    @staticmethod
    def _enabling(changes: SettingChanges, allowed_now: Callable[[str], bool]) -> List[str]:
        """Return the devices whose allow_control the changes switch on."""
        return [device for device, change in changes.items()
                if change.get('allow_control') and not allowed_now(device)]

    def _record(self, changes: SettingChanges, enabling: List[str], how: str) -> None:
        """Log and keep for /diagnostics each allow_control the changes set."""
        stamp = time.strftime('%Y-%m-%dT%H:%M:%S%z')
        for device in enabling:
            self.changes_in_words[device] = f'control enabled at runtime at {stamp}'
            self._logger.warning(f'{device}: control ENABLED at runtime {how}')
        for device, change in changes.items():
            if change.get('allow_control') is False:
                self.changes_in_words[device] = f'monitor only since a runtime change at {stamp}'
