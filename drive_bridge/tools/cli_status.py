"""``drive-bridge status`` and ``monitor``: a device's decoded reading, once or once a period."""

import time
from typing import List

from drive_bridge.devices.contracts import DeviceReading
from drive_bridge.errors import TransportError
from drive_bridge.tools.cli_session import Session, with_session
from drive_bridge.tools.cli_target import CliError, EXIT_OK


# Details that repeat the state or the trip as the raw code the device gave: the state's
# name and the trip's text are printed instead (as the node publishes them on <name>/state
# and <name>/trip), and an unknown state code is named in a warning line.
RAW_CODE_DETAILS = frozenset({'state_code', 'trip_code_register', 'trip_code_reply',
                              'mcd200_state'})


def trip_text(reading: DeviceReading) -> str:
    """Return the trip as a user reads it: its text and code (the node's trip, trip_code)."""
    if not reading.trip_code and not reading.trip_name:
        return 'none'
    return f'{reading.trip_name or "code not known"} (trip code {reading.trip_code})'


def reading_lines(reading: DeviceReading) -> List[str]:
    """Return a reading as 'key: value' lines, in the words a user reads."""
    lines = [f'state: {reading.state}', f'status word: 0x{reading.status_word:04X}',
             f'trip: {trip_text(reading)}']
    for label, value, unit in (('motor current', reading.motor_current_a, 'A'),
                               ('motor temperature', reading.motor_temperature_pct, '%'),
                               ('speed feedback', reading.speed_feedback_pct, '%')):
        if value is not None:
            lines.append(f'{label}: {value:.1f} {unit}')
    for label, word in (('alarm word', reading.alarm_word),
                        ('warning word', reading.warning_word)):
        if word is not None:
            lines.append(f'{label}: 0x{word:08X}')
    lines += [f'{key}: {value}' for key, value in reading.details.items()
              if key not in RAW_CODE_DETAILS]
    lines += [f'warning: {text}' for text in reading.warnings]
    if reading.fault:
        lines.append(f'fault: {reading.fault}')
    return lines


def command_status(args, out) -> int:
    """Print one device's decoded status."""
    def status(session: Session) -> None:
        lines = reading_lines(session.poll())
        print(f'{session.name}: {session.device.family} {session.profile.model} at address '
              f'{session.device.address}', file=out)
        for line in lines:
            print(f'  {line}', file=out)
    with_session(args, status)
    return EXIT_OK


def command_monitor(args, out) -> int:
    """Print the decoded status once a period until Ctrl-C (or --count polls)."""
    def monitor(session: Session) -> None:
        polls = 0
        while args.count == 0 or polls < args.count:
            started = time.monotonic()
            try:
                line = '  '.join(reading_lines(session.poll())[:6])
            except (TransportError, CliError) as error:
                line = f'no reading: {error}'
            print(f'{time.strftime("%H:%M:%S")}  {line}', file=out, flush=True)
            polls += 1
            if args.count == 0 or polls < args.count:
                time.sleep(max(0.0, args.period - (time.monotonic() - started)))
    with_session(args, monitor)
    return EXIT_OK
