"""
What an FC-profile drive reads, and how one poll becomes a reading: two collaborators.

:class:`DriveReadouts` knows the readouts (which parameter each is on a model, whose turn it
is, which value is still current); :class:`FcProfileDecoder` turns a poll's status word,
main actual value and current readouts into a :class:`DeviceReading` (state, trip, details).
Both serve :class:`~drive_bridge.devices.fc_profile_drive.FcProfileDrive`, whatever carries
its telegrams; neither does I/O.
"""

from typing import Callable, Dict, FrozenSet, List, Mapping, Optional, Tuple

from drive_bridge.devices.contracts import (
    DeviceReading, Freshness, SlowReadouts, TRIP_CODE_UNKNOWN)
from drive_bridge.devices.parameters import ParameterSpec
from drive_bridge.protocol import fc_profile, fc_profile_scaling
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.fc_profile import StatusWord

ALWAYS_READ = ('motor_current',)  # every poll; the other readouts take turns
# The reading field each readout fills, where a model has the readout.
READOUT_FIELDS = (('motor_current', 'motor_current'), ('motor_temperature', 'motor_thermal'),
                  ('alarm_word', 'alarm_word'), ('warning_word', 'warning_word'))


def witnesses(status: StatusWord) -> Dict[str, bool]:
    """
    Return, per readout a status bit witnesses, whether the bit says it has something.

    Such a readout counts only while current: read since its bit took its present value (an
    alarm word read before a trip does not name that trip, nor one read during a trip the
    state after the reset), and it is read at once when it has something or is not current.
    """
    return {'alarm_word': status.tripped, 'warning_word': status.flag(fc_profile.STW_WARNING)}


class DriveReadouts:
    """
    The readouts of one drive: their parameters per model, their turns, and what is current.

    ``numbers``: model -> readout name -> parameter number; ``spec_of(number, model)``: the
    parameter's spec; ``overrides``: readout name -> number, on every model.
    """

    def __init__(self, numbers: Mapping[str, Mapping[str, int]],
                 spec_of: Callable[[int, str], ParameterSpec],
                 overrides: Optional[Mapping[str, int]] = None,
                 slow_readouts: Optional[SlowReadouts] = None):
        self.numbers = numbers
        self.spec_of = spec_of
        self.overrides = dict(overrides or {})
        self.slow_readouts = slow_readouts or SlowReadouts(0.0)
        self.read = Freshness()  # the readouts, each with the poll that read it
        self._witnessed: Dict[str, int] = {}  # readout -> the poll since which it is current
        self._by_model: Dict[str, Dict[str, ParameterSpec]] = {}
        self._rotation = 0

    def of_model(self, model: str) -> Dict[str, ParameterSpec]:
        """Return readout name -> parameter spec on ``model`` (built once a model)."""
        if model not in self._by_model:
            numbers = dict(self.numbers[model], **self.overrides)
            self._by_model[model] = {name: self.spec_of(number, model)
                                     for name, number in numbers.items()}
        return self._by_model[model]

    def fields(self, model: str) -> FrozenSet[str]:
        """Return speed feedback and the reading fields the readouts of ``model`` fill."""
        names = set(self.of_model(model))
        return frozenset({'speed_feedback'} | {field_name for field_name, readout
                                               in READOUT_FIELDS if readout in names})

    def next_rotating(self, model: str, now_s: float) -> Optional[str]:
        """Return the slow readout whose turn it is, if the poll begun at ``now_s`` reads one."""
        rotating = [name for name in self.of_model(model) if name not in ALWAYS_READ]
        if not rotating or not self.slow_readouts.due(now_s):
            return None
        name = rotating[self._rotation % len(rotating)]
        self._rotation += 1
        return name

    def take_status(self, model: str, status: StatusWord, read: List[str]) -> List[str]:
        """Note the status word just read; return the witnessed readouts to fetch at once."""
        wanted = []
        for name, on in witnesses(status).items():
            self._witnessed[name] = self.read.hold(name, on)
            stale = self.read.read_in(name) is not None and self.current(name) is None
            if on or stale:
                wanted.append(name)
        return [name for name in wanted if name in self.of_model(model) and name not in read]

    def take(self, name: str, value: object) -> None:
        """Keep the decoded value of readout ``name`` (display units), read in this poll."""
        self.read.take(name, value)

    def current(self, name: str) -> object:
        """Return readout ``name`` as last read, or None where its status bit changed since."""
        return self.read.current(name, self._witnessed.get(name, 0))

    def values(self, model: str) -> Dict[str, object]:
        """Return the current value (or None) of every readout of ``model``."""
        return {name: self.current(name) for name in self.of_model(model)}

    def forget(self) -> None:
        """Forget every value read: the drive may come back as another one."""
        self.read.forget()


class FcProfileDecoder:
    """
    One poll of an FC-profile drive into a reading: state, readouts, trip and details.

    It keeps one fact between polls: whether the drive has reached its reference since the
    start command (a drive not started yet reads "on reference" too).
    """

    def __init__(self, alarm_bits: Mapping[int, Tuple[int, str]],
                 warning_bits: Mapping[int, str], extended_status_bits: Mapping[int, str],
                 current_scale: float = 1.0):
        self.alarm_bits = alarm_bits
        self.warning_bits = warning_bits
        self.extended_status_bits = extended_status_bits
        self.current_scale = current_scale
        self.reached_reference = False

    def forget(self) -> None:
        """Forget the reference reached: the drive may come back as another one."""
        self.reached_reference = False

    def reading(self, status_word: int, actual_word: int, steady: Optional[Command],
                values: Mapping[str, object], identity: Mapping[str, str],
                control: Mapping[str, str]) -> DeviceReading:
        """
        Return the reading of one poll.

        ``steady``: the command in force; ``values``: the current readouts (None: not
        current); ``identity`` (model, drive type ...) and ``control`` (control word sent,
        reference) head the details, around the status flags and the main actual value.
        """
        commanded_run = None if steady is None else steady is Command.START
        status = StatusWord(status_word)
        if not commanded_run:
            self.reached_reference = False
        elif status.flag(fc_profile.STW_RUNNING) and status.flag(fc_profile.STW_ON_REFERENCE):
            # Running on reference: a drive that has not started yet reads "on reference"
            # too (stopped at its output), which must not end 'starting' before it began.
            self.reached_reference = True
        reading = DeviceReading(
            state=status.state(commanded_run, self.reached_reference),
            status_word=status_word,
            speed_feedback_pct=fc_profile_scaling.word_to_percent(actual_word))
        self._fill_readouts(reading, values)
        self._fill_trip(reading, status)
        self._fill_details(reading, status, actual_word, values, identity, control)
        return reading

    def _fill_readouts(self, reading: DeviceReading, values: Mapping[str, object]) -> None:
        if values.get('motor_current') is not None:
            reading.motor_current_a = float(values['motor_current']) * self.current_scale
        if values.get('motor_thermal') is not None:
            reading.motor_temperature_pct = float(values['motor_thermal'])
        if values.get('alarm_word') is not None:
            reading.alarm_word = int(values['alarm_word'])
        if values.get('warning_word') is not None:
            reading.warning_word = int(values['warning_word'])

    def _fill_trip(self, reading: DeviceReading, status: StatusWord) -> None:
        if not status.tripped:
            return
        code, name = self.trip_from_alarm_word(reading.alarm_word)
        reading.trip_code, reading.trip_name = code, name
        locked = ' (trip locked: cycle the mains power)' if \
            status.flag(fc_profile.STW_TRIP_LOCKED) else ''
        reading.fault = f'tripped: {name}{locked}'

    def trip_from_alarm_word(self, alarm_word: Optional[int]) -> Tuple[int, str]:
        """Return (trip code, names of the set bits); unknown code while no bit is read."""
        if not alarm_word:
            return TRIP_CODE_UNKNOWN, 'tripped (alarm word not read yet or empty)'
        codes = [self.alarm_bits.get(index, (1000 + index, f'alarm word bit {index}'))
                 for index in range(32) if alarm_word >> index & 1]
        return codes[0][0], ', '.join(name for _, name in codes)

    def _fill_details(self, reading: DeviceReading, status: StatusWord, actual_word: int,
                      values: Mapping[str, object], identity: Mapping[str, str],
                      control: Mapping[str, str]) -> None:
        details = dict(identity)
        details.update({name: str(value) for name, value in status.flags().items()})
        details['main_actual_value'] = f'0x{actual_word:04X}'
        details.update(control)
        for name, value in values.items():
            if value is not None:
                details[name] = f'{value:g}' if isinstance(value, float) else str(value)
        reading.warnings.extend(status.warnings())
        if reading.warning_word:
            details['warnings'] = bit_names(reading.warning_word, self.warning_bits)
        extended = values.get('extended_status')
        if isinstance(extended, int):
            details['extended_status'] = bit_names(extended, self.extended_status_bits)
        if not status.bus_control:
            reading.warnings.append('local operation: the drive ignores bus commands')
        reading.details = details


def bit_names(word: int, names: Mapping[int, str]) -> str:
    """Return the names of the set bits of ``word`` (``bit <n>`` where unnamed), or none."""
    set_bits = [names.get(index, f'bit {index}') for index in range(32) if word >> index & 1]
    return ', '.join(set_bits) or 'none'
