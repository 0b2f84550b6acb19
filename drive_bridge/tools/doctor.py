"""
``drive-bridge doctor``: check a serial port, its adapter and its line, and find the devices.

In order, each finding printed as soon as it is made, one line with its fix
(:mod:`.doctor_findings`): the port (it exists, this user may open it, its stable
``/dev/serial/by-id/`` name), the adapter (USB id and driver from sysfs; an FTDI adapter's
latency timer, with the udev rule that sets it to 1 ms) (:mod:`.doctor_port`); the line
(quiet or babbling, local echo) (:mod:`.doctor_line`); then the search over protocol, baud
rate and parity for the addresses named (:mod:`.doctor_search`). Reads only: nothing is
written to a device. Exit status 0 when devices answered and nothing is wrong, 1 otherwise,
2 a bad argument.
"""

import argparse
import math
import os
from typing import Callable, Dict, List, Optional, Sequence

from drive_bridge.config import model as cfg
from drive_bridge.console import parse_integer
from drive_bridge.tools import doctor_search as found
from drive_bridge.tools.cli_identify import scan_families
from drive_bridge.tools.cli_scan import parse_range
from drive_bridge.tools.cli_target import bus_values, CliError, EXIT_USAGE, file_block
from drive_bridge.tools.doctor_findings import exit_status, Finding, note, PROBLEM
from drive_bridge.tools.doctor_line import check_line
from drive_bridge.tools.doctor_port import DEV_ROOT, port_findings, SYSFS_ROOT
from drive_bridge.transport.link import LinkSettings, pty_device
from drive_bridge.transport.protocols import PROTOCOLS

DEFAULT_ADDRESSES = (1, 2, 3, 4, 5, 20)  # factory addresses: FC 51 1, Remote Operator 20
DEFAULT_LISTEN_S = 0.5
DEFAULT_SEARCH_TIMEOUT_S = 0.2
SYSFS_ENV, DEV_ENV = 'DRIVE_BRIDGE_SYSFS_ROOT', 'DRIVE_BRIDGE_DEV_ROOT'


def add_options(parser: argparse.ArgumentParser) -> None:
    """Add the doctor's own options to its subcommand parser."""
    group = parser.add_argument_group('search')
    group.add_argument('--address', type=address_argument, action='append', default=[],
                       help='an address to find (repeat it); default: the devices of --config, '
                       'else ' + ', '.join(map(str, DEFAULT_ADDRESSES)))
    group.add_argument('--addresses', metavar='RANGE', help='a range of addresses, e.g. 1-8')
    group.add_argument('--baudrates', type=baudrates_argument,
                       default=found.SEARCH_BAUDRATES, metavar='LIST',
                       help='baud rates to try after the configured one (default '
                       f'{",".join(map(str, found.SEARCH_BAUDRATES))})')
    group.add_argument('--no-search', dest='search', action='store_false',
                       help='check the port, adapter and line only')
    group.add_argument('--listen', type=listen_seconds, default=DEFAULT_LISTEN_S,
                       metavar='SECONDS',
                       help=f'listen this long for babble (default {DEFAULT_LISTEN_S:g})')
    roots = parser.add_argument_group('roots (tests)')
    roots.add_argument('--sysfs-root', default=os.environ.get(SYSFS_ENV, SYSFS_ROOT),
                       help=f'where sysfs is (default ${SYSFS_ENV} or {SYSFS_ROOT})')
    roots.add_argument('--dev-root', default=os.environ.get(DEV_ENV, DEV_ROOT),
                       help=f'where /dev is, for serial/by-id (default ${DEV_ENV} or '
                       f'{DEV_ROOT})')


def address_argument(text: str) -> int:
    """Return ``text`` as a device address 1-247 (an argparse type)."""
    try:
        address = parse_integer(text)
    except ValueError:
        address = 0
    if not 1 <= address <= 247:
        raise argparse.ArgumentTypeError(f'{text!r} is no address 1-247')
    return address


def baudrates_argument(text: str) -> tuple:
    """Return ``9600,19200`` as (9600, 19200), each a baud rate the bridge takes."""
    allowed = cfg.BAUDRATES
    try:
        rates = tuple(parse_integer(part) for part in text.split(','))
    except ValueError:
        rates = ()
    if not rates or any(rate not in allowed for rate in rates):
        raise argparse.ArgumentTypeError(f'{text!r}: give baud rates separated by commas, '
                                         f'from {", ".join(map(str, allowed))}')
    return rates


def command_doctor(args, out) -> int:
    """Check the port, adapter and line, then search the addresses; print each finding."""
    file_bus, blocks = file_block(args)
    bus = bus_values(args, file_bus)
    protocol = bus.get('protocol', 'modbus_rtu')
    if not PROTOCOLS[protocol].is_serial:
        raise CliError(f'doctor checks a serial port, and protocol {protocol} is a gateway: '
                       "run it on the gateway's serial side, or use scan", EXIT_USAGE)
    addresses = chosen_addresses(args, blocks)
    bus.setdefault('port', '/dev/ttyUSB0')
    findings: List[Finding] = []

    def report(finding: Finding) -> None:
        findings.append(finding)
        print(finding.line(), file=out, flush=True)

    with found.quiet_framing_notes():  # the pty note, once per setting: the plan says it
        hits = diagnose(args, bus, addresses, report)
    if hits is not None:  # None: the port cannot be used, and its one line says why
        print(f'doctor: {len(hits)} device(s) found, '
              f'{sum(f.level == PROBLEM for f in findings)} problem(s)', file=out)
    return exit_status(findings, len(hits or ()))


def diagnose(args, bus: Dict, addresses: Sequence[int],
             report: Callable[[Finding], None]) -> Optional[list]:
    """Run the checks in order, reporting each finding; return the hits (None: no port)."""
    port = bus['port']
    for finding in port_findings(port, args.sysfs_root, args.dev_root):
        report(finding)
        if finding.level == PROBLEM and finding.topic in ('port', 'permissions'):
            return None
    line = check_line(link_of(bus), args.listen)
    for finding in line.findings:
        report(finding)
    if not line.opened or not args.search:
        return []
    if line.echo is not None:
        bus = dict(bus, local_echo=line.echo)  # the search hears its own bytes otherwise
    return search_addresses(args, bus, addresses, report)


def search_addresses(args, bus: Dict, addresses: Sequence[int],
                     report: Callable[[Finding], None]) -> list:
    """Search ``addresses`` over protocol, baud rate and parity; report each address."""
    configured = found.configured_setting(bus)
    settings = found.settings_to_try(configured, baudrates=args.baudrates, port=bus['port'])
    timeout_s = args.timeout or DEFAULT_SEARCH_TIMEOUT_S
    report(found.plan_finding(addresses, settings, timeout_s, bool(pty_device(bus['port']))))
    hits = found.search(bus, addresses, settings, timeout_s, report)
    named = bool(args.address or args.addresses)
    missing = [address for address in addresses if address not in {h.address for h in hits}]
    if named:
        for address in missing:
            report(found.silent_finding(address, settings))
    elif missing and hits:
        report(note('search', f'nothing at {", ".join(map(str, missing))}'))
    elif not hits:
        report(found.silent_finding(addresses[0], settings)._replace(
            topic='search', text=f'nothing answers at {", ".join(map(str, addresses))} at any '
            f'of the {len(settings)} settings tried: give --address or --addresses if the '
            'devices sit elsewhere; check power, wiring (A and B swapped?) and termination'))
    return hits


def chosen_addresses(args, blocks: Dict[str, Dict]) -> List[int]:
    """Return the addresses to search: named, a range, the file's devices, or the defaults."""
    addresses = list(args.address)
    if args.addresses:
        low, high = parse_range(args.addresses)
        addresses += range(low, high + 1)
    if not addresses:
        addresses = [block['address'] for block in blocks.values() if 'address' in block] \
            or list(DEFAULT_ADDRESSES)
    return list(dict.fromkeys(addresses))


def link_of(bus: Dict) -> LinkSettings:
    """Return the link settings of ``bus`` (checked as the node checks them)."""
    families = scan_families(bus) or ('fc',)
    return cfg.build_config(dict(bus, devices=['probe']),
                            {'probe': {'family': families[0], 'address': 1}}).link


MAX_LISTEN_S = 60.0


def listen_seconds(text: str) -> float:
    """Return ``text`` as seconds to listen, 0-60 (an argparse type)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 0.0 <= value <= MAX_LISTEN_S):
        raise argparse.ArgumentTypeError(
            f'{text!r}: give the seconds to listen, 0-{MAX_LISTEN_S:g}')
    return value
