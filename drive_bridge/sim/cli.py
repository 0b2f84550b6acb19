"""
``drive_bridge_sim``: simulated devices on a pty or a TCP port, for tests and commissioning.

Examples::

    drive_bridge_sim --device mcd500:20 --link /tmp/ttyMCD     # RTU on a pty, 8N2
    drive_bridge_sim --device mcd500:20 --device mcd202:21 --tcp 5020 --framing rtu
    drive_bridge_sim --device fc51:1 --device mcd500:20 --link /tmp/ttyLINE
    drive_bridge_sim --protocol ap_ascii --device mcd500:20 --device mcd3000:21
    drive_bridge_sim --lvsg mcd202:0:100 --lvsg mcd201:10:110:basic --no-pty --tcp 5020
    drive_bridge_sim --device mcd500:20 --pace 19200:E:1 --link /tmp/ttyMCD  # a paced wire

With ``--console`` (default when standard input is a terminal) it reads commands:
``trip ADDR CODE`` (MCD trip code; FC: alarm word bit, 5 = over current), ``hand ADDR
on|off`` (MCD Hand On; FC local operation), ``silent ADDR on|off``, ``fault ADDR KIND
[COUNT]`` (the next replies; Modbus: crc, no_reply, slow, exception, garbage, truncated,
wrong_address, late, late_batched; FC protocol: bcc for crc, no exception; AP ASCII: nak,
bel, silence, garbage, slow, late, late_batched, each as ``KIND`` or ``KIND:address`` for the
address fragment's ACK and ``KIND:message`` for the reply to the message fragment),
``status``, ``quit``.
``--faults RATE[:KIND,...]`` with ``--fault-seed N`` injects random faults into that share of
all replies, reproducibly. A ``late`` reply comes ``--master-timeout`` (the bridge's
``timeout``, 0.5 s) plus ``--fault-late`` (0.02 s) after its request, a ``late_batched`` one
just before the reply to the next request on its connection; the device executes the request
either way. ``--pace BAUD[:PARITY[:STOPBITS]]`` puts a wire pacer
(:mod:`drive_bridge.sim.wire_pacer`) in front of the pty: every byte takes its wire time at
that timing, the line is half duplex and, for Modbus, every frame must follow 3.5 characters
of silence; the pty path printed (and ``--link``) is then the pacer's.
"""

import argparse
import signal
import sys
import threading
import time
from typing import Dict, List, Optional

from drive_bridge.console import OneLineParser, plain_text
from drive_bridge.devices import mcd
from drive_bridge.errors import ConfigError
from drive_bridge.sim.adapter import AdapterBehaviour, AdapterRelay, parse_device_line, \
    SerialSetting
from drive_bridge.sim.ap_ascii_server import ApAsciiSimServer
from drive_bridge.sim.devices import make_device, SIM_MODELS
from drive_bridge.sim.faults import FaultPlan, parse_fault_plan
from drive_bridge.sim.fc_profile_model import FcProfileModel
from drive_bridge.sim.fc_protocol_device import FcProtocolDevice
from drive_bridge.sim.fc_protocol_server import FcProtocolSimServer
from drive_bridge.sim.lvsg_gateway import make_lvsg_gateway
from drive_bridge.sim.modbus_server import ModbusSimServer, WireTiming
from drive_bridge.sim.wire_pacer import LineTiming, MASTER, SLAVE, WirePacer
from drive_bridge.sim.wire_tap import WireTap
from drive_bridge.transport.wire_trace import TraceSettings, WireTrace


def parse_device(text: str) -> tuple:
    """Parse ``MODEL:ADDRESS`` into (model, address)."""
    model, _, address = text.partition(':')
    if model not in SIM_MODELS:
        raise argparse.ArgumentTypeError(
            f'unknown model {model!r}: allowed {", ".join(SIM_MODELS)}')
    try:
        unit = int(address)
    except ValueError:
        raise argparse.ArgumentTypeError(f'address in {text!r} must be a number') from None
    if not 1 <= unit <= 247:
        raise argparse.ArgumentTypeError(f'address {unit} is out of range 1-247')
    return model, unit


def parse_lvsg(text: str) -> tuple:
    """Parse ``MODEL:IN:OUT[:basic]`` into (input register, (model, output register, module))."""
    parts = text.split(':')
    if len(parts) not in (3, 4) or parts[0] not in ('mcd201', 'mcd202') or \
            not all(part.isdigit() for part in parts[1:3]) or parts[3:] not in ([], ['basic']):
        raise argparse.ArgumentTypeError(
            f'{text!r}: give MODEL:IN:OUT[:basic], MODEL mcd201 or mcd202, IN and OUT register '
            'numbers (frame addresses)')
    return int(parts[1]), (parts[0], int(parts[2]), 'basic' if parts[3:] else 'extended')


def non_negative_seconds(text: str) -> float:
    """Parse a time in seconds that must not be negative (an option's type)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number of seconds') from None
    if not value >= 0 or value == float('inf'):  # NaN and inf too
        raise argparse.ArgumentTypeError(f'{text!r}: give seconds, 0 or more')
    return value


def device_line(text: str) -> SerialSetting:
    """Parse ``--device-line`` (an option's type)."""
    try:
        return parse_device_line(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser."""
    parser = OneLineParser(prog='drive_bridge_sim',
                           description=plain_text(__doc__.strip().split('\n')[0]))
    parser.add_argument('--device', action='append', type=parse_device, default=[],
                        metavar='MODEL:ADDRESS', help=f'models: {", ".join(SIM_MODELS)}')
    parser.add_argument('--lvsg', action='append', type=parse_lvsg, default=[],
                        metavar='MODEL:IN:OUT[:basic]',
                        help='an MCD 200 (mcd201, mcd202) with the Profibus Module behind a '
                             'Modbus gateway at unit 1: input and output image registers')
    parser.add_argument('--protocol', choices=('modbus', 'ap_ascii', 'fc_protocol'),
                        default='modbus',
                        help='ap_ascii: MCD starters on an AP ASCII line (pty only); '
                             'fc_protocol: drives (fc51, vlt5000, vlt6000) on the Danfoss FC '
                             'protocol')
    parser.add_argument('--link', default='', help='symlink to create for the pty')
    parser.add_argument('--no-pty', action='store_true', help='do not open a pty')
    parser.add_argument('--tcp', type=int, default=None, metavar='PORT',
                        help='also listen on this TCP port (0 = any free port)')
    parser.add_argument('--host', default='127.0.0.1', help='TCP address to listen on')
    parser.add_argument('--framing', choices=('mbap', 'rtu'), default='mbap',
                        help='TCP framing: mbap = Modbus TCP, rtu = RTU over TCP')
    parser.add_argument('--wire-baud', type=int, default=0,
                        help='hold replies back to the wire time at this baud rate')
    parser.add_argument('--wire-parity', choices=('N', 'E', 'O'), default='E')
    parser.add_argument('--pace', default='', metavar='BAUD[:PARITY[:STOPBITS]]',
                        help='put a wire pacer with this timing in front of the pty (parity '
                             'E, or N for AP ASCII; Modbus RTU gap rule for Modbus)')
    adapter = parser.add_argument_group(
        'adapter and line (a relay in front of the pty, after --pace; drive_bridge.sim.adapter)')
    adapter.add_argument('--echo', action='store_true',
                         help='the adapter echoes what the master sends (local_echo: true)')
    adapter.add_argument('--usb-latency', type=non_negative_seconds, default=0.0,
                         metavar='MS', help='bytes reach the master in batches every MS '
                         'milliseconds (an FTDI latency timer: 16)')
    adapter.add_argument('--babble', type=non_negative_seconds, default=0.0,
                         metavar='BYTES_PER_S', help='noise bytes reach the master at this '
                         'mean rate (seed: --fault-seed)')
    adapter.add_argument('--device-line', type=device_line, default=None,
                         metavar='BAUD[:PARITY[:STOPBITS]]',
                         help="the devices' baud rate and stop bits: nothing crosses while the "
                         "master's port is set otherwise (a pty shows no parity: it counts "
                         'through its stop bits, 2 for N, else 1)')
    parser.add_argument('--start-time', type=float, default=3.0, help='MCD soft start, s')
    parser.add_argument('--stop-time', type=float, default=2.0, help='MCD soft stop, s')
    parser.add_argument('--flc', type=float, default=100.0, help='MCD motor FLC, amperes')
    parser.add_argument('--ramp-up', type=float, default=3.0, help='FC par. 3-41, seconds')
    parser.add_argument('--ramp-down', type=float, default=3.0, help='FC par. 3-42, seconds')
    parser.add_argument('--hand-on', type=int, action='append', default=[], metavar='ADDR',
                        help='start this device in Hand On mode (MCD) or local operation (FC)')
    parser.add_argument('--trip', action='append', default=[], metavar='ADDR:CODE',
                        help='start this device tripped: MCD trip code, FC alarm word bit')
    parser.add_argument('--console', action='store_true', default=None,
                        help='read commands from standard input')
    parser.add_argument('--faults', default='', metavar='RATE[:KIND,...]',
                        help='inject random faults into this share of replies, e.g. 0.1 or '
                             '0.05:crc,no_reply (kinds: see drive_bridge.sim.faults)')
    parser.add_argument('--fault-seed', type=int, default=1, help='seed of --faults')
    parser.add_argument('--fault-slow', type=non_negative_seconds, default=0.1,
                        help="delay of a 'slow' reply, seconds (keep it under the timeout)")
    parser.add_argument('--fault-late', type=non_negative_seconds, default=0.02,
                        metavar='SECONDS',
                        help="a 'late' reply comes this long after the master's timeout")
    parser.add_argument('--master-timeout', type=non_negative_seconds, default=0.5,
                        metavar='SECONDS',
                        help="the master's timeout (the bridge's 'timeout'), for 'late' "
                             'replies')
    parser.add_argument('--wire-trace', default='', metavar='FILE',
                        help='write every request read and reply written to FILE, a '
                             '.pcapng (Wireshark) or .txt / .log (text); see docs/wire_trace.md')
    return parser


TRACE_PROTOCOLS = {'modbus': 'modbus_rtu', 'ap_ascii': 'ap_ascii', 'fc_protocol': 'fc_protocol'}


def wire_tap(server, args: argparse.Namespace) -> Optional[WireTap]:
    """Return the WireTap of ``--wire-trace`` set on ``server`` (before its endpoints), or None."""
    if not args.wire_trace:
        return None
    try:
        trace = WireTrace(TraceSettings(args.wire_trace), args.link or 'sim',
                          TRACE_PROTOCOLS[args.protocol], server_side=True)
    except ConfigError as error:
        raise SystemExit(f'drive_bridge_sim: --wire-trace: {error}') from None
    tap = WireTap(trace)
    if isinstance(server, ApAsciiSimServer):
        server.tap = tap
    else:
        server.line.tap = tap
    return tap


def parse_pace(text: str, protocol: str = 'modbus') -> LineTiming:
    """Parse ``BAUD[:PARITY[:STOPBITS]]`` into the pacer's timing for ``protocol``."""
    parts = text.split(':')
    ascii_line = protocol == 'ap_ascii'
    try:
        if len(parts) > 3:
            raise ValueError('too many fields')
        baudrate = int(parts[0])
        parity = parts[1] if len(parts) > 1 else ('N' if ascii_line else 'E')
        stopbits = int(parts[2]) if len(parts) > 2 else (
            1 if ascii_line or parity != 'N' else 2)
        return LineTiming(baudrate, parity, stopbits, gap_rule=protocol == 'modbus')
    except ValueError as error:
        raise SystemExit(f'drive_bridge_sim: --pace {text!r}: {error}; give '
                         'BAUD[:PARITY[:STOPBITS]], e.g. 19200:E:1') from None


def build_server(args: argparse.Namespace):
    """Create the devices and the server (Modbus or AP ASCII) from parsed arguments."""
    if args.lvsg:
        if args.device:
            raise SystemExit('drive_bridge_sim: --lvsg (a gateway) and --device do not mix')
        return _with_faults(make_lvsg_gateway(dict(args.lvsg), start_time_s=args.start_time,
                                              stop_time_s=args.stop_time,
                                              motor_flc_a=args.flc), args)
    if not args.device:
        raise SystemExit('drive_bridge_sim: give at least one --device or --lvsg')
    now = time.monotonic()
    settings = {
        'mcd': {'start_time_s': args.start_time, 'stop_time_s': args.stop_time,
                'motor_flc_a': args.flc},
        'fc': {'ramp_up_s': args.ramp_up, 'ramp_down_s': args.ramp_down},
    }
    settings['vlt'] = settings['fc']
    devices: Dict[int, object] = {}
    line = served_line(args)
    for model, unit in args.device:
        if unit in devices:
            raise SystemExit(f'drive_bridge_sim: address {unit} is used twice')
        devices[unit] = make_device(model, now, unit, line, **settings[SIM_MODELS[model]])
    for unit in args.hand_on:
        _set_hand(_device(devices, unit), True)
    for text in args.trip:
        unit, _, code = text.partition(':')
        _device(devices, int(unit)).model.trip(int(code), now)
    if args.protocol == 'ap_ascii':
        if any(SIM_MODELS[model] != 'mcd' for model, _ in args.device) or args.tcp \
                is not None:
            raise SystemExit('drive_bridge_sim: AP ASCII serves MCD models on a pty only')
        server = ApAsciiSimServer({unit: device.model for unit, device in devices.items()})
    elif args.protocol == 'fc_protocol':
        if any(SIM_MODELS[model] not in ('fc', 'vlt') for model, _ in args.device):
            raise SystemExit('drive_bridge_sim: the FC protocol serves drives only (fc51, '
                             'vlt5000, vlt6000)')
        server = FcProtocolSimServer({unit: FcProtocolDevice(device.model)
                                      for unit, device in devices.items()},
                                     wire_baud=args.wire_baud, wire_parity=args.wire_parity)
    else:
        wire = WireTiming(args.wire_baud, args.wire_parity,
                          1 if args.wire_parity != 'N' else 2) if args.wire_baud else None
        server = ModbusSimServer(devices, wire=wire)
    return _with_faults(server, args)


def served_line(args: argparse.Namespace) -> Dict[str, object]:
    """
    Return the line the devices are served on, as a drive reports it (FC 51 par. 8-30..8-33).

    The protocol, and the timing of ``--pace`` or ``--wire-baud``; a pty without either has
    no baud rate of its own: the drives then report their default, 9600 baud 8E1.
    """
    line: Dict[str, object] = {
        'protocol': 'fc_protocol' if args.protocol == 'fc_protocol' else 'modbus_rtu'}
    if args.pace:
        timing = parse_pace(args.pace, args.protocol)
        line.update(baudrate=timing.baudrate, parity=timing.parity, stopbits=timing.stopbits)
    elif args.wire_baud:
        line.update(baudrate=args.wire_baud, parity=args.wire_parity,
                    stopbits=1 if args.wire_parity != 'N' else 2)
    return line


def _with_faults(server, args: argparse.Namespace):
    """Give the server the fault plan of ``--faults`` (none: only its timing); return it."""
    timing = {'slow_s': args.fault_slow, 'late_s': args.fault_late,
              'master_timeout_s': args.master_timeout}
    if not args.faults:  # the console's faults take the timing too
        server.faults.set_plan(FaultPlan(0.0, server.faults.allowed, args.fault_seed,
                                         **timing))
        return server
    try:
        server.faults.set_plan(parse_fault_plan(args.faults, server.faults.allowed,
                                                args.fault_seed, **timing))
    except ValueError as error:
        raise SystemExit(f'drive_bridge_sim: --faults: {error}') from None
    return server


def _set_hand(device, on: bool) -> None:
    if isinstance(_model(device), FcProfileModel):  # over Modbus or the FC protocol
        _model(device).local_mode = on
    else:
        _model(device).hand_on = on


def _device(devices: Dict[int, object], unit: int):
    if unit not in devices:
        raise SystemExit(f'drive_bridge_sim: no device at address {unit}')
    return devices[unit]


CONSOLE_COMMANDS = ('status', 'trip', 'hand', 'silent', 'fault')


def run_console_command(server: ModbusSimServer, line: str) -> str:
    """Carry out one console command; return the answer to print."""
    words = line.split()
    if not words:
        return ''
    try:
        return _console(server, words)
    except (ValueError, IndexError, KeyError) as error:
        return f'error: {error}; commands: trip ADDR CODE, hand ADDR on|off, ' \
               'silent ADDR on|off, fault ADDR KIND[:address|:message] [COUNT], status, quit'


def _console(server: ModbusSimServer, words: List[str]) -> str:
    command = words[0]
    if command not in CONSOLE_COMMANDS:
        raise ValueError(f'unknown command {command!r}')
    now = time.monotonic()
    with server.lock:
        if command == 'status':
            return '\n'.join(_describe(unit, device, now)
                             for unit, device in sorted(server.devices.items()))
        unit = int(words[1])
        device = server.devices[unit]
        if command == 'trip':
            _model(device).trip(int(words[2]), now)
        elif command == 'hand':
            _set_hand(device, words[2] == 'on')
        elif command == 'silent':
            (server.silent_units.add if words[2] == 'on' else server.silent_units.discard)(unit)
        elif command == 'fault':
            _inject(server, unit, words[2], int(words[3]) if len(words) > 3 else 1)
        else:
            raise ValueError(f'unknown command {command!r}')
        return _describe(unit, device, now)


def _inject(server, unit: int, text: str, count: int) -> None:
    """Inject ``KIND`` or, on AP ASCII, ``KIND:address`` / ``KIND:message`` into ``unit``."""
    kind, colon, fragment = text.partition(':')
    if not colon:
        server.faults.inject(unit, kind, count)
    elif isinstance(server, ApAsciiSimServer):
        server.inject(unit, kind, count, fragment)
    else:
        raise ValueError(f'{text!r}: a fragment (:address, :message) is for AP ASCII only')


def _model(device):
    """Return the behaviour model of a simulated device (AP ASCII serves models directly)."""
    return getattr(device, 'model', device)


def _describe(unit: int, device, now: float) -> str:
    model = _model(device)
    model.advance(now)
    if isinstance(model, FcProfileModel):  # over Modbus or the FC protocol
        return (f'{unit}: {model.config.model} output {model.output_pct:.1f} % current '
                f'{model.motor_current_a():.2f} A control word 0x{model.control_word:04X} '
                f'reference 0x{model.reference_word:04X} alarm word 0x{model.alarm_word:08X} '
                f'local {model.local_mode}')
    state = mcd.STATE_CODES.get(model.state, '?')
    return (f'{unit}: {model.config.model} {state} current {model.motor_current_a:.1f} A '
            f'temperature {model.temperature_pct:.0f} % trip {model.trip_code} '
            f'hand_on {model.hand_on}')


def main(argv: Optional[List[str]] = None) -> int:
    """Run the simulator until SIGINT/SIGTERM or ``quit``."""
    args = build_parser().parse_args(argv)
    done = threading.Event()  # set by a signal from now on: before 'ready' is printed
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    pacer = _pacer(args)
    relay = _relay(args)
    server = build_server(args)
    tap = wire_tap(server, args)
    path = ''
    if not args.no_pty:
        path = server.open_pty('' if pacer or relay else args.link)
        if pacer:
            path = pacer.open_pty(path, '' if relay else args.link)
            print(f'paced: {pacer.timing.describe()}', flush=True)
        if relay:
            path = relay.open_pty(path, args.link)
            print(f'adapter: {describe_adapter(relay.behaviour)}', flush=True)
        print(f'pty: {path}', flush=True)
        if args.link:
            print(f'link: {args.link}', flush=True)
    if args.tcp is not None and isinstance(server, ModbusSimServer):
        print(f'tcp: {args.host}:{server.open_tcp(args.host, args.tcp, args.framing)} '
              f'({args.framing})', flush=True)
    if tap is not None and not args.link:
        tap.trace.form.interface = path or f'{args.host}:{getattr(server, "tcp_port", 0)}'
    server.start()
    if pacer:
        pacer.start()
    if relay:
        relay.start()
    served = [f'{m}@{u}' for m, u in args.device] + \
        [f'{m} in {i} out {o} ({kind})' for i, (m, o, kind) in args.lvsg]
    print('ready: ' + ', '.join(served), flush=True)
    console = sys.stdin.isatty() if args.console is None else args.console
    if console:
        threading.Thread(target=_read_console, args=(server, done), daemon=True).start()
    while not done.wait(0.5):
        pass
    if relay:
        relay.stop()
    if pacer:
        pacer.stop()
        print(describe_line(pacer), flush=True)
    server.stop()
    if tap is not None:
        tap.close()
    return 0


def _pacer(args: argparse.Namespace) -> Optional[WirePacer]:
    """Return the wire pacer of ``--pace``, or None."""
    if not args.pace:
        return None
    if args.no_pty or args.wire_baud:
        raise SystemExit('drive_bridge_sim: --pace paces the pty: it does not mix with '
                         '--no-pty or --wire-baud')
    return WirePacer(parse_pace(args.pace, args.protocol))


def _relay(args: argparse.Namespace) -> Optional[AdapterRelay]:
    """Return the adapter relay of the adapter and line options (None: none given)."""
    behaviour = AdapterBehaviour(args.echo, args.usb_latency / 1000.0, args.babble,
                                 args.device_line, args.fault_seed)
    if not behaviour.active:
        return None
    if args.no_pty:
        raise SystemExit('drive_bridge_sim: --echo, --usb-latency, --babble and --device-line '
                         'act on the pty: they do not mix with --no-pty')
    return AdapterRelay(behaviour)


def describe_adapter(behaviour: AdapterBehaviour) -> str:
    """Return what the simulated adapter and line do, in words."""
    parts = (['echo'] if behaviour.echo else []) + \
        ([f'latency {behaviour.latency_s * 1000:g} ms'] if behaviour.latency_s else []) + \
        ([f'babble {behaviour.babble_per_s:g} bytes/s'] if behaviour.babble_per_s else []) + \
        ([f'devices at {behaviour.device_line.describe()}'] if behaviour.device_line else [])
    return ', '.join(parts)


def describe_line(pacer: WirePacer) -> str:
    """Return the pacer's counters in one line."""
    counters = pacer.counters()
    return (f'line: {counters.frames[MASTER]} frames from the master, '
            f'{counters.frames[SLAVE]} from the devices, {counters.gap_violations} gap '
            f'violations, {counters.collisions} collisions')


def _read_console(server: ModbusSimServer, done: threading.Event) -> None:
    for line in sys.stdin:
        if line.strip() == 'quit':
            break
        answer = run_console_command(server, line)
        if answer:
            print(answer, flush=True)
    done.set()


if __name__ == '__main__':
    sys.exit(main())
