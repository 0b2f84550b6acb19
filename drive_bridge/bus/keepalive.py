"""
The keepalive rule: the longest a working line may go without writing to a drive.

A drive's own control word timeout (``comms_timeout``: FC 51 par. 8-03, the VLT option
card's register 2) stops or trips it when no control word comes for that long. The bridge
writes the control word at the start of each of the drive's polls while a command is in
force (the keepalive), so the timeout must be longer than the longest gap between two of its
polls while the line works: the drive answers, any other device may have stopped answering.
:func:`keepalive_gap` computes that gap from the line's schedule; no I/O, no clock.

How the bus schedules (:mod:`.polling`): one poll cycle at a time, earliest due first, and a
device is next due one period after it was due (or at the start of its poll, if it is late).
Between the start of the drive's poll and the start of its next one (due at most one period
later) the line carries:

- the rest of the drive's own poll: its transactions, with up to ``min(retries,
  offline_after - 1)`` lost reads sent again (more and it goes offline: no writes at all,
  and its timeout may trip legitimately);
- at most ``ceil(P / P_j) + 1`` polls of each other device ``j`` (a poll that starts first
  must be due first: due times one period ``P_j`` apart, all within the drive's period
  ``P``, and the one that was due at the start);
- if device ``j`` has stopped answering: the failed transactions that take it offline
  (``offline_after``, and its writes) or its probes (one a backoff, the first after
  ``backoff_initial``: its writes and one read each), each a whole timeout, the guard after
  it and a silence;
- the identity reads and set-up writes of devices coming online.

Not counted: what a user asks for (commands, parameter reads and writes: a few transactions
each), a line that loses the drive's writes, and the host's own delays (the margin).
"""

from dataclasses import dataclass
import math
from typing import List, Sequence, Tuple

MARGIN_S = 1.0  # the margin advised above the gap (host delays; a reply a little slower)


@dataclass(frozen=True)
class PollLoad:
    """
    One device on the line as the schedule sees it; times in seconds.

    ``transactions``: the most one poll takes; ``writes``: its writes before the first read
    (a probe sends them too); ``online``: transactions each time it comes online.
    """

    name: str
    poll_period_s: float
    transactions: int = 1
    writes: int = 0
    online: int = 0


@dataclass(frozen=True)
class LineTimes:
    """
    How long the line is busy with one transaction, and the retry policy.

    ``answered_s``: an answered transaction (frames, gaps, the device's reply delay);
    ``failed_s``: an unanswered one (the timeout, the guard after it, a silence).
    """

    answered_s: float
    failed_s: float
    retries: int = 2
    offline_after: int = 3
    backoff_initial_s: float = 1.0

    def describe(self) -> str:
        """Return the two transaction times in words."""
        return f'an answered transaction {self.answered_s:.3f} s, a failed one ' \
            f'{self.failed_s:.3f} s'


@dataclass(frozen=True)
class KeepaliveGap:
    """The longest gap between two polls of a drive, and what it is made of (in words)."""

    device: str
    gap_s: float
    parts: Tuple[Tuple[str, float], ...]

    @property
    def advised_s(self) -> float:
        """Return the gap with the margin, rounded up to 0.1 s."""
        return round_up(self.gap_s + MARGIN_S)

    def explain(self) -> str:
        """Return the sum in words: ``poll 0.2 s + crusher: 2 polls 0.1 s, ...``."""
        return ' + '.join(f'{label} {seconds:.2f} s' for label, seconds in self.parts)


def round_up(seconds: float, step: float = 0.1) -> float:
    """Return ``seconds`` rounded up to a multiple of ``step`` (0.1 s), as it is shown."""
    return round(math.ceil(round(seconds / step, 6)) * step, 6)


def keepalive_gap(name: str, devices: Sequence[PollLoad], times: LineTimes) -> KeepaliveGap:
    """Return the longest gap between two polls of device ``name``; see the module docstring."""
    own = next(device for device in devices if device.name == name)
    lost_reads = min(times.retries, times.offline_after - 1)
    own_poll_s = own.transactions * times.answered_s + lost_reads * times.failed_s
    parts: List[Tuple[str, float]] = []
    if own_poll_s > own.poll_period_s:
        lost = f' with {lost_reads} lost reads' if lost_reads else ''
        parts.append((f'its own poll{lost}', own_poll_s))
    else:
        parts.append(('its poll period', own.poll_period_s))
    for other in devices:
        if other is not own:
            parts.extend(_other_device(own.poll_period_s, other, times))
    coming_online = sum(device.online for device in devices) * times.answered_s
    if coming_online:
        parts.append(('devices coming online', coming_online))
    return KeepaliveGap(name, sum(seconds for _, seconds in parts), tuple(parts))


def _other_device(period_s: float, other: PollLoad,
                  times: LineTimes) -> List[Tuple[str, float]]:
    """Return what device ``other`` may put on the line within one period of the drive."""
    polls = math.ceil(round(period_s / other.poll_period_s, 9)) + 1
    answered_s = polls * other.transactions * times.answered_s
    failed = silent_failures(period_s, other, polls, times)
    return [(f'{other.name}: {polls} polls', answered_s),
            (f'{failed} failed if {other.name} is silent', failed * times.failed_s)]


def silent_failures(period_s: float, other: PollLoad, polls: int, times: LineTimes) -> int:
    """
    Return the most failed transactions of a silent device within one period of the drive.

    It goes offline after ``offline_after`` failed transactions in a row (its writes may
    come on top: they are not retried), then is probed once a backoff, never sooner than
    ``backoff_initial``. Each poll fails at most its writes and a read with its retries.
    """
    going_offline = times.offline_after + other.writes
    per_poll = min(other.writes + times.retries + 1, going_offline)
    probes = min(polls, math.ceil(round(period_s / times.backoff_initial_s, 9)) + 1)
    probing = probes * (other.writes + 1)
    # A probe comes a backoff after the failure that took the device offline: within one
    # period only if the backoff is shorter than the period.
    either = going_offline + probing if times.backoff_initial_s < period_s else \
        max(going_offline, probing)
    return min(polls * per_poll, either)
