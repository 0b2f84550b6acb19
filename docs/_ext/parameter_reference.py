"""
The configuration reference as data: every parameter the node declares, in groups.

Taken from the declarations themselves (:mod:`drive_bridge.config`, each protocol's own in
:mod:`drive_bridge.transport.protocols`, each family's in its module through
:mod:`drive_bridge.devices.registry`), so the reference the docs build renders from it
(:mod:`drive_bridge_docs`) cannot drift from the code. No Sphinx here: the tests import it.
"""

from dataclasses import dataclass
from typing import Any, Dict, List, Tuple

from drive_bridge.config import model as config
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.settings import Setting
from drive_bridge.sim.registry import SIMULATORS
from drive_bridge.transport.protocols import PROTOCOLS

ROS_TYPES = {bool: 'bool', int: 'integer', float: 'double', str: 'string',
             list: 'string array'}


@dataclass(frozen=True)
class Group:
    """A table of the reference: its key (the directive's argument), title and settings."""

    key: str
    title: str
    prefix: str  # how the parameter is written: '' (bus, node) or '<name>.' (device)
    settings: Tuple[Setting, ...]


def groups() -> List[Group]:
    """Return every group of the reference, in the order of the configuration page."""
    protocol_names = {setting.name for spec in PROTOCOLS.values() for setting in spec.settings}
    result = [
        Group('node', 'Node parameters', '', config.NODE_SETTINGS),
        Group('bus', 'Bus parameters', '',
              tuple(s for s in config.BUS_SETTINGS if s.name not in protocol_names)),
    ]
    result += [Group(f'protocol:{name}', f'Protocol {name}', '', spec.settings)
               for name, spec in PROTOCOLS.items() if spec.settings]
    result += [
        Group('device', 'Device parameters, every family', '<name>.',
              config.COMMON_DEVICE_SETTINGS + config.PROFILE_SETTINGS),
        Group('drive', 'Drives: speed reference and deadman', '<name>.',
              config.SPEED_REFERENCE_SETTINGS),
        Group('joint', 'Drives: ros2_control joints', '<name>.', config.JOINT_SETTINGS),
    ]
    result += [Group(f'family:{name}', f'Family {name}', '<name>.', tuple(family.settings))
               for name, family in FAMILIES.items() if family.settings]
    return result


def group(key: str) -> Group:
    """Return the group called ``key``; raise KeyError naming the keys there are."""
    for candidate in groups():
        if candidate.key == key:
            return candidate
    raise KeyError(f'no settings group {key!r}: there are '
                   f'{", ".join(g.key for g in groups())}')


def reference_names() -> Dict[str, set]:
    """Return the names in the reference: {'bus': node and bus names, 'device': ...}."""
    names: Dict[str, set] = {'bus': set(), 'device': set()}
    for entry in groups():
        names['device' if entry.prefix else 'bus'].update(s.name for s in entry.settings)
    return names


def type_of(setting: Setting) -> str:
    """Return the parameter's ROS type."""
    return ROS_TYPES[setting.kind]


def default_of(setting: Setting) -> str:
    """Return the default as it is written in a parameters file ('' = required)."""
    value: Any = setting.default
    if value is None:
        return ''
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return f'"{value}"' if value in ('N', 'E', 'O') or not value else value
    if isinstance(value, float):
        return repr(value)
    return str(value)


def allowed_of(setting: Setting) -> str:
    """Return the allowed values ('' for any value of the type)."""
    if setting.choices:
        return ', '.join(default_of(Setting('', setting.kind, choice, ''))
                         for choice in setting.choices)
    if setting.low is not None:
        return setting.allowed()
    return ''


def simulated_models(family: str) -> Tuple[str, ...]:
    """Return the models of ``family`` that the simulator has (its sim-side registry entry)."""
    simulator = SIMULATORS.get(family)
    return simulator.models if simulator else ()


def family_rows() -> List[Tuple[str, ...]]:
    """Return (family, what it is, models, addresses, protocols, simulated models) rows."""
    return [(family.name, family.description, ', '.join(family.models),
             f'{family.address_range[0]}-{family.address_range[1]}',
             ', '.join(family.protocols), ', '.join(simulated_models(family.name)))
            for family in FAMILIES.values()]


def protocol_rows() -> List[Tuple[str, ...]]:
    """Return (protocol, what it is, link, framing, families, own settings) rows."""
    rows = []
    for name, spec in PROTOCOLS.items():
        if spec.fixed_framing:
            framing = f'8{spec.fixed_framing[0]}{spec.fixed_framing[1]} always'
        elif spec.is_serial:
            framing = f'parity as set; stopbits 0 = {spec.default_stopbits("N")} with "N", ' \
                f'{spec.default_stopbits("E")} with "E"/"O"'
        else:
            framing = ''
        families = ', '.join(f.name for f in FAMILIES.values() if name in f.protocols)
        rows.append((name, spec.description, spec.link, framing, families,
                     ', '.join(s.name for s in spec.settings)))
    return rows
