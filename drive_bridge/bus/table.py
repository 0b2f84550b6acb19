"""
The device table: every device of one bus and the lock over their state.

The bus thread changes a device's health, reading, statistics and motor state while callers
on other threads read copies (:class:`DeviceSnapshot`), queue commands and change settings.
The table owns the devices and that lock: its own methods take it, and a part that changes
several things that must be seen together holds it through :meth:`DeviceTable.locked`. It is
reentrant: a change may call another that locks too.
"""

from dataclasses import dataclass, field
import threading
from typing import Callable, ContextManager, Dict, FrozenSet, Iterator, List, Optional

from drive_bridge.bus.device import BusDevice, DeviceSpec
from drive_bridge.bus.motor import Motion
from drive_bridge.devices.contracts import DeviceReading, SpeedReference
from drive_bridge.errors import CommandRefused
from drive_bridge.protocol.commands import Command


@dataclass
class DeviceSnapshot:
    """A copy of one device's state for readers outside the bus thread."""

    name: str
    unit: int
    family: str
    model: str
    online: Optional[bool]
    status_text: str
    reading: Optional[DeviceReading]
    reading_age_s: float
    poll_failure: str
    stats: Dict[str, str]
    motor: str  # the motor-state owner's account, in words
    motion: Motion
    holds_run: bool
    allow_control: bool
    commands: FrozenSet[Command] = frozenset()
    reading_fields: FrozenSet[str] = frozenset()
    control: str = ''
    hardware: Dict[str, str] = field(default_factory=dict)
    poll_period_s: float = 0.0  # the time between two polls at the configured poll_rate


class DeviceTable:
    """The devices of one bus by name, and the lock over their state (see the module)."""

    def __init__(self, specs: List[DeviceSpec], clock: Callable[[], float]):
        self.clock = clock
        now = clock()
        self._devices: Dict[str, BusDevice] = {spec.name: BusDevice(spec, now)
                                               for spec in specs}
        self._lock = threading.RLock()
        self._by_unit: Dict[int, BusDevice] = {}
        for device in reversed(list(self._devices.values())):
            self._by_unit[device.spec.unit] = device

    def locked(self) -> ContextManager:
        """Hold the table's lock for a change that others must see whole (any thread)."""
        return self._lock

    @property
    def names(self) -> List[str]:
        """Return the device names in the configured order."""
        return list(self._devices)

    def __iter__(self) -> Iterator[BusDevice]:
        """Iterate over the devices in the configured order."""
        return iter(list(self._devices.values()))

    def __getitem__(self, name: str) -> BusDevice:
        """Return the device ``name`` (KeyError if there is none)."""
        return self._devices[name]

    def known(self, name: str) -> BusDevice:
        """Return the device ``name``; raise CommandRefused naming the devices there are."""
        device = self._devices.get(name)
        if device is None:
            raise CommandRefused(
                f'unknown device {name!r}: this bus has {", ".join(self._devices)}')
        return device

    def by_unit(self, unit: int) -> Optional[BusDevice]:
        """Return the first device at bus address ``unit``, or None (no lock: fixed)."""
        return self._by_unit.get(unit)

    def next_due(self) -> Optional[BusDevice]:
        """Return the device whose poll is due first, or None without devices."""
        with self._lock:
            if not self._devices:
                return None
            return min(self._devices.values(), key=lambda device: device.health.next_due_s)

    def all_due(self) -> None:
        """Make every device due now (the link was opened)."""
        now = self.clock()
        with self._lock:
            for device in self._devices.values():
                device.health.next_due_s = now

    def transaction_count(self) -> int:
        """Return the transactions run on this bus so far, every device together."""
        with self._lock:
            return sum(device.stats.transactions for device in self._devices.values())

    def snapshot(self, name: str) -> DeviceSnapshot:
        """Return a copy of one device's state (KeyError for an unknown name)."""
        with self._lock:
            device = self._devices[name]
            profile = device.profile
            owner = device.owner
            return DeviceSnapshot(
                name=name, unit=device.spec.unit, family=profile.family, model=profile.model,
                online=device.health.online, status_text=device.health.status_text,
                reading=device.reading,
                reading_age_s=self.clock() - device.reading_time_s,
                poll_failure=device.health.poll_failure,
                stats=_device_stats(device), motor=owner.describe(),
                motion=owner.motion, holds_run=owner.holds_run,
                allow_control=owner.allow_control, commands=profile.commands,
                reading_fields=profile.reading_fields,
                control=profile.describe_control(owner), poll_period_s=device.poll_period_s)


def _device_stats(device: BusDevice) -> Dict[str, str]:
    stats = device.stats.as_dict()
    if device.setup_error:
        stats['setup_error'] = device.setup_error
    if isinstance(device.profile, SpeedReference):
        stats['rejected_references'] = str(device.rejected_references)
        stats['deadman_stops'] = str(device.deadman_stops)
        stats['reference_timeout_s'] = f'{device.spec.reference_timeout_s:g}'
    return stats
