"""
The doctor's search: which protocol, baud rate and parity each named address answers at.

The settings to try are ordered by how far they are from the configured ones (the
configured settings first, then those that differ in one of protocol, baud rate and parity,
then two, then all three); an address found is not asked again. Each setting opens the port
once and asks every address still missing, with reads only (:func:`identify`, as ``scan``
asks). A setting the port cannot tell from another (a pty has no parity: only the stop bits
remain) is tried once. What answers away from the configured settings gets the fix on both
sides: the device's parameters, or the bridge's settings.
"""

from contextlib import contextmanager
import logging
from typing import Callable, Dict, Iterator, List, NamedTuple, Optional, Sequence, Tuple

from drive_bridge.config import model as cfg
from drive_bridge.devices.identification import Answer
from drive_bridge.errors import ConfigError
from drive_bridge.tools.cli_identify import identify, scan_families
from drive_bridge.tools.cli_session import open_runner
from drive_bridge.tools.cli_target import CliError
from drive_bridge.tools.doctor_findings import Finding, note, ok, problem
from drive_bridge.transport.link import LinkSettings, port_framing
from drive_bridge.transport.protocols import PROTOCOLS

SEARCH_PROTOCOLS = ('modbus_rtu', 'fc_protocol', 'ap_ascii')
SEARCH_BAUDRATES = (9600, 19200, 38400)
SEARCH_PARITIES = ('E', 'N')
PROTOCOL_WORDS = {'modbus_rtu': 'Modbus RTU', 'fc_protocol': 'the FC protocol',
                  'ap_ascii': 'AP ASCII'}
# Where each family sets its protocol, baud rate and parity.
DEVICE_SETTINGS = {
    'fc': ('8-30', '8-32', '8-33'),
    'vlt': ('par. 500 (FC protocol) or the Modbus option card', "the option card's "
            'switches SW1-SW3 (FC protocol: par. 502)', "the option card's switches SW4-SW5"),
    'mcd': ("the Modbus Module's protocol switch (Remote Operator: par. 4)",
            "the Modbus Module's baud rate switches (Remote Operator: par. 1)",
            "the Modbus Module's parity switches (Remote Operator: par. 5)"),
    None: ("the device's protocol", "the device's baud rate", "the device's parity"),
}


class Setting(NamedTuple):
    """One way to talk on the line."""

    protocol: str
    baudrate: int
    parity: str

    def words(self) -> str:
        """Return the setting in words: ``the FC protocol at 9600 baud, parity E``."""
        parity = '' if PROTOCOLS[self.protocol].fixed_framing else f', parity {self.parity}'
        return f'{PROTOCOL_WORDS[self.protocol]} at {self.baudrate} baud{parity}'


class Hit(NamedTuple):
    """An address that answered, at which setting, and as what."""

    address: int
    setting: Setting
    answer: Answer


def settings_to_try(configured: Setting, protocols: Sequence[str] = SEARCH_PROTOCOLS,
                    baudrates: Sequence[int] = SEARCH_BAUDRATES,
                    parities: Sequence[str] = SEARCH_PARITIES, port: str = '') -> List[Setting]:
    """Return the settings to try, nearest to ``configured`` first, each once on the port."""
    protocols = _first(configured.protocol, protocols)
    baudrates = _first(configured.baudrate, baudrates)
    parities = _first(configured.parity, parities)
    found: Dict[Tuple, Setting] = {}
    ranked = sorted(
        ((sum((protocol != configured.protocol, baudrate != configured.baudrate,
               parity != configured.parity)), i, j, k, Setting(protocol, baudrate, parity))
         for i, protocol in enumerate(protocols) for j, baudrate in enumerate(baudrates)
         for k, parity in enumerate(parities)))
    for *_, setting in ranked:
        fixed = PROTOCOLS[setting.protocol].fixed_framing
        if fixed:
            setting = setting._replace(parity=fixed[0])
        found.setdefault(port_key(setting, port), setting)
    return list(found.values())


def _first(value, values: Sequence) -> list:
    return [value] + [other for other in values if other != value]


def port_key(setting: Setting, port: str) -> Tuple:
    """Return what the port is opened with at ``setting`` (a pty: no parity, stop bits kept)."""
    link = LinkSettings(protocol=setting.protocol, port=port, baudrate=setting.baudrate,
                        parity=setting.parity)
    framing = port_framing(link) if port else (link.effective_parity, link.effective_stopbits)
    return setting.protocol, setting.baudrate, framing[0], framing[1]


def attempt_s(setting: Setting, timeout_s: float) -> float:
    """Return the longest an address that keeps silent costs at ``setting``."""
    spec = PROTOCOLS[setting.protocol]
    return max(timeout_s, spec.min_timeout_s) + spec.reply_guard_s


def search(bus: Dict, addresses: Sequence[int], settings: Sequence[Setting], timeout_s: float,
           report: Callable[[Finding], None], first_only: bool = False) -> List[Hit]:
    """
    Ask each address at each setting in order until it answers; return what answered.

    ``first_only``: stop at the first setting at which anything answers (scan's hint).
    """
    missing, hits = list(addresses), []
    with quiet_framing_notes():
        for setting in settings:
            if not missing or (first_only and hits):
                break
            for hit in _search_setting(bus, missing, setting, timeout_s):
                missing.remove(hit.address)
                hits.append(hit)
                report(hit_finding(hit, bus))
    return hits


@contextmanager
def quiet_framing_notes() -> Iterator[None]:
    """Keep the pty's framing note (logged once per port opened) out of the search."""
    notes = logging.getLogger('drive_bridge.transport.serial_port')
    level = notes.level
    notes.setLevel(logging.WARNING)
    try:
        yield
    finally:
        notes.setLevel(level)


def _search_setting(bus: Dict, addresses: Sequence[int], setting: Setting,
                    timeout_s: float) -> List[Hit]:
    values = dict(bus, protocol=setting.protocol, baudrate=setting.baudrate,
                  parity=setting.parity, stopbits=0,
                  timeout=max(timeout_s, PROTOCOLS[setting.protocol].min_timeout_s))
    families = scan_families(values)
    if not families:
        return []
    try:
        config = cfg.build_config(dict(values, devices=['probe']),
                                  {'probe': {'family': families[0], 'address': 1}})
    except ConfigError as error:
        raise CliError(f'doctor: {setting.words()}: {error}') from None
    runner = open_runner(config)
    try:
        return [Hit(address, setting, answer) for address, answer in
                ((address, identify(values, address, runner)) for address in addresses)
                if answer is not None]
    finally:
        runner.transport.close()


def configured_setting(bus: Dict) -> Setting:
    """Return the bus's configured protocol, baud rate and parity."""
    protocol = bus.get('protocol', 'modbus_rtu')
    fixed = PROTOCOLS[protocol].fixed_framing
    return Setting(protocol, bus.get('baudrate', 9600),
                   fixed[0] if fixed else bus.get('parity', 'E'))


def hit_finding(hit: Hit, bus: Dict) -> Finding:
    """Return the line of an address that answered: ok as configured, else how to fix it."""
    configured = configured_setting(bus)
    found = hit.setting
    if found == configured:
        return ok(f'address {hit.address}', f'{hit.answer.words} ({found.words()}, as '
                  'configured)')
    return problem(f'address {hit.address}', f'answers {found.words()} ({hit.answer.words}): '
                   f'{fix(found, configured, hit.answer.family)}')


def fix(found: Setting, configured: Setting, family: Optional[str]) -> str:
    """Return both fixes: set the device to the configured setting, or the bridge to the found."""
    where = DEVICE_SETTINGS.get(family, DEVICE_SETTINGS[None])
    device, bridge = [], []
    if found.protocol != configured.protocol:
        device.append(f'{where[0]} to {PROTOCOL_WORDS[configured.protocol]}')
        bridge.append(f'protocol: {found.protocol}')
    if found.baudrate != configured.baudrate:
        device.append(f'{where[1]} to {configured.baudrate} baud')
        bridge.append(f'baudrate: {found.baudrate}')
    if found.parity != configured.parity and not PROTOCOLS[found.protocol].fixed_framing:
        device.append(f'{where[2]} to parity {configured.parity}')
        bridge.append(f'parity: "{found.parity}"')
    return f'set {" and ".join(device)}, or set {", ".join(bridge)}'


def search_worst_s(addresses: Sequence[int], settings: Sequence[Setting],
                   timeout_s: float) -> float:
    """Return how long a search of ``addresses`` at ``settings`` takes at the most."""
    return sum(attempt_s(setting, timeout_s) for setting in settings) * len(addresses)


def plan_finding(addresses: Sequence[int], settings: Sequence[Setting], timeout_s: float,
                 pty: bool) -> Finding:
    """Return what the search will try and how long it takes at the most."""
    worst_s = search_worst_s(addresses, settings, timeout_s)
    protocols = sorted({setting.protocol for setting in settings}, key=SEARCH_PROTOCOLS.index)
    bauds = ', '.join(str(b) for b in dict.fromkeys(setting.baudrate for setting in settings))
    parities = 'no parity (a pty carries none: stop bits only)' if pty else 'parities ' + \
        ', '.join(dict.fromkeys(setting.parity for setting in settings))
    return note('search', f'{len(settings)} settings ({", ".join(protocols)}; baud {bauds}; '
                f'{parities}) at address(es) {", ".join(map(str, addresses))}: at most '
                f'{worst_s:.0f} s, less as addresses answer')


def silent_finding(address: int, settings: Sequence[Setting]) -> Finding:
    """Return the line of a named address that answered at none of the settings."""
    return problem(f'address {address}', f'no answer at any of the {len(settings)} settings '
                   'tried: check the address set in the device, its power, the wiring (A and B '
                   'swapped? common ground?) and the termination; a baud rate outside those '
                   'tried: give --baudrates')
