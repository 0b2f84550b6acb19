"""
``mbpoll`` (Debian ``mbpoll``), a Modbus master built on libmodbus, run once per call.

:func:`run_mbpoll` runs it for one transaction (``-1``: poll once) in RTU mode at 9600 8N2
(manual 000 section 8.1: no parity, 2 stop bits; a pty takes no parity) with a reply
timeout, and :class:`MbpollResult` reads what it printed: the values read, the reason a
transaction failed, and with ``verbose`` the bytes libmodbus received (its debug output,
``<14><86><04>...``). mbpoll numbers references from 1 (reference 3 is frame address 2)
unless ``-0`` is given; the caller passes the reference as mbpoll reads it.
"""

import re
import shutil
import subprocess
from typing import Dict, List, NamedTuple, Sequence

import pytest

SKIP_REASON = 'mbpoll not installed: apt install mbpoll'
REPLY_TIMEOUT_S = 5.0  # mbpoll -o: the simulator may be held up on a busy machine
PROCESS_TIMEOUT_S = 30.0
_VALUE_LINE = re.compile(r'^\[(\d+)\]:\s+(-?(?:0x)?[0-9A-Fa-f]+)', re.MULTILINE)
_FAILED_LINE = re.compile(r'^(?:Read|Write) .* failed: (.+)$', re.MULTILINE)
_RECEIVED_BYTE = re.compile(r'<([0-9A-F]{2})>')


class MbpollResult(NamedTuple):
    """What one mbpoll run did and printed."""

    status: int
    stdout: str
    stderr: str

    def values(self) -> Dict[int, int]:
        """Return reference -> value of the lines ``[3]: 65`` or ``[50200]: 0x0703``."""
        return {int(reference): int(value, 0)
                for reference, value in _VALUE_LINE.findall(self.stdout)}

    def failure(self) -> str:
        """Return libmodbus's reason for a failed transaction ('' if none failed)."""
        found = _FAILED_LINE.search(self.stderr)
        return found.group(1).strip() if found else ''

    def received(self) -> bytes:
        """Return the bytes libmodbus received, as its debug output in a verbose run shows them."""
        return bytes(int(byte, 16) for byte in _RECEIVED_BYTE.findall(self.stdout))


def mbpoll_path() -> str:
    """Return the mbpoll command; skip the test where it is not installed."""
    path = shutil.which('mbpoll')
    if path is None:
        pytest.skip(SKIP_REASON)
    return path


def run_mbpoll(port: str, unit: int, reference: int, options: Sequence[str] = (),
               values: Sequence[int] = (), verbose: bool = False) -> MbpollResult:
    """
    Run mbpoll once on ``port``: read (no ``values``) or write from ``reference``.

    ``options`` go before the port (``-c 6``, ``-t 4:hex``, ``-0``); write values after it,
    as mbpoll's usage has them.
    """
    command: List[str] = [
        mbpoll_path(), '-m', 'rtu', '-b', '9600', '-P', 'none', '-s', '2', '-1',
        '-o', f'{REPLY_TIMEOUT_S:g}', '-a', str(unit), '-r', str(reference), *options]
    if verbose:
        command.append('-v')
    command += [port, *(str(value) for value in values)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=PROCESS_TIMEOUT_S,
                          stdin=subprocess.DEVNULL)
    return MbpollResult(done.returncode, done.stdout, done.stderr)
