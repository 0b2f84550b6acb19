"""
The ``/diagnostics`` status of one device, from a bus snapshot (contract: level, name, values).

Levels: ERROR when the device is offline, unread, unknown (every poll refused), tripped, or
reports a hazard; WARN for warnings, a failed set-up write, a poll that failed since the last
reading, readings older than :data:`STALE_POLLS` poll periods (at least :data:`STALE_MIN_S`:
the line cannot keep the poll rates), or a motor that may be running without an acknowledged
start; OK otherwise. Values
of a reading are shown only with their age: a device whose polls fail shows the failure and
how old the values are, never old values as current.
"""

from typing import Dict, List

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from drive_bridge.bus.master import DeviceSnapshot
from drive_bridge.bus.motor import Motion
from drive_bridge.devices.contracts import DeviceReading
from drive_bridge.ros.naming import status_name  # noqa: F401 - part of this module's API

STALE_POLLS = 3  # readings older than this many poll periods are stale (WARN) ...
STALE_MIN_S = 0.5  # ... and older than this (the host's own delays at high poll rates)


def diagnostic_status(snapshot: DeviceSnapshot, name: str, link: str,
                      commands: str = 'enabled') -> DiagnosticStatus:
    """Return the DiagnosticStatus of one device; ``name`` from :func:`status_name`."""
    status = DiagnosticStatus(
        name=name, hardware_id=f'{snapshot.family} {snapshot.model} address {snapshot.unit}')
    reading = snapshot.reading
    values = {'link': link, 'online': str(snapshot.online), 'commands': commands,
              'allow_control': str(snapshot.allow_control), 'motor': snapshot.motor,
              'control_image': snapshot.control}
    if snapshot.online is not True or reading is None:
        status.level = DiagnosticStatus.ERROR
        prefix = 'offline' if snapshot.online is False else 'no reading'
        status.message = f'{prefix}: {snapshot.status_text}'
    else:
        values.update(reading_values(reading))
        values['reading_age_s'] = f'{snapshot.reading_age_s:.2f}'
        status.level, status.message = _level(snapshot, reading)
    values.update(snapshot.stats)
    status.values = [KeyValue(key=key, value=str(value)) for key, value in values.items()]
    return status


def _level(snapshot: DeviceSnapshot, reading: DeviceReading) -> tuple:
    if reading.fault:
        return DiagnosticStatus.ERROR, reading.fault
    warnings: List[str] = list(reading.warnings)
    if snapshot.poll_failure:
        warnings.append(f'last poll failed ({snapshot.poll_failure}); values are '
                        f'{snapshot.reading_age_s:.1f} s old')
    elif stale(snapshot):
        warnings.append(
            f'readings are {snapshot.reading_age_s:.1f} s old at poll_rate '
            f'{1 / snapshot.poll_period_s:g} Hz (more than {STALE_POLLS} poll periods): the '
            "line may be too slow for the poll rates; lower this device's poll_rate or the "
            "other devices'")
    if snapshot.stats.get('setup_error'):
        warnings.append(snapshot.stats['setup_error'])
    if snapshot.motion is Motion.MAY_RUN:
        warnings.append(f'motor {snapshot.motor}')
    if warnings:
        return DiagnosticStatus.WARN, '; '.join(warnings)
    return DiagnosticStatus.OK, reading.state


def stale(snapshot: DeviceSnapshot) -> bool:
    """Return whether the reading is older than a few poll periods (the line lags behind)."""
    limit_s = max(STALE_POLLS * snapshot.poll_period_s, STALE_MIN_S)
    return snapshot.poll_period_s > 0 and snapshot.reading_age_s > limit_s


def reading_values(reading: DeviceReading) -> Dict[str, str]:
    """Return every field of a reading as text key/values."""
    values = {'state': reading.state, 'status_word': f'0x{reading.status_word:04X}',
              'trip_code': str(reading.trip_code), 'trip': reading.trip_name}
    if reading.motor_current_a is not None:
        values['motor_current_a'] = f'{reading.motor_current_a:.1f}'
    if reading.motor_temperature_pct is not None:
        values['motor_temperature_pct'] = f'{reading.motor_temperature_pct:.0f}'
    if reading.speed_feedback_pct is not None:
        values['speed_feedback_pct'] = f'{reading.speed_feedback_pct:.2f}'
    for key in ('alarm_word', 'warning_word'):
        if getattr(reading, key) is not None:
            values[key] = f'0x{getattr(reading, key):08X}'
    values.update(reading.details)
    return values
