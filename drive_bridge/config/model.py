"""
The settings model: every bus and device setting as data, validated into typed objects.

The common settings are here; each protocol (:mod:`drive_bridge.transport.protocols`) and
each device family (:mod:`drive_bridge.devices.registry`) declares its own. The ROS node
declares its parameters from these tables (types, defaults, ranges, text) and the tools use
the same validation, so a bad value gets the same one-line message anywhere, naming the
parameter and the allowed values. What a parameters file holds is read by
:mod:`drive_bridge.config.params_file`; which names the node declares and refuses is
:mod:`drive_bridge.config.node_parameters`.
"""

from dataclasses import dataclass, field, replace
import re
from typing import Any, Dict, List, Mapping, Tuple

from drive_bridge.bus.keepalive import keepalive_gap, KeepaliveGap, LineTimes, PollLoad
from drive_bridge.bus.master import BusTiming, DeviceSpec
from drive_bridge.devices.contracts import Family
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.errors import ConfigError
from drive_bridge.settings import check_value, Setting
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.line_transport import line_timing
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.protocols import protocol_settings, PROTOCOLS
from drive_bridge.transport.wire_trace import trace_format, TraceSettings

GUARD_DEFAULTS = ', '.join(f'{name} {spec.reply_guard_s:g} s' for name, spec in PROTOCOLS.items()
                           if spec.reply_guard_s)
BAUDRATES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)
PARITIES = ('N', 'E', 'O')
DEVICE_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*')
MAX_DEVICE_NAME = 64

BUS_SETTINGS: Tuple[Setting, ...] = (
    Setting('protocol', str, 'modbus_rtu', 'bus protocol', choices=tuple(PROTOCOLS)),
    Setting('port', str, '/dev/ttyUSB0', 'serial device (serial protocols)'),
    Setting('host', str, '127.0.0.1', 'gateway host (TCP protocols)'),
    Setting('tcp_port', int, 502, 'gateway TCP port', low=1, high=65535),
    Setting('baudrate', int, 9600, 'serial baud rate', choices=BAUDRATES),
    Setting('parity', str, 'E', 'serial parity (quote "N" in YAML)', choices=PARITIES),
    Setting('stopbits', int, 0, "0 = the protocol's standard: Modbus RTU 2 with no parity, 1 "
            'with parity; FC protocol and AP ASCII 1', choices=(0, 1, 2)),
    Setting('timeout', float, 0.5, 'seconds per transaction', low=0.02, high=10.0),
    Setting('retries', int, 2, 'retries of a read (commands are never repeated)',
            low=0, high=10),
    Setting('devices', list, None, 'device names; each has a block <name>.*'),
    Setting('offline_after', int, 3,
            'failed transactions (or refused polls) in a row before a device is reported '
            'offline (or unknown)', low=1, high=100),
    Setting('backoff_max', float, 10.0,
            'longest pause in seconds between probes of an offline device or link',
            low=0.5, high=600.0),
    Setting('frame_gap', float, 0.0,
            "pause in seconds between transactions; 0 = the protocol's own: 3.5 characters "
            'on Modbus RTU and AP ASCII, 2 on the FC protocol, none on TCP',
            low=0.0, high=1.0),
    Setting('late_reply_guard', float, 0.0,
            'seconds after a failed transaction during which the line is quarantined: late '
            'replies are read, counted and discarded before the next request; 0 = the '
            f"protocol's own: {GUARD_DEFAULTS} (Modbus TCP has transaction ids and needs none)",
            low=0.0, high=10.0),
    Setting('local_echo', bool, False, 'the RS-485 adapter echoes what it sends'),
    Setting('diagnostics_period', float, 1.0, 'seconds between /diagnostics messages',
            low=0.1, high=60.0),
    Setting('command_deadline', float, 2.0,
            'seconds a command may wait for the bus; one not on the wire by then is dropped, '
            'answered as failed and never sent', low=0.1, high=30.0),
    Setting('wire_trace', str, '',
            'file to trace every frame of the bus to, both ways with times and outcomes: '
            'a .pcapng file (Wireshark) or .txt / .log (text, one line a frame); empty = off'),
    Setting('wire_trace_max_mb', float, 10.0,
            'megabytes a wire trace file may reach before it is renamed <name>.1.<ext> and a '
            'new one begins', low=0.01, high=100000.0),
    Setting('wire_trace_files', int, 5,
            'wire trace files kept, the current one included (the oldest is dropped)',
            low=1, high=1000),
) + protocol_settings()

COMMON_DEVICE_SETTINGS: Tuple[Setting, ...] = (
    Setting('family', str, None, 'device family', choices=tuple(FAMILIES)),
    Setting('model', str, 'auto', 'device model; auto reads it from the device'),
    Setting('address', int, None, 'bus address', low=1, high=247),
    Setting('poll_rate', float, 5.0, 'polls per second', low=0.1, high=100.0, runtime=True),
    Setting('allow_control', bool, True,
            'false: monitor only, nothing at all is written to the device', runtime=True),
    Setting('stop_on_shutdown', bool, True,
            'shutdown and deactivate stop the motors that may run because of this node',
            runtime=True),
    Setting('current_scale', float, 1.0,
            'factor on the reported current (MCD5-0068B and smaller: 0.1)',
            low=0.001, high=1000.0),
)
# Every family takes these; they go to the profile with the family's own settings.
PROFILE_SETTINGS: Tuple[Setting, ...] = (
    Setting('readout_period', float, 1.0,
            'seconds between two polls that read the slow readouts (FC: frequency, thermal '
            'load and status words in turn; MCD: product and protocol registers 40007-40008, '
            'the trip code over AP ASCII; LVSG: operating parameters 1-2); the fast values '
            '(status, current, speed) are read every poll; 0 = every poll',
            low=0.0, high=3600.0),
)
# Families that take a speed reference (drives) take these too: the reference and its
# deadman, and the ros2_control joint settings (~/joint_states, ~/joint_commands: see
# drive_bridge.ros.node.joints).
SPEED_REFERENCE_SETTINGS: Tuple[Setting, ...] = (
    Setting('speed_reference', float, 0.0,
            'drives: the bus speed reference in percent (FC scaling, 0x4000 = 100 %; negative '
            '= reverse); it goes out with the next process-data write',
            low=-200.0, high=200.0, high_open=True, runtime=True),
    Setting('reference_timeout', float, 0.0,
            'drives: seconds without a speed_reference message before a ramp stop; 0 = off',
            low=0.0, high=3600.0, runtime=True),
)
JOINT_SETTINGS: Tuple[Setting, ...] = (
    Setting('velocity_scale', float, 0.0,
            'drives: rad/s of the joint at 100 % reference (negative: the joint turns the '
            'other way); 0 = not a joint', low=-10000.0, high=10000.0),
    Setting('joint_name', str, '',
            'drives: the joint name on ~/joint_states and ~/joint_commands; empty = the device '
            'name'),
    Setting('command_mode', str, 'reference',
            'drives: reference = joint commands set the speed reference only; auto_start = a '
            'nonzero command also starts the stopped drive, a zero one held auto_stop_delay '
            'stops it', choices=('reference', 'auto_start'), runtime=True),
    Setting('auto_stop_delay', float, 1.0,
            'drives: seconds a zero joint command is held before command_mode auto_start '
            'ramp-stops the drive', low=0.0, high=3600.0, runtime=True),
)
REFERENCE_SETTINGS: Tuple[Setting, ...] = SPEED_REFERENCE_SETTINGS + JOINT_SETTINGS
# The node's own settings (not the bus's): a parameters file may hold them; declared by
# drive_bridge.ros.node.parameters.
NODE_SETTINGS: Tuple[Setting, ...] = (
    Setting('autostart', bool, True,
            'walk the lifecycle to active at start (false: wait for configure and activate)'),
    Setting('allow_runtime_control_enable', bool, True,
            'false: allow_control cannot be switched on with ros2 param set (a site can '
            'forbid other processes to enable control)'),
)
JOINT_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_./-]*')
MAX_JOINT_NAME = 128


def device_settings(family: Family) -> Tuple[Setting, ...]:
    """Return every setting a device of ``family`` takes."""
    return COMMON_DEVICE_SETTINGS + PROFILE_SETTINGS + \
        (REFERENCE_SETTINGS if family.reference else ()) + tuple(family.settings)


def all_device_settings() -> Dict[str, Setting]:
    """Return every device setting of any family, by name."""
    settings = {setting.name: setting
                for setting in COMMON_DEVICE_SETTINGS + PROFILE_SETTINGS + REFERENCE_SETTINGS}
    for family in FAMILIES.values():
        for setting in family.settings:
            settings.setdefault(setting.name, setting)
    return settings


def families_taking(name: str) -> List[str]:
    """Return the families that take device setting ``name``."""
    return [family.name for family in FAMILIES.values()
            if any(setting.name == name for setting in device_settings(family))]


@dataclass
class DeviceConfig:
    """One validated device block: the common settings, and the family's by name."""

    name: str
    family: str
    model: str
    address: int
    poll_rate: float
    allow_control: bool
    stop_on_shutdown: bool
    current_scale: float
    protocol: str = 'modbus_rtu'
    options: Dict[str, Any] = field(default_factory=dict)

    @property
    def entry(self) -> Family:
        """Return the device's family entry."""
        return FAMILIES[self.family]

    @property
    def is_drive(self) -> bool:
        """Return whether the device takes a speed reference (FC-profile drives)."""
        return self.entry.reference

    @property
    def is_joint(self) -> bool:
        """Return whether the device is a ros2_control joint (a drive with a velocity_scale)."""
        return self.is_drive and bool(self.option('velocity_scale'))

    def option(self, name: str, default: Any = None) -> Any:
        """Return a family or reference setting by name."""
        return self.options.get(name, default)

    def make_spec(self) -> DeviceSpec:
        """Return the bus's view of this device, with a new profile."""
        options = dict(self.options, current_scale=self.current_scale)
        profile = self.entry.make_profile(self.model, self.protocol, options)
        return DeviceSpec(self.name, self.address, profile, self.poll_rate,
                          self.allow_control, self.stop_on_shutdown,
                          self.option('reference_timeout', 0.0),
                          self.option('speed_reference', 0.0))


@dataclass
class BridgeConfig:
    """A validated bus with its devices."""

    link: LinkSettings
    timing: BusTiming
    devices: List[DeviceConfig] = field(default_factory=list)
    diagnostics_period_s: float = 1.0
    protocol_options: Dict[str, Any] = field(default_factory=dict)
    trace: TraceSettings = field(default_factory=TraceSettings)

    def make_transport(self):
        """Return the transport of this bus (tracing the wire if ``wire_trace`` is set)."""
        return make_transport(self.link, self.protocol_options, self.trace)

    def device(self, name: str) -> DeviceConfig:
        """Return the device called ``name``; raise ConfigError naming the ones there are."""
        for device in self.devices:
            if device.name == name:
                return device
        raise ConfigError(f'no device {name!r} on this bus: it has '
                          f'{", ".join(d.name for d in self.devices)}')


def build_config(bus_values: Mapping[str, Any],
                 device_values: Mapping[str, Mapping[str, Any]]) -> BridgeConfig:
    """Validate raw values (name -> value; devices: name -> {setting -> value})."""
    check_bus_keys(bus_values)
    bus = {setting.name: check_value(setting, bus_values.get(setting.name, setting.default),
                                     setting.name)
           for setting in BUS_SETTINGS}
    spec = PROTOCOLS[bus['protocol']]
    _check_framing(bus, spec)
    names = check_device_names(bus['devices'])
    devices = [build_device(name, device_values.get(name, {}), bus['protocol'])
               for name in names]
    options = {setting.name: bus[setting.name] for setting in spec.settings}
    _check_protocol_addresses(devices, spec, options)
    _check_unique_addresses(devices)
    check_unique_joints(devices)
    link = LinkSettings(
        protocol=bus['protocol'], port=bus['port'], host=bus['host'],
        tcp_port=bus['tcp_port'], baudrate=bus['baudrate'], parity=bus['parity'],
        stopbits=bus['stopbits'], timeout_s=bus['timeout'], local_echo=bus['local_echo'],
        reply_guard_s=bus['late_reply_guard'])
    gap = bus['frame_gap'] or link.frame_gap_s
    timing = BusTiming(retries=bus['retries'], offline_after=bus['offline_after'],
                       backoff_initial_s=min(1.0, bus['backoff_max']),
                       backoff_max_s=bus['backoff_max'], frame_gap_s=gap,
                       command_deadline_s=bus['command_deadline'],
                       transaction_timeout_s=bus['timeout'],
                       slow_reply_s=bus['timeout'] / 2)
    config = BridgeConfig(link, timing, devices, bus['diagnostics_period'], options,
                          _trace_settings(bus))
    check_comms_timeouts(config)
    return config


# -- the keepalive rule: a drive's comms_timeout against the line's schedule --------------
def line_times(link: LinkSettings, timing: BusTiming) -> LineTimes:
    """Return how long one answered and one failed transaction keep the line busy."""
    line = line_timing(link, paced=False)
    spec = PROTOCOLS[link.protocol]
    gap_s = timing.frame_gap_s
    answered_s = spec.poll_frame_chars * line.char_s + 2 * max(gap_s, line.gap_s) + \
        spec.reply_delay_s
    failed_s = line.timeout_s + line.guard_s + line.quarantine_silence_s + gap_s
    return LineTimes(answered_s, failed_s, timing.retries, timing.offline_after)


def keepalive_gaps(config: BridgeConfig) -> Dict[str, KeepaliveGap]:
    """Return, per drive with a ``comms_timeout``, the longest gap between two of its polls."""
    loads = []
    for device in config.devices:
        shape = device.make_spec().profile.poll_shape()
        loads.append(PollLoad(device.name, 1.0 / device.poll_rate, shape.transactions,
                              shape.writes, shape.online))
    times = line_times(config.link, config.timing)
    return {device.name: keepalive_gap(device.name, loads, times) for device in config.devices
            if device.option('comms_timeout', 0.0) > 0}


def check_poll_rate_changes(config: BridgeConfig, poll_rates: Mapping[str, float]) -> None:
    """
    Refuse runtime poll rates (device -> Hz) under which a drive's comms_timeout could trip.

    The keepalive rule (:func:`check_comms_timeouts`) holds at configure; a slower poll at
    runtime stretches the gap between a drive's control words just as a short timeout does.
    """
    if not poll_rates:
        return
    changed = [replace(device, poll_rate=poll_rates.get(device.name, device.poll_rate))
               for device in config.devices]
    try:
        check_comms_timeouts(replace(config, devices=changed))
    except ConfigError as error:
        raise ConfigError(f'poll_rate not changed: {error}') from None


def check_comms_timeouts(config: BridgeConfig) -> None:
    """Refuse a drive's ``comms_timeout`` shorter than the longest gap between its polls."""
    for name, gap in keepalive_gaps(config).items():
        device = config.device(name)
        timeout_s = device.option('comms_timeout')
        if timeout_s < gap.gap_s:
            times = line_times(config.link, config.timing).describe()
            raise ConfigError(
                f'{name}.comms_timeout {timeout_s:g} s is below {gap.gap_s:.2f} s, the longest '
                f'the bus may go without writing to {name} (address {device.address}) while '
                f'the line works: {gap.explain()} ({times}): set comms_timeout to at least '
                f'{gap.advised_s:g} s (a margin of 1 s), or raise poll_rate, lower timeout or '
                "retries, or lower the other devices' poll_rate")


def _trace_settings(bus: Mapping[str, Any]) -> TraceSettings:
    """Return the wire trace settings; refuse a file name of no known format."""
    trace = TraceSettings(bus['wire_trace'], bus['wire_trace_max_mb'], bus['wire_trace_files'])
    if trace.enabled:
        try:
            trace_format(trace.path)
        except ConfigError as error:
            raise ConfigError(f"parameter 'wire_trace': {error}") from None
    return trace


def check_bus_keys(bus_values: Mapping[str, Any]) -> None:
    """Refuse a protocol's own setting given (other than its default) for another protocol."""
    protocol = bus_values.get('protocol', 'modbus_rtu')
    if protocol not in PROTOCOLS:
        return  # check_value names the allowed protocols
    own = {setting.name for setting in PROTOCOLS[protocol].settings}
    for name, spec in PROTOCOLS.items():
        for setting in spec.settings:
            if setting.name in bus_values and setting.name not in own and \
                    bus_values[setting.name] != setting.default:
                raise ConfigError(f'parameter {setting.name!r} applies to protocol {name} '
                                  f'only, not {protocol}')


def _check_framing(bus: Dict[str, Any], spec) -> None:
    """Check a protocol's fixed framing (AP ASCII: 8N1) and its minimum timeout."""
    if spec.fixed_framing:
        parity, stopbits = spec.fixed_framing
        if bus['parity'] != parity or bus['stopbits'] not in (0, stopbits):
            raise ConfigError(
                f'parameter \'parity\' = {bus["parity"]!r}, \'stopbits\' = {bus["stopbits"]} '
                f'do not fit protocol {spec.name!r}: it is 8{parity}{stopbits}, set parity: '
                f'"{parity}" and stopbits: 0 or {stopbits}')
    if bus['timeout'] < spec.min_timeout_s:
        raise ConfigError(f'parameter \'timeout\' = {bus["timeout"]} is too short for '
                          f'protocol {spec.name!r}: allowed [{spec.min_timeout_s}, 10]')


def check_device_name(name: Any) -> str:
    """Return ``name`` if it can name a device (it becomes a topic name), else raise."""
    if not isinstance(name, str) or not DEVICE_NAME.fullmatch(name) or \
            len(name) > MAX_DEVICE_NAME:
        raise ConfigError(f"parameter 'devices': device name {name!r} is invalid: use a letter "
                          f'followed by letters, digits or _, at most {MAX_DEVICE_NAME} '
                          'characters (it becomes a topic name)')
    return name


def check_device_names(names: List[str]) -> List[str]:
    """Return the device names if they are valid and unique, else raise ConfigError."""
    if not names:
        raise ConfigError("parameter 'devices' is empty: list at least one device name")
    seen = set()
    for name in names:
        check_device_name(name)
        if name in seen:
            raise ConfigError(f"parameter 'devices': name {name!r} is listed twice")
        seen.add(name)
    return names


def build_device(name: str, values: Mapping[str, Any], protocol: str) -> DeviceConfig:
    """Validate one device block."""
    family = FAMILIES[check_value(COMMON_DEVICE_SETTINGS[0], values.get('family'),
                                  f'{name}.family')]
    settings = device_settings(family)
    known = {setting.name for setting in settings}
    for key in values:
        if key not in known:
            owners = families_taking(key)
            if owners:
                raise ConfigError(f'parameter {name + "." + key!r} applies to families '
                                  f'{", ".join(owners)} only, not {family.name}')
            raise ConfigError(f'unknown parameter {name + "." + key!r}: a {family.name} device '
                              f'takes {", ".join(sorted(known))}')
    checked = {setting.name: check_value(setting, values.get(setting.name, setting.default),
                                         f'{name}.{setting.name}')
               for setting in settings}
    if checked['model'] not in family.models:
        hint = ' (this family cannot report its model: name it)' \
            if checked['model'] == 'auto' else ''
        raise ConfigError(f'parameter {name + ".model"!r} = {checked["model"]!r} is invalid '
                          f'for family {family.name}{hint}: allowed {", ".join(family.models)}')
    low, high = family.address_range
    if not low <= checked['address'] <= high:
        raise ConfigError(f'parameter {name + ".address"!r} = {checked["address"]} is out of '
                          f'range for family {family.name}: allowed {low}-{high}')
    _check_model_address(name, family, checked)
    if protocol not in family.protocols:
        raise ConfigError(f'device {name!r} (family {family.name}) cannot run on protocol '
                          f'{protocol!r}: allowed {", ".join(family.protocols)}')
    if family.reference and not checked['allow_control'] and checked['speed_reference']:
        raise ConfigError(f'parameter {name + ".speed_reference"!r} = '
                          f'{checked["speed_reference"]} is refused: a monitor-only drive '
                          '(allow_control false) takes no speed reference; set it to 0')
    if family.reference:
        _check_joint(name, checked)
    common = {setting.name for setting in COMMON_DEVICE_SETTINGS}
    device = DeviceConfig(
        name=name, family=family.name, model=checked['model'], address=checked['address'],
        poll_rate=checked['poll_rate'], allow_control=checked['allow_control'],
        stop_on_shutdown=checked['stop_on_shutdown'], current_scale=checked['current_scale'],
        protocol=protocol,
        options={key: value for key, value in checked.items() if key not in common})
    try:
        device.make_spec()  # the profile checks what the tables alone cannot
    except ConfigError as error:
        raise ConfigError(f'device {name!r}: {error}') from None
    return device


def _check_joint(name: str, checked: Mapping[str, Any]) -> None:
    """Check a drive's joint settings (ros2_control): a valid name, auto_start only if usable."""
    joint = checked['joint_name']
    if joint and (not JOINT_NAME.fullmatch(joint) or len(joint) > MAX_JOINT_NAME):
        raise ConfigError(f'parameter {name + ".joint_name"!r} = {joint!r} is invalid: use a '
                          'letter or _ followed by letters, digits, _, -, . or /, at most '
                          f'{MAX_JOINT_NAME} characters')
    if checked['velocity_scale'] == 0.0:
        for key, default in (('joint_name', ''), ('command_mode', 'reference')):
            if checked[key] != default:
                raise ConfigError(f'parameter {name + "." + key!r} = {checked[key]!r} applies '
                                  f'to joints only: set {name}.velocity_scale (rad/s at 100 %) '
                                  'too, or leave it out')
    if checked['command_mode'] == 'auto_start' and not checked['allow_control']:
        raise ConfigError(f'parameter {name + ".command_mode"!r} = \'auto_start\' is refused: '
                          'a monitor-only drive (allow_control false) is never started; use '
                          'reference')


def joint_name_of(device: 'DeviceConfig') -> str:
    """Return the joint name of a drive (its device name unless joint_name is set)."""
    return device.option('joint_name') or device.name


def check_unique_joints(devices: List['DeviceConfig']) -> None:
    """Refuse two joints of one node with the same joint name."""
    seen: Dict[str, str] = {}
    for device in devices:
        if not device.option('velocity_scale'):
            continue
        joint = joint_name_of(device)
        other = seen.setdefault(joint, device.name)
        if other != device.name:
            raise ConfigError(f'parameter {device.name + ".joint_name"!r}: joint name {joint!r} '
                              f'is also the joint of {other!r}: joint names must be unique '
                              'across the node')


def _check_protocol_addresses(devices: List[DeviceConfig], spec, options: Dict[str, Any]) \
        -> None:
    """Refuse an address the protocol cannot carry (FC protocol: 1-126, or 1-31)."""
    if spec.address_range is None:
        return
    low, high = spec.address_range(options)
    for device in devices:
        if not low <= device.address <= high:
            raise ConfigError(f'parameter {device.name + ".address"!r} = {device.address} is '
                              f'out of range for protocol {spec.name!r}'
                              + (f' ({options})' if options else '') + f': allowed {low}-{high}')


def _check_model_address(name: str, family, checked: Mapping[str, Any]) -> None:
    """Refuse an address outside what sets it on this model (MCD: the module's switches)."""
    if family.model_address_range is None:
        return
    low, high, where = family.model_address_range(checked['model'], checked)
    if not low <= checked['address'] <= high:
        raise ConfigError(f'parameter {name + ".address"!r} = {checked["address"]} is out of '
                          f'range: {where}')


def _check_unique_addresses(devices: List[DeviceConfig]) -> None:
    """One device an address; LVSG slaves share their gateway's, one input area each."""
    by_key: Dict[tuple, str] = {}
    for device in devices:
        area = device.option('gateway_input_register')
        key = (device.address, area) if area is not None else (device.address,)
        other = by_key.setdefault(key, device.name)
        if other != device.name:
            where = f' and gateway_input_register {key[1]}' if len(key) > 1 else ''
            raise ConfigError(f'parameter {device.name + ".address"!r} = {device.address}'
                              f'{where} is also the address of {other!r}: addresses must be '
                              'unique')
