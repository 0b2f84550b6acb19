"""
What ``drive-bridge doctor`` says: findings, one line each, with the fix.

A :class:`Finding` is one thing the doctor checked: ``ok``, a ``note`` (worth knowing,
nothing wrong) or a ``problem`` (with what to do). The exit status follows from them
(:func:`exit_status`).
"""

from typing import Iterable, NamedTuple

OK, NOTE, PROBLEM = 'ok', 'note', 'problem'
LEVELS = (OK, NOTE, PROBLEM)
EXIT_HEALTHY, EXIT_PROBLEM = 0, 1
# The udev rule that sets every FTDI adapter's latency timer to 1 ms when it is plugged in.
FTDI_UDEV_RULE = 'ACTION=="add", SUBSYSTEM=="usb-serial", DRIVERS=="ftdi_sio", ' \
    'ATTR{latency_timer}="1"'
FTDI_UDEV_FILE = '/etc/udev/rules.d/99-ftdi-latency.rules'


class Finding(NamedTuple):
    """One check: its level, what was checked (``port``, ``echo``) and the line to print."""

    level: str
    topic: str
    text: str

    def line(self) -> str:
        """Return the finding as printed: ``problem  latency timer: ...``."""
        return f'{self.level:<8} {self.topic}: {self.text}'


def ok(topic: str, text: str) -> Finding:
    """Return a finding with nothing wrong."""
    return Finding(OK, topic, text)


def note(topic: str, text: str) -> Finding:
    """Return a finding worth knowing, nothing wrong."""
    return Finding(NOTE, topic, text)


def problem(topic: str, text: str) -> Finding:
    """Return a finding that something is wrong (``text`` says what to do)."""
    return Finding(PROBLEM, topic, text)


def exit_status(findings: Iterable[Finding], devices_found: int) -> int:
    """Return 0 when devices answered and no finding is a problem, else 1."""
    if devices_found and not any(finding.level == PROBLEM for finding in findings):
        return EXIT_HEALTHY
    return EXIT_PROBLEM
