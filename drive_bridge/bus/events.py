"""
What the bus tells its listener: one frozen dataclass per kind of event, dispatched by type.

Every event names its device and carries ``stamp_s``, the bus clock when it happened: for a
reading (and the reading that brings a device online), when the reply carrying its process
data arrived. A consumer dispatches through a table built by :func:`handler_table`, which
refuses a table that leaves an event type out, so a new kind of event cannot be dropped
unnoticed by a consumer that was written before it.
"""

from dataclasses import dataclass
from typing import Any, Callable, Dict, Mapping, Tuple, Type

from drive_bridge.devices.contracts import DeviceReading


@dataclass(frozen=True, kw_only=True)
class BusEvent:
    """The base of every bus event: the device and when it happened (bus clock, s)."""

    device: str
    stamp_s: float


@dataclass(frozen=True, kw_only=True)
class ReadingEvent(BusEvent):
    """A poll cycle ended with a reading; ``stamp_s``: its process data's reply arrived."""

    reading: DeviceReading


@dataclass(frozen=True, kw_only=True)
class DeviceOnline(BusEvent):
    """The device answers again (or for the first time); a ReadingEvent follows."""

    reading: DeviceReading
    address: int = 0  # the device's bus address, for messages (0: not given)


@dataclass(frozen=True, kw_only=True)
class DeviceOffline(BusEvent):
    """The device stopped answering, or the link was lost; its values are gone."""

    message: str
    address: int = 0  # the device's bus address, for messages (0: not given)


@dataclass(frozen=True, kw_only=True)
class StateUnknown(BusEvent):
    """The device answers but cannot be read (refused polls, a model mismatch)."""

    message: str


@dataclass(frozen=True, kw_only=True)
class Notice(BusEvent):
    """Something a user should read in the log (a run ended by a trip, a deadman stop)."""

    message: str


#: Every event type the bus emits: each consumer's table handles each of them.
EVENT_TYPES: Tuple[Type[BusEvent], ...] = (
    ReadingEvent, DeviceOnline, DeviceOffline, StateUnknown, Notice)

Listener = Callable[[BusEvent], None]
Handler = Callable[..., None]


def ignore(*_args: Any) -> None:
    """Handle an event a consumer has no use for (named in its table, so never forgotten)."""


def handler_table(handlers: Mapping[Type[BusEvent], Handler]) -> Dict[Type[BusEvent], Handler]:
    """Return ``handlers`` as a dispatch table; raise TypeError unless it has every event type."""
    missing = [kind.__name__ for kind in EVENT_TYPES if kind not in handlers]
    unknown = [getattr(kind, '__name__', repr(kind)) for kind in handlers
               if kind not in EVENT_TYPES]
    if missing or unknown:
        raise TypeError(f'bus event handlers: missing {", ".join(missing) or "none"}; '
                        f'not bus events: {", ".join(unknown) or "none"}')
    return dict(handlers)
