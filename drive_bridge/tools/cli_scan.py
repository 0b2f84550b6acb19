"""
``drive-bridge scan``: what answers at each address of a range, with family and model.

One port is opened for the whole scan; each address is asked with reads only
(:func:`drive_bridge.tools.cli_identify.identify`). When nothing answers, the first addresses
are searched at the other protocols, baud rates and parities (the doctor's search, short),
a hint says what to do, and the exit status is 1.
"""

from typing import Any, Dict, Tuple

from drive_bridge.bus.runner import TransactionRunner
from drive_bridge.config import model as cfg
from drive_bridge.console import parse_integer
from drive_bridge.tools import doctor_search
from drive_bridge.tools.cli_identify import identify, scan_families
from drive_bridge.tools.cli_session import open_runner, Progress
from drive_bridge.tools.cli_target import bus_values, CliError, EXIT_FAILED, EXIT_OK, \
    EXIT_USAGE, file_block
from drive_bridge.transport.protocols import PROTOCOLS

SHORT_SEARCH_ADDRESSES = 3  # nothing answered: the first addresses of the range are searched
SHORT_SEARCH_TIMEOUT_S = 0.2


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
    if found:
        return EXIT_OK
    hint_nothing_found(args, bus, first, last, out)
    return EXIT_FAILED


def hint_nothing_found(args, bus: Dict[str, Any], first: int, last: int, out) -> None:
    """
    Print what to do when nothing answered: the doctor's search, short, and its command.

    On a serial line the first :data:`SHORT_SEARCH_ADDRESSES` addresses of the range are
    asked at the other protocols, baud rates and parities (unless ``--no-search``).
    """
    port = bus.get('port', '/dev/ttyUSB0')
    high = min(last, first + SHORT_SEARCH_ADDRESSES - 1)
    doctor = f'drive-bridge doctor --port {port} --addresses {first}-{high}'
    if not PROTOCOLS[bus.get('protocol', 'modbus_rtu')].is_serial:
        print(f'hint: nothing answers through the gateway: check its serial settings and the '
              f'unit addresses; on its serial side {doctor} checks the line', file=out)
        return
    if args.search:
        configured = doctor_search.configured_setting(dict(bus, port=port))
        settings = doctor_search.settings_to_try(configured, port=port)[1:]
        addresses = list(range(first, high + 1))
        worst_s = doctor_search.search_worst_s(addresses, settings, SHORT_SEARCH_TIMEOUT_S)
        print(f'searching {len(settings)} other protocols, baud rates and parities at '
              f'addresses {first}-{high} (at most {worst_s:.0f} s, '
              'until something answers; --no-search skips this)', file=out, flush=True)
        hits = doctor_search.search(dict(bus, port=port), addresses, settings,
                                    SHORT_SEARCH_TIMEOUT_S,
                                    lambda finding: print(finding.line(), file=out, flush=True),
                                    first_only=True)
        if hits:
            print(f'hint: set the devices or the bus as above, then scan again; {doctor} '
                  'checks the adapter and the line too', file=out)
            return
    print(f'hint: nothing answers at {doctor_search.configured_setting(bus).words()}: run '
          f'{doctor} to check the port, the adapter and the line and to search other '
          'protocols, baud rates and parities (an FC 51 speaks the FC protocol as delivered)',
          file=out)


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
