"""
The deadman: a drive whose speed reference messages stop is ramp-stopped.

Armed per device by ``reference_timeout_s`` (0 = off): each reference message from a
topic, and each start sent, pushes the deadline out by the timeout. When it passes while the
bridge holds a run command for the device (in force, or a start that may have run), the bus
queues a stop, once; the next message or start arms it again.
"""

from concurrent.futures import Future
import functools
import math

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.events import Notice
from drive_bridge.bus.jobs import CommandJob
from drive_bridge.bus.seams import EventSink, JobSink
from drive_bridge.bus.table import DeviceTable
from drive_bridge.protocol.commands import Command


def feed(device: BusDevice, now_s: float) -> None:
    """Push the device's deadline out by its timeout (a reference message, a start)."""
    timeout_s = device.spec.reference_timeout_s
    device.reference_deadline_s = now_s + timeout_s if timeout_s > 0 else math.inf


def expired(device: BusDevice, now_s: float) -> bool:
    """Return whether the deadman must stop ``device`` now (and disarm it if so)."""
    if device.spec.reference_timeout_s <= 0 or now_s < device.reference_deadline_s or \
            not device.owner.holds_run:
        return False
    device.reference_deadline_s = math.inf
    device.deadman_stops += 1
    return True


def message(device: BusDevice) -> str:
    """Return what the deadman did, in words (without the outcome)."""
    return (f'reference timeout ({device.spec.reference_timeout_s:g} s without a speed '
            'reference message): ramp stop')


class Deadman:
    """Queue the deadman's stops on the bus thread and report them; see the module docstring."""

    def __init__(self, devices: DeviceTable, jobs: JobSink, events: EventSink,
                 command_deadline_s: float):
        self.devices = devices
        self.jobs = jobs
        self.events = events
        self.command_deadline_s = command_deadline_s

    def check(self, now_s: float) -> None:
        """Queue a stop for each device whose deadline passed while a run is held."""
        with self.devices.locked():
            stops = [device for device in self.devices if expired(device, now_s)]
        for device in stops:
            future: Future = Future()
            future.add_done_callback(functools.partial(self._report, device, now_s))
            self.jobs.push(CommandJob(device, now_s + self.command_deadline_s, future,
                                      Command.STOP, internal='deadman'))

    def _report(self, device: BusDevice, now_s: float, future: Future) -> None:
        error = future.exception()
        text = message(device) + (f' failed: {error}' if error else ' sent')
        with self.devices.locked():
            device.stats.last_error = text
        self.events.emit(Notice(device=device.name, stamp_s=now_s, message=text))
