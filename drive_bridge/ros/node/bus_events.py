"""How the node shows each bus event: a reading or state published, a line in the log."""

from drive_bridge.bus.events import (
    BusEvent, DeviceOffline, DeviceOnline, handler_table, Notice, ReadingEvent, StateUnknown)
from drive_bridge.ros.node.publishers import DevicePublishers


def named(device: str, address: int) -> str:
    """Return a device with its bus address: ``fc1 (address 2)``."""
    return f'{device} (address {address})' if address else device


def _reading(publishers: DevicePublishers, logger, event: ReadingEvent) -> None:
    publishers.publish_reading(event.reading)


def _offline(publishers: DevicePublishers, logger, event: DeviceOffline) -> None:
    publishers.publish_state('offline')
    logger.error(f'{named(event.device, event.address)} offline: {event.message}')


def _unknown(publishers: DevicePublishers, logger, event: StateUnknown) -> None:
    publishers.publish_state('unknown')
    logger.error(f'{event.device}: {event.message}')


def _notice(publishers: DevicePublishers, logger, event: Notice) -> None:
    logger.warning(f'{event.device}: {event.message}')


def _online(publishers: DevicePublishers, logger, event: DeviceOnline) -> None:
    logger.info(f'{named(event.device, event.address)} online')


HANDLERS = handler_table({ReadingEvent: _reading, DeviceOffline: _offline,
                          StateUnknown: _unknown, Notice: _notice, DeviceOnline: _online})


def publish_event(publishers: DevicePublishers, logger, event: BusEvent) -> None:
    """Publish or log ``event`` for its device (bus thread)."""
    HANDLERS[type(event)](publishers, logger, event)
