"""What the bus tells its listener."""

from dataclasses import dataclass
from typing import Optional

from drive_bridge.devices.contracts import DeviceReading


@dataclass
class BusEvent:
    """What the bus tells its listener: a new reading, or a change of link status."""

    device: str
    kind: str  # 'reading', 'offline', 'online', 'error' (state unknown), 'notice' (a log line)
    reading: Optional[DeviceReading] = None
    message: str = ''
    stamp_s: float = 0.0  # the bus clock when the reply carrying the process data arrived
