"""
Configuration: every bus and device setting as data, validated into typed objects.

The ROS node declares its parameters from these tables (types, defaults, ranges, text) and
the tools use the same validation, so a bad value gets the same one-line message anywhere.
"""

from dataclasses import dataclass, field
import math
import re
from typing import Any, Dict, List, Optional, Tuple

from drive_bridge.bus.master import BusTiming, DeviceSpec
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.errors import ConfigError
from drive_bridge.protocol import ap_ascii, rtu
from drive_bridge.transport.factory import make_transport, SERIAL_ENGINES
from drive_bridge.transport.link import LinkSettings

PROTOCOLS = ('modbus_rtu', 'ap_ascii', 'modbus_tcp', 'rtu_over_tcp')
DRIVES = tuple(name for name, family in FAMILIES.items() if family.is_drive)
LVSG = ('lvsg',)
BAUDRATES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)
PARITIES = ('N', 'E', 'O')
DEVICE_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')


@dataclass(frozen=True)
class Setting:
    """
    One parameter: name, Python type, default (None = required), limits and meaning.

    ``low``/``high`` bound numbers (``high_open``: high itself excluded); ``choices`` bound
    strings and ints; ``runtime`` settings may be changed with ``ros2 param set``.
    """

    name: str
    kind: type
    default: Any
    description: str
    low: Optional[float] = None
    high: Optional[float] = None
    choices: Tuple = ()
    runtime: bool = False
    high_open: bool = False
    families: Tuple[str, ...] = ()  # the families that take it; () = every family

    def allowed(self) -> str:
        """Return the allowed values in words."""
        if self.choices:
            return ', '.join(str(choice) for choice in self.choices)
        if self.low is not None:
            closing = ')' if self.high_open else ']'
            return f'[{self.low:g}, {self.high:g}{closing}'
        return {bool: 'true or false', str: 'a string', int: 'an integer',
                float: 'a number', list: 'a list of names'}[self.kind]


BUS_SETTINGS: Tuple[Setting, ...] = (
    Setting('protocol', str, 'modbus_rtu', 'bus protocol', choices=PROTOCOLS),
    Setting('port', str, '/dev/ttyUSB0', 'serial device (serial protocols)'),
    Setting('host', str, '127.0.0.1', 'gateway host (TCP protocols)'),
    Setting('tcp_port', int, 502, 'gateway TCP port', low=1, high=65535),
    Setting('baudrate', int, 9600, 'serial baud rate', choices=BAUDRATES),
    Setting('parity', str, 'E', 'serial parity (quote "N" in YAML)', choices=PARITIES),
    Setting('stopbits', int, 0, '0 = Modbus standard: 2 with no parity, 1 with parity',
            choices=(0, 1, 2)),
    Setting('timeout', float, 0.5, 'seconds per transaction', low=0.02, high=10.0),
    Setting('retries', int, 2, 'retries of a read (commands are never repeated)',
            low=0, high=10),
    Setting('devices', list, None, 'device names; each has a block <name>.*'),
    Setting('offline_after', int, 3,
            'failed transactions in a row before a device is reported offline', low=1, high=100),
    Setting('backoff_max', float, 10.0,
            'longest pause in seconds between probes of an offline device or link',
            low=0.5, high=600.0),
    Setting('frame_gap', float, 0.0,
            'pause in seconds between transactions; 0 = 3.5 characters on serial lines',
            low=0.0, high=1.0),
    Setting('local_echo', bool, False, 'the RS-485 adapter echoes what it sends'),
    Setting('diagnostics_period', float, 1.0, 'seconds between /diagnostics messages',
            low=0.1, high=60.0),
    Setting('ap_nak_retries', int, 2,
            'AP ASCII: how often an exchange answered with NAK (bad LRC, not executed) is '
            'restarted from the address', low=0, high=10),
    Setting('ap_address_lrc_eot', bool, True,
            'AP ASCII: the address fragment LRC includes EOT (the manual leaves it open)'),
    Setting('serial_engine', str, 'native',
            'Modbus RTU on a serial port: native (reads replies by their length) or pymodbus',
            choices=SERIAL_ENGINES),
)

DEVICE_SETTINGS: Tuple[Setting, ...] = (
    Setting('family', str, None, 'device family', choices=tuple(FAMILIES)),
    Setting('model', str, 'auto', 'device model; auto reads it from the device'),
    Setting('address', int, None, 'bus address', low=1, high=247),
    Setting('poll_rate', float, 5.0, 'polls per second', low=0.1, high=100.0, runtime=True),
    Setting('allow_control', bool, True, 'false: monitor only, commands refused',
            runtime=True),
    Setting('stop_on_shutdown', bool, True,
            'a clean shutdown stops the motors this node started', runtime=True),
    Setting('current_scale', float, 1.0,
            'factor on the reported current (MCD5-0068B and smaller: 0.1)',
            low=0.001, high=1000.0),
    Setting('speed_reference', float, 0.0, 'drives: percent, FC scaling',
            low=-200.0, high=200.0, high_open=True, runtime=True, families=DRIVES),
    Setting('reference_timeout', float, 0.0,
            'drives: seconds without a speed_reference message before a ramp stop; 0 = off',
            low=0.0, high=3600.0, runtime=True, families=DRIVES),
    Setting('comms_timeout', float, 0.0,
            "drives: the drive's own control word timeout in seconds, written when the drive "
            'comes online (FC: par. 8-03); 0 = leave the drive as set',
            low=0.0, high=6000.0, families=DRIVES),
    Setting('comms_timeout_function', int, -1,
            'drives: what the drive does on a control word timeout (FC: par. 8-04; 0 off, '
            '1 freeze, 2 stop, 3 jog, 4 max speed, 5 stop and trip); -1 = leave as set',
            choices=(-1, 0, 1, 2, 3, 4, 5), families=DRIVES),
    Setting('drive_link_timeout', float, 0.0,
            "VLT option card: register 3, the card's drive communications timeout in seconds, "
            'written when the drive comes online; 0 = leave it', low=0.0, high=655.35,
            families=DRIVES),
    Setting('gateway_input_register', int, None,
            "lvsg: frame address of the first register holding the slave's input bytes "
            '(status) in the gateway', low=0, high=65535, families=LVSG),
    Setting('gateway_output_register', int, None,
            "lvsg: frame address of the first register holding the slave's output bytes "
            '(control) in the gateway', low=0, high=65535, families=LVSG),
    Setting('gateway_byte_order', str, 'big',
            'lvsg: big = the first process byte is the high byte of a register',
            choices=('big', 'little'), families=LVSG),
    Setting('lvsg_module', str, 'extended',
            'lvsg: the GSD module configured in the DP master: basic or extended',
            choices=('basic', 'extended'), families=LVSG),
    Setting('current_parameter', int, 0,
            "drives: parameter number of the motor current readout; 0 = the model's own "
            '(FC 51: 1614 = 16-14; VLT 5000: 520; VLT 6000: 514)',
            low=0, high=6553, families=DRIVES),
)
BUS_SETTING = {setting.name: setting for setting in BUS_SETTINGS}
DEVICE_SETTING = {setting.name: setting for setting in DEVICE_SETTINGS}


@dataclass
class DeviceConfig:
    """One validated device block."""

    name: str
    family: str
    model: str
    address: int
    poll_rate: float
    allow_control: bool
    stop_on_shutdown: bool
    current_scale: float
    speed_reference: float = 0.0
    reference_timeout: float = 0.0
    comms_timeout: float = 0.0
    comms_timeout_function: int = -1
    current_parameter: int = 0
    drive_link_timeout: float = 0.0
    gateway_input_register: int = 0
    gateway_output_register: int = 0
    gateway_byte_order: str = 'big'
    lvsg_module: str = 'extended'
    protocol: str = 'modbus_rtu'

    @property
    def is_drive(self) -> bool:
        """Return whether the device takes a speed reference (FC-profile drives)."""
        return FAMILIES[self.family].is_drive

    def make_spec(self) -> DeviceSpec:
        """Return the bus's view of this device, with its profile."""
        profile = FAMILIES[self.family].make_profile(self)
        if self.is_drive:
            profile.set_reference(self.speed_reference)
        return DeviceSpec(self.name, self.address, profile, self.poll_rate,
                          self.allow_control, self.stop_on_shutdown, self.reference_timeout)


@dataclass
class BridgeConfig:
    """A validated bus with its devices."""

    link: LinkSettings
    timing: BusTiming
    devices: List[DeviceConfig] = field(default_factory=list)
    diagnostics_period_s: float = 1.0
    serial_engine: str = 'native'
    ap_nak_retries: int = 2
    ap_address_lrc_eot: bool = True

    def make_transport(self):
        """Return the transport of this bus."""
        return make_transport(self.link, self.serial_engine, self.ap_nak_retries,
                              self.ap_address_lrc_eot)


def check_value(setting: Setting, value: Any, label: str) -> Any:
    """Return ``value`` checked against ``setting`` (ints accepted for floats), or raise."""
    if value is None:
        raise ConfigError(f'parameter {label!r} is required: allowed {setting.allowed()}')
    value = _coerce(setting, value, label)
    if setting.choices and value not in setting.choices:
        raise ConfigError(f'parameter {label!r} = {value!r} is invalid: allowed '
                          f'{setting.allowed()}')
    if setting.low is not None and not _in_range(setting, value):
        raise ConfigError(f'parameter {label!r} = {value!r} is out of range: allowed '
                          f'{setting.allowed()}')
    return value


def _coerce(setting: Setting, value: Any, label: str) -> Any:
    if setting.kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if setting.kind is list:
        ok = isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)
    else:
        ok = isinstance(value, setting.kind) and not (
            setting.kind is not bool and isinstance(value, bool))
    if not ok:
        hint = ''
        if setting.name == 'parity' and isinstance(value, bool):
            hint = ' (write parity: "N" with quotes: unquoted N is YAML false)'
        raise ConfigError(f'parameter {label!r} = {value!r} has the wrong type: allowed '
                          f'{setting.allowed()}{hint}')
    if setting.kind is float and (math.isnan(value) or math.isinf(value)):
        raise ConfigError(f'parameter {label!r} = {value!r} must be a finite number')
    return list(value) if setting.kind is list else value


def _in_range(setting: Setting, value: float) -> bool:
    if setting.high_open:
        return setting.low <= value < setting.high
    return setting.low <= value <= setting.high


def build_config(bus_values: Dict[str, Any], device_values: Dict[str, Dict[str, Any]]) \
        -> BridgeConfig:
    """Validate raw values (name -> value; devices: name -> {setting -> value})."""
    bus = {setting.name: check_value(setting, bus_values.get(setting.name, setting.default),
                                     setting.name)
           for setting in BUS_SETTINGS}
    if bus['protocol'] == 'ap_ascii':
        _check_ap_ascii(bus)
    names = bus['devices']
    if not names:
        raise ConfigError("parameter 'devices' is empty: list at least one device name")
    devices = [build_device(name, device_values.get(name, {}), bus['protocol'])
               for name in _checked_names(names)]
    _check_unique_addresses(devices)
    link = LinkSettings(
        protocol=bus['protocol'], port=bus['port'], host=bus['host'],
        tcp_port=bus['tcp_port'], baudrate=bus['baudrate'], parity=bus['parity'],
        stopbits=bus['stopbits'], timeout_s=bus['timeout'], local_echo=bus['local_echo'])
    gap = bus['frame_gap']
    if gap == 0.0 and link.is_serial:
        gap = rtu.frame_gap_s(link.baudrate, link.parity, link.effective_stopbits)
    timing = BusTiming(retries=bus['retries'], offline_after=bus['offline_after'],
                       backoff_initial_s=min(1.0, bus['backoff_max']),
                       backoff_max_s=bus['backoff_max'], frame_gap_s=gap,
                       slow_reply_s=bus['timeout'] / 2)
    return BridgeConfig(link, timing, devices, bus['diagnostics_period'], bus['serial_engine'],
                        bus['ap_nak_retries'], bus['ap_address_lrc_eot'])


def _check_ap_ascii(bus: Dict[str, Any]) -> None:
    """AP ASCII runs 8N1 (manual 000 section 10) with a timeout the MCD 3000 can meet."""
    if bus['parity'] != 'N' or bus['stopbits'] not in (0, 1):
        raise ConfigError(f"parameter 'parity' = {bus['parity']!r}, 'stopbits' = "
                          f"{bus['stopbits']} do not fit protocol 'ap_ascii': AP ASCII is "
                          '8N1, set parity: "N" and stopbits: 0 or 1')
    if bus['timeout'] < ap_ascii.MIN_TIMEOUT_S:
        raise ConfigError(f"parameter 'timeout' = {bus['timeout']} is too short for "
                          f"protocol 'ap_ascii': allowed [{ap_ascii.MIN_TIMEOUT_S}, 10] (an MCD "
                          '3000 may take 250 ms to answer)')


def _checked_names(names: List[str]) -> List[str]:
    seen = set()
    for name in names:
        if not DEVICE_NAME.match(name):
            raise ConfigError(f"parameter 'devices': name {name!r} is invalid: use a letter "
                              'followed by letters, digits or _ (it becomes a topic name)')
        if name in seen:
            raise ConfigError(f"parameter 'devices': name {name!r} is listed twice")
        seen.add(name)
    return names


def build_device(name: str, values: Dict[str, Any], protocol: str) -> DeviceConfig:
    """Validate one device block."""
    family_name = values.get('family')
    family = FAMILIES[check_value(DEVICE_SETTING['family'], family_name, f'{name}.family')]
    checked = {}
    for setting in device_settings(family.name):
        checked[setting.name] = check_value(
            setting, values.get(setting.name, setting.default), f'{name}.{setting.name}')
    for key in values:
        setting = DEVICE_SETTING.get(key)
        if setting is not None and setting.families and family.name not in setting.families \
                and values[key] != setting.default:
            raise ConfigError(f'parameter {name + "." + key!r} applies to families '
                              f'{", ".join(setting.families)} only, not {family.name}')
    if checked['model'] not in family.models:
        hint = ' (this family cannot report its model: name it)' \
            if checked['model'] == 'auto' else ''
        raise ConfigError(f'parameter {name + ".model"!r} = {checked["model"]!r} is invalid '
                          f'for family {family.name}{hint}: allowed {", ".join(family.models)}')
    low, high = family.address_range
    if not low <= checked['address'] <= high:
        raise ConfigError(f'parameter {name + ".address"!r} = {checked["address"]} is out of '
                          f'range for family {family.name}: allowed {low}-{high}')
    if protocol not in family.protocols:
        raise ConfigError(f'device {name!r} (family {family.name}) cannot run on protocol '
                          f'{protocol!r}: allowed {", ".join(family.protocols)}')
    device = DeviceConfig(name=name, protocol=protocol, **checked)
    try:
        device.make_spec()  # the profile checks what the tables alone cannot
    except ConfigError as error:
        raise ConfigError(f'device {name!r}: {error}') from None
    return device


def device_settings(family: str) -> Tuple[Setting, ...]:
    """Return the settings a device of ``family`` takes (drives and lvsg have a few more)."""
    return tuple(setting for setting in DEVICE_SETTINGS
                 if not setting.families or family in setting.families)


def _check_unique_addresses(devices: List[DeviceConfig]) -> None:
    """One device an address; LVSG slaves share their gateway's, one input area each."""
    by_key: Dict[tuple, str] = {}
    for device in devices:
        lvsg_slave = device.family == 'lvsg'
        key = (device.address, device.gateway_input_register) if lvsg_slave else \
            (device.address,)
        other = by_key.setdefault(key, device.name)
        if other != device.name:
            where = f' and gateway_input_register {key[1]}' if len(key) > 1 else ''
            raise ConfigError(f'parameter {device.name + ".address"!r} = {device.address}'
                              f'{where} is also the address of {other!r}: addresses must be '
                              'unique')


def check_params_files(argv: List[str]) -> None:
    """
    Raise ConfigError, in one line, for a ``--params-file`` that is missing or not YAML.

    rcl would refuse it too, with a traceback and a parser location; this says which file
    and why, before anything starts.
    """
    import yaml  # pyyaml: with every ROS install
    for position, argument in enumerate(argv):
        if argument != '--params-file' or position + 1 >= len(argv):
            continue
        path = argv[position + 1]
        try:
            with open(path) as stream:
                content = yaml.safe_load(stream)
        except OSError as error:
            raise ConfigError(f'cannot read the parameters file {path}: '
                              f'{error.strerror}') from None
        except yaml.YAMLError as error:
            where = getattr(error, 'problem_mark', None)
            line = f' at line {where.line + 1}' if where is not None else ''
            raise ConfigError(f'the parameters file {path} is not valid YAML{line}: '
                              f'{getattr(error, "problem", None) or error}') from None
        if not isinstance(content, dict) or not all(
                isinstance(block, dict) and isinstance(block.get('ros__parameters'), dict)
                for block in content.values()):
            raise ConfigError(f'the parameters file {path} must map a node name (such as '
                              '/**/drive_bridge) to a ros__parameters block')


def write_params_file(path: str, bus: Dict[str, Any], devices: Dict[str, Dict[str, Any]],
                      node_key: str = '/**/drive_bridge') -> str:
    """
    Write a node parameters file (bus settings, ``devices`` and one block per device).

    Every string is quoted, as ROS's YAML parser needs (an unquoted N is false there).
    """
    import yaml

    class QuotingDumper(yaml.SafeDumper):
        """Quote every string."""

    QuotingDumper.add_representer(
        str, lambda dumper, value: dumper.represent_scalar('tag:yaml.org,2002:str', value,
                                                           style="'"))
    parameters = dict(bus, devices=list(devices), **devices)
    with open(path, 'w') as stream:
        yaml.dump({node_key: {'ros__parameters': parameters}}, stream, Dumper=QuotingDumper,
                  sort_keys=False)
    return str(path)
