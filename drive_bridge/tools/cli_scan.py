"""
``drive-bridge scan``: what answers at each address of a range, with family and model.

One port is opened for the whole scan; each address is asked with reads only
(:func:`drive_bridge.tools.cli_session.identify`).
"""

from typing import Any, Dict, Tuple

from drive_bridge import config as cfg
from drive_bridge.bus.runner import TransactionRunner
from drive_bridge.console import parse_integer
from drive_bridge.tools.cli_session import identify, open_runner, Progress, scan_families
from drive_bridge.tools.cli_target import bus_values, CliError, EXIT_OK, EXIT_USAGE, file_block


def command_scan(args, out) -> int:
    """Try every address in the range; print what answers, with family and model."""
    first, last = parse_range(args.addresses)
    bus = bus_values(args, file_block(args)[0])  # the file's bus, options winning
    families = scan_families(bus)
    if not families:
        raise CliError(f'scan: no family it can identify runs on protocol '
                       f'{bus.get("protocol", "modbus_rtu")!r}', EXIT_USAGE)
    config = cfg.build_config(dict(bus, devices=['probe']),
                              {'probe': {'family': families[0], 'address': first}})
    runner = open_runner(config)  # one port for the whole scan
    found = 0
    try:
        with Progress(last - first + 1, 'scanning', args, out, unit='address') as progress:
            for address in range(first, last + 1):
                result = scan_address(bus, address, runner)
                progress.step()
                if result:
                    found += 1
                    progress.emit(f'address {address}: {result}')
    finally:
        runner.transport.close()
    print(f'{found} device(s) found at addresses {first}-{last}', file=out)
    return EXIT_OK


def parse_range(text: str) -> Tuple[int, int]:
    """Return (first, last) of ``1-32`` or ``5``."""
    first, _, last = text.partition('-')
    try:
        low, high = parse_integer(first), parse_integer(last or first)
    except ValueError:
        raise CliError(f'address range {text!r}: write it as 1-32', EXIT_USAGE) from None
    if not 1 <= low <= high <= 247:
        raise CliError(f'address range {text!r} must lie within 1-247, low to high',
                       EXIT_USAGE)
    return low, high


def scan_address(bus: Dict[str, Any], address: int, runner: TransactionRunner) -> str:
    """Return what answers at ``address`` in words, or '' if nothing does."""
    found = identify(bus, address, runner)
    return '' if found is None else found.words
