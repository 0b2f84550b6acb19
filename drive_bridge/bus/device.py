"""
One device on the bus as the bus thread keeps it: its configuration, health and statistics.

:class:`DeviceSpec` is the configuration; :class:`BusDevice` adds what the bus learns while
it runs: the motor-state owner (:mod:`.motor`), the health of the link to the device
(:class:`DeviceHealth`: online, failures in a row, backoff, when it is next due), the
statistics and the latest reading.
"""

from dataclasses import dataclass
import math
from typing import Optional

from drive_bridge.bus.motor import MotorOwner
from drive_bridge.bus.stats import DeviceStats
from drive_bridge.devices.contracts import (
    CyclicControl, DeviceProfile, DeviceReading, SpeedReference)


@dataclass
class DeviceSpec:
    """One device on the bus as configured; times in seconds."""

    name: str
    unit: int
    profile: DeviceProfile
    poll_rate_hz: float = 5.0
    allow_control: bool = True
    stop_on_shutdown: bool = True
    reference_timeout_s: float = 0.0  # deadman on speed reference messages; 0 = off
    reference_pct: float = 0.0  # the speed reference at start (devices with a reference)


class DeviceHealth:
    """
    Whether a device answers: online, failures in a row, backoff, and when it is next due.

    ``online`` is None until the first poll's outcome. A device is marked offline after
    ``offline_after`` failed transactions in a row; it is then probed once per backoff
    period, doubling up to the bus's maximum.
    """

    def __init__(self, now_s: float):
        self.online: Optional[bool] = None
        self.status_text = 'waiting for first reply'
        self.consecutive_failures = 0
        self.refused_polls = 0  # polls refused by the device in a row (exception replies)
        self.poll_failure = ''  # why the last poll gave no reading ('' after a good one)
        self.backoff_s = 0.0
        self.next_due_s = now_s
        self.misconfigured = ''

    def schedule_next(self, period_s: float, now_s: float) -> None:
        """Make the device due one period after it was due (never in the past)."""
        self.next_due_s = max(self.next_due_s + period_s, now_s)

    def backoff(self, initial_s: float, maximum_s: float, now_s: float,
                first: bool = False) -> None:
        """Wait before the next probe: the initial backoff, or twice the last one."""
        self.backoff_s = initial_s if first else min(max(self.backoff_s * 2, initial_s),
                                                     maximum_s)
        self.next_due_s = now_s + self.backoff_s


class BusDevice:
    """The bus thread's record of one device; see the module docstring."""

    def __init__(self, spec: DeviceSpec, now_s: float):
        self.spec = spec
        profile = spec.profile
        self.owner = MotorOwner(spec.name, cyclic=isinstance(profile, CyclicControl),
                                allow_control=spec.allow_control)
        if isinstance(profile, SpeedReference):
            self.owner.set_reference_word(profile.reference_word(spec.reference_pct))
        self.reference_pct = spec.reference_pct
        self.health = DeviceHealth(now_s)
        self.stats = DeviceStats()
        self.reading: Optional[DeviceReading] = None
        self.reading_time_s = -math.inf  # when the poll that gave ``reading`` began
        self.setup_error = ''
        self.setup_retry_at_s = math.inf  # when to send the set-up writes again (lost reply)
        self.rejected_references = 0
        self.deadman_stops = 0
        self.reference_deadline_s = math.inf

    @property
    def name(self) -> str:
        """Return the device's name."""
        return self.spec.name

    @property
    def profile(self) -> DeviceProfile:
        """Return the device's profile."""
        return self.spec.profile

    @property
    def poll_period_s(self) -> float:
        """Return the time between two polls."""
        return 1.0 / self.spec.poll_rate_hz
