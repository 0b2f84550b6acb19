"""
Device controls: the speed reference, the deadman feed and runtime settings (any thread).

Nothing here is sent: a speed reference goes out with the next cyclic write, settings change
what the bus does from now on. Each change is made whole under the device table's lock; the
motor-state owner refuses monitor-only while the bridge holds a run.
"""

from typing import Any, Callable, Dict, Mapping, Optional

from drive_bridge.bus import deadman
from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.table import DeviceTable
from drive_bridge.devices.contracts import SpeedReference
from drive_bridge.errors import CommandRefused, MonitorOnly


class DeviceControls:
    """Take speed references, deadman feeds and settings for the devices of one bus."""

    def __init__(self, devices: DeviceTable, clock: Callable[[], float]):
        self.devices = devices
        self.clock = clock

    def set_speed_reference(self, name: str, percent: float, from_topic: bool) -> int:
        """Take a drive's speed reference; return its word (see BusMaster)."""
        with self.devices.locked():
            device = self.devices.known(name)
            word = self._checked_reference(device, percent)
            device.owner.set_reference_word(word)
            device.reference_pct = float(percent)
            if from_topic:
                deadman.feed(device, self.clock())
        return word

    def count_rejected_reference(self, name: str) -> None:
        """Count a reference refused before it became a value (see BusMaster)."""
        with self.devices.locked():
            self.devices.known(name).rejected_references += 1

    def feed_deadman(self, name: str) -> None:
        """Count a command message for the deadman (reference_timeout_s)."""
        with self.devices.locked():
            deadman.feed(self.devices.known(name), self.clock())

    def _checked_reference(self, device: BusDevice, percent: float) -> int:
        profile = device.profile
        if not isinstance(profile, SpeedReference):
            raise CommandRefused(f'{device.name} ({profile.family}) takes no speed reference')
        try:
            if not device.owner.allow_control:
                raise MonitorOnly(f'{device.name} is monitor only (allow_control is false): '
                                  'speed reference not taken')
            return profile.reference_word(percent)
        except CommandRefused:
            device.rejected_references += 1
            raise

    def apply_settings(self, changes: Mapping[str, Mapping[str, Any]]) -> None:
        """Apply runtime settings of several devices at once, or none of them (see BusMaster)."""
        with self.devices.locked():
            words = self._checked_settings(changes)
            for name, settings in changes.items():
                self._apply(self.devices[name], settings, words.get(name))

    def _checked_settings(self, changes: Mapping[str, Mapping[str, Any]]
                          ) -> Dict[str, Optional[int]]:
        """Raise CommandRefused if any change is refused; return the new reference words."""
        words = {}
        for name, settings in changes.items():
            device = self.devices.known(name)
            if settings.get('allow_control') is False:
                device.owner.check_monitor_only()
            if 'speed_reference' in settings:
                allow = settings.get('allow_control', device.owner.allow_control)
                if not allow and settings['speed_reference'] != device.reference_pct:
                    raise MonitorOnly(f'{name} is monitor only (allow_control is false): '
                                      'speed reference not taken')
                words[name] = device.profile.reference_word(settings['speed_reference']) \
                    if isinstance(device.profile, SpeedReference) else None
        return words

    def _apply(self, device: BusDevice, settings: Mapping[str, Any],
               reference_word: Optional[int]) -> None:
        spec = device.spec
        if 'allow_control' in settings:
            device.owner.set_allow_control(settings['allow_control'])
            spec.allow_control = settings['allow_control']
        if 'poll_rate' in settings:
            spec.poll_rate_hz = settings['poll_rate']
        if 'stop_on_shutdown' in settings:
            spec.stop_on_shutdown = settings['stop_on_shutdown']
        if 'reference_timeout' in settings:
            spec.reference_timeout_s = settings['reference_timeout']
            deadman.feed(device, self.clock())
        if reference_word is not None:
            device.owner.set_reference_word(reference_word)
            device.reference_pct = float(settings['speed_reference'])
