"""
The keepalive rule: the longest a working line may go without writing to a drive.

A drive's own control word timeout (``comms_timeout``: FC 51 par. 8-03, the VLT option
card's register 2) stops or trips it when no control word comes for that long. The bridge
writes the control word at the start of each of the drive's polls while a command is in
force (the keepalive), so the timeout must be longer than the longest gap between two of its
polls while the line works: the drive answers, any other device may have stopped answering.
:func:`keepalive_gap` computes that gap from the line's schedule; no I/O, no clock.

How the bus schedules (:mod:`.polling`): one poll cycle at a time; the device whose
``next_due_s`` is earliest begins next; as a poll begins, the device is made due one period
after it was due, never before that moment (:meth:`.device.Health.schedule_next`). Hence a
bound that holds whatever the other devices' rates: let the drive's poll begin at ``S1``
(its keepalive write goes out first), so it is next due at ``D <= S1 + P`` (``P`` its
period). A device that begins a poll at or after ``D`` is made due no sooner than that
moment, so after ``D`` every other device begins at most one poll before the drive's next,
besides the one in progress at ``D``, which began before it. The next write therefore goes
out by ``S1 + max(own, P + c_max) + sum(c_j)``: ``own`` the drive's own poll, ``c_j`` the
longest poll of device ``j``, ``c_max`` the longest of them (the poll in progress at ``D``).

The longest poll of a device that stays online ("while the line works": the drive answers,
any device may lose replies): each of its transactions answered after ``lost = min(retries,
offline_after - 1)`` lost attempts (failures in a row below ``offline_after`` never take it
offline, and an answer ends the row); of one that stopped answering: its writes and a read
with its retries failed (no more than take it offline), or, offline, a probe (its writes and
one read). Devices coming online add their identity reads and set-up writes.

Not counted: what a user asks for (commands, parameter reads and writes: a few transactions
each), a line that loses the drive's writes, replies slower than the protocol's reply delay
(``slow_replies`` in ``/diagnostics``), and the host's own delays (the margin).
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
    own_poll_s = longest_online_poll_s(own, times)
    others = [(other.name, longest_poll_s(other, times)) for other in devices
              if other is not own]
    in_progress_s = max((seconds for _, seconds in others), default=0.0)
    parts: List[Tuple[str, float]] = []
    if own_poll_s > own.poll_period_s + in_progress_s:
        retried = ', each read answered at the last retry' if lost_attempts(times) else ''
        parts.append((f'its own poll{retried}', own_poll_s))
    else:
        parts.append(('its poll period', own.poll_period_s))
        if in_progress_s:
            parts.append(('a poll under way as it falls due', in_progress_s))
    parts.extend((f'a poll of {other}', seconds) for other, seconds in others)
    coming_online = sum(device.online for device in devices) * times.answered_s
    if coming_online:
        parts.append(('devices coming online', coming_online))
    return KeepaliveGap(name, sum(seconds for _, seconds in parts), tuple(parts))


def lost_attempts(times: LineTimes) -> int:
    """Return how many attempts in a row a device may lose and stay online."""
    return max(0, min(times.retries, times.offline_after - 1))


def longest_online_poll_s(device: PollLoad, times: LineTimes) -> float:
    """Return the longest poll of a device that stays online: each transaction retried."""
    return device.transactions * (times.answered_s + lost_attempts(times) * times.failed_s)


def longest_poll_s(device: PollLoad, times: LineTimes) -> float:
    """
    Return the longest poll of ``device``, online or not.

    Silent, a poll fails its writes (not sent again) and a read with its retries, but no more
    failures in a row than take it offline (``offline_after``, its writes on top); offline,
    a probe fails its writes and one read.
    """
    silent = min(device.writes + times.retries + 1, times.offline_after + device.writes)
    return max(longest_online_poll_s(device, times), silent * times.failed_s)
