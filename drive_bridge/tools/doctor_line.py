"""
The doctor's checks of the line itself: whether it is quiet, whether the adapter echoes.

The port is opened at the configured settings (exclusively, as the node opens it). First
the doctor only listens: bytes while nobody was asked mean another master, a device that
sends on its own, or noise (termination, biasing). Then it sends a few bytes that no device
takes for a request (:data:`~drive_bridge.transport.port_probe.PROBE_BYTES`) and listens:
its own bytes coming back mean the adapter echoes (``local_echo: true``).
"""

from typing import List, NamedTuple, Optional, Tuple

from drive_bridge.errors import LinkDown
from drive_bridge.tools.doctor_findings import Finding, note, ok, problem
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.port_probe import PortProbe, PROBE_BYTES

ECHO_WAIT_S = 0.2  # a USB adapter's latency timer (16 ms) and a busy machine included
SHOWN_BYTES = 12


class LineCheck(NamedTuple):
    """What the line checks found: findings, and the echo (None: not told)."""

    findings: List[Finding]
    echo: Optional[bool]
    opened: bool


def check_line(settings: LinkSettings, listen_s: float) -> LineCheck:
    """Open the port at ``settings``, listen for ``listen_s``, then test for local echo."""
    try:
        with PortProbe(settings) as probe:
            heard = probe.listen(listen_s)
            back = probe.send_and_listen(PROBE_BYTES, ECHO_WAIT_S)
    except LinkDown as error:
        text = str(error).replace('bus offline: ', '')
        return LineCheck([problem('open', text)], None, False)
    quiet = babble_finding(heard, listen_s, settings)
    echo, found = echo_finding(back, bool(heard), settings.local_echo)
    return LineCheck([quiet, found], echo, True)


def babble_finding(heard: bytes, listen_s: float, settings: LinkSettings) -> Finding:
    """Return whether the line kept quiet while nobody was asked."""
    if not heard:
        return ok('line', f'quiet for {listen_s:g} s before anything was sent')
    return problem('line', f'{len(heard)} byte(s) in {listen_s:g} s while nobody was asked '
                   f'({shown(heard)}) at {settings.baudrate} baud: another master on the line '
                   '(a PLC, a second bridge, a Remote Operator), a device that sends on its '
                   'own, or noise: stop the other master; check the 120 ohm termination at '
                   'both ends of the line only, and the biasing (one pull-up on B, one '
                   'pull-down on A, at one place)')


def echo_finding(back: bytes, babbling: bool, configured: bool) -> Tuple[Optional[bool], Finding]:
    """Return (echo, finding): did the probe bytes come back, and does that fit local_echo."""
    if PROBE_BYTES in back:
        if configured:
            return True, ok('local echo', 'the adapter echoes what it sends (local_echo: true, '
                            'as configured)')
        return True, problem('local echo', 'the adapter echoes what it sends: set local_echo: '
                             'true (or switch its echo off, if it has a switch)')
    if back and babbling:
        return None, note('local echo', 'not told: the line babbles (see line); its bytes '
                          'hide an echo')
    if back:
        return None, note('local echo', f'{len(back)} byte(s) came back but not the ones sent '
                          f'({shown(back)}): a half echo (a slow driver turn-around?) or noise')
    if configured:
        return False, problem('local echo', 'the adapter does not echo what it sends: set '
                              'local_echo: false')
    return False, ok('local echo', 'none (local_echo: false, as configured)')


def shown(data: bytes) -> str:
    """Return the first bytes of ``data`` in hex."""
    more = ' ...' if len(data) > SHOWN_BYTES else ''
    return data[:SHOWN_BYTES].hex(' ') + more
