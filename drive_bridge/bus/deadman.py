"""
The deadman: a drive whose speed reference messages stop is ramp-stopped.

Armed per device by ``reference_timeout_s`` (0 = off): each reference message from a
topic, and each start sent, pushes the deadline out by the timeout. When it passes while the
bridge holds a run command for the device (in force, or a start that may have run), the bus
queues a stop, once; the next message or start arms it again.
"""

import math

from drive_bridge.bus.device import BusDevice


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
