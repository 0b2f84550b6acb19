"""
The node's parameter names: which it declares, which it refuses, and a node block split.

A parameters file's node block (``ros__parameters``) is checked here the way the node checks
it, so ``drive-bridge --config`` refuses a name the node would refuse, in the same words.
"""

from typing import Any, Callable, Dict, Iterable, Iterator, List, Mapping, Set, Tuple

from drive_bridge.config.model import (
    BUS_SETTINGS, check_device_names, COMMON_DEVICE_SETTINGS, device_settings, families_taking,
    NODE_SETTINGS)
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.errors import ConfigError
from drive_bridge.settings import check_value
from drive_bridge.transport.protocols import PROTOCOLS

# Parameters rclpy declares on every node itself.
ROS_PARAMETERS = ('use_sim_time', 'start_type_description_service')
ROS_PARAMETER_PREFIXES = ('qos_overrides.',)


def bus_parameter_names(protocol: str) -> List[str]:
    """Return the bus and node parameters the node declares for a bus of ``protocol``."""
    own = PROTOCOLS[protocol].settings if protocol in PROTOCOLS else ()
    protocol_names = {setting.name for spec in PROTOCOLS.values() for setting in spec.settings}
    return [setting.name for setting in BUS_SETTINGS + NODE_SETTINGS
            if setting.name not in protocol_names or setting in own]


def declared_parameters(protocol: str, families: Mapping[str, str]) -> Set[str]:
    """
    Return every parameter name the node declares.

    The bus's, the node's, rclpy's own and each device's (``families``: device name ->
    family, each a valid family).
    """
    names = set(bus_parameter_names(protocol)) | set(ROS_PARAMETERS)
    for device, family in families.items():
        names.update(f'{device}.{setting.name}' for setting in device_settings(FAMILIES[family]))
    return names


def check_unknown_parameters(keys: Iterable[str], declared: Callable[[str], bool],
                             names: List[str], protocol: str,
                             families: Mapping[str, str]) -> None:
    """
    Refuse the first parameter of ``keys`` (flat names, ``feeder.family``) not declared.

    The node refuses a parameters file with one, naming it (``baud_rate``: unknown, with the
    known ones; a family's setting on another family; a protocol's on another protocol; a
    device block not in ``devices``), and ``drive-bridge --config`` refuses it the same way.
    ``families``: each listed device's family.
    """
    for key in keys:
        if declared(key) or key.startswith(ROS_PARAMETER_PREFIXES):
            continue
        device, _, setting = key.partition('.')
        if device in names and setting:
            owners = families_taking(setting)
            if owners:
                raise ConfigError(f'parameter {key!r} applies to families '
                                  f'{", ".join(owners)} only')
            family = families[device]
            known = [s.name for s in device_settings(FAMILIES[family])]
            raise ConfigError(f'unknown parameter {key!r}: a {family} device takes '
                              f'{", ".join(known)}')
        for name, spec in PROTOCOLS.items():
            if any(s.name == key for s in spec.settings):
                raise ConfigError(f'parameter {key!r} applies to protocol {name} only, '
                                  f'not {protocol}')
        if '.' in key:
            raise ConfigError(f'parameter {key!r}: {device!r} is not a listed device '
                              f'(devices: {", ".join(names)})')
        known_names = ', '.join(s.name for s in BUS_SETTINGS + NODE_SETTINGS)
        raise ConfigError(f'unknown parameter {key!r}: known bus parameters are {known_names}')


def flat_parameters(parameters: Mapping[str, Any], prefix: str = '') -> Iterator[str]:
    """Yield the names of a ros__parameters block as rclpy flattens them (``feeder.family``)."""
    for key, value in parameters.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            yield from flat_parameters(value, f'{name}.')
        else:
            yield name


def check_parameters_block(parameters: Mapping[str, Any]) -> None:
    """
    Refuse a node block (ros__parameters) the node would refuse for a name it does not know.

    The names as the node sees them: the protocol, the listed devices and their families
    checked as the node checks them, then every parameter of the block.
    """
    protocol = check_value(BUS_SETTINGS[0], parameters.get('protocol', BUS_SETTINGS[0].default),
                           'protocol')
    bus, devices = split_parameters(parameters)
    listed = bus.get('devices', list(devices))
    names = check_device_names(check_value(
        next(s for s in BUS_SETTINGS if s.name == 'devices'), listed, 'devices'))
    families = {name: check_value(COMMON_DEVICE_SETTINGS[0], devices.get(name, {}).get('family'),
                                  f'{name}.family') for name in names}
    declared = declared_parameters(protocol, families)
    check_unknown_parameters(flat_parameters(parameters), declared.__contains__, names,
                             protocol, families)


def split_parameters(parameters: Mapping[str, Any]) \
        -> Tuple[Dict[str, Any], Dict[str, Dict[str, Any]]]:
    """Split one node block into (bus values, device blocks by name)."""
    bus: Dict[str, Any] = {}
    devices: Dict[str, Dict[str, Any]] = {}
    for key, value in parameters.items():
        if isinstance(value, dict):
            devices[str(key)] = dict(value)
        elif '.' in str(key):  # flat form: device.setting
            device, _, setting = str(key).partition('.')
            devices.setdefault(device, {})[setting] = value
        else:
            bus[str(key)] = value
    return bus, devices
