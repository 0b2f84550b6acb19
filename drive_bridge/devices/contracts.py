"""
The contracts between a device family and the bus: what a profile is, and what it can do.

A *profile* (:class:`DeviceProfile`) knows one device's register map or telegrams: how to
read it (a poll cycle), which writes carry out a command, and how to explain the device's
errors. It keeps no command state of its own: which command is in force is decided by the
bus's motor-state owner (:mod:`drive_bridge.bus.motor`), which hands the profile a read-only
:class:`ControlView` whenever the profile builds a write.

A poll cycle is a generator (:data:`PollCycle`): it yields one :class:`PollStep` at a time,
receives the step's result, and returns the decoded :class:`DeviceReading`. The bus asks for
the next step only when it is about to send it, so a write built from the control view (the
drives' keepalive) always carries what is in force at that moment, even when a command was
sent between two steps of the same cycle.

A profile has no clock: the bus gives each poll cycle the time it begins on the bus's clock
(``now_s``), and the profile schedules its slow readouts by that (:class:`SlowReadouts`), so
a bus on a virtual clock (a soak's virtual line, a test's fake clock) reads them once a
readout period of its own time, as a bus on the wall clock does. What a profile reads slowly
it keeps with the poll that read it (:class:`Freshness`): such a value decides or refines a
state, a trip or a published field only while it is at least as fresh as the fast values it
would override.

Optional capabilities are abstract classes that a profile class inherits explicitly; the bus
asks ``isinstance(profile, Capability)`` and never probes attributes:

- :class:`CyclicControl`: once a command is in force, the device is driven by a control
  image the bridge rewrites every poll (drives' control word, the LVSG output image);
- :class:`SpeedReference`: the device takes a speed reference in percent (FC scaling);
- :class:`ParameterAccess`: parameters by number (read, write, backup);
- :class:`SetupWrites`: settings written each time the device comes online.
"""

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import (
    Any, Callable, Dict, FrozenSet, Generator, List, Mapping, Optional, Sequence, Tuple)

from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import Request

# State names of the ROS contract (`<name>/state`).
STATES = (
    'ready', 'starting', 'running', 'stopping', 'restart_delay', 'tripped', 'program_mode',
    'jog_forward', 'jog_reverse', 'not_ready', 'offline', 'unknown',
)
# The contract's trip code for "tripped, but the device did not say why".
TRIP_CODE_UNKNOWN = 65535
# The optional fields of a reading, each published on its own topic where a device has it.
READING_FIELDS = ('motor_current', 'motor_temperature', 'speed_feedback', 'alarm_word',
                  'warning_word')


@dataclass
class DeviceReading:
    """
    One decoded poll of a device, in the units of the ROS contract.

    Optional fields are None where the device or model does not report them. ``details``
    carries every decoded field as text for /diagnostics; ``warnings`` lists conditions that
    make the diagnostics level WARN; ``fault`` (tripped, or a hazard) makes it ERROR.
    ``trip_code`` is 0 when not tripped and :data:`TRIP_CODE_UNKNOWN` when tripped for a
    reason the device did not report.
    """

    state: str
    status_word: int
    trip_code: int = 0
    trip_name: str = ''
    motor_current_a: Optional[float] = None
    motor_temperature_pct: Optional[float] = None
    speed_feedback_pct: Optional[float] = None
    alarm_word: Optional[int] = None
    warning_word: Optional[int] = None
    details: Dict[str, str] = field(default_factory=dict)
    warnings: List[str] = field(default_factory=list)
    fault: str = ''

    @property
    def tripped(self) -> bool:
        """Return whether the device reports a trip."""
        return self.state == 'tripped'


@dataclass(frozen=True)
class PollStep:
    """
    One transaction of a poll cycle.

    ``optional``: a refusal by the device (and, for a write, any failure) is handed back to
    the cycle as the result (the error object) instead of failing the poll. ``retry``: the
    bus may repeat the request after a lost or garbled reply (reads; never a write).
    ``stamps``: the reply carries the reading's process data (status, speed); the time it
    was received stamps the reading (joint states).
    """

    request: Request
    optional: bool = False
    retry: bool = True
    stamps: bool = False


# A poll cycle: yields steps, receives each step's result, returns the reading.
PollCycle = Generator[PollStep, Any, DeviceReading]


@dataclass(frozen=True)
class PollShape:
    """
    The most a poll cycle puts on the line, once the device is identified.

    ``transactions``: the most one poll takes (every readout due, a trip and a warning
    read at once); ``writes``: the writes before its first read (a probe of a silent
    device sends them too); ``online``: the transactions each time it comes online
    (identity reads, set-up writes).
    """

    transactions: int = 1
    writes: int = 0
    online: int = 0


@dataclass(frozen=True)
class CommandPlan:
    """The writes that carry out one command, in order (sent as one job)."""

    command: Command
    writes: Tuple[Request, ...]


@dataclass(frozen=True)
class ParameterOptions:
    """How to access a parameter the tables do not describe, or how to store a write."""

    data_type: Optional[str] = None
    conversion: Optional[int] = None
    index: Optional[int] = None
    eeprom: bool = False


@dataclass(frozen=True)
class ParameterPlan:
    """The transactions of one parameter access and how to turn their results into a value."""

    label: str
    transactions: Tuple[Request, ...]
    decode: Callable[[list], Any]


class ControlView(ABC):
    """What the motor-state owner has in force for one device, read-only, for the profile."""

    @property
    @abstractmethod
    def steady(self) -> Optional[Command]:
        """
        Return the command the cyclic image carries now (None: write no control data).

        Always None while writes are not allowed (monitor only).
        """

    @property
    @abstractmethod
    def reference_word(self) -> int:
        """Return the speed reference word in force (drives; 0 otherwise)."""

    @property
    @abstractmethod
    def writes_allowed(self) -> bool:
        """Return whether anything may be written to the device (False: monitor only)."""


class FixedControl(ControlView):
    """A control view with fixed values: for tools and tests that run a profile directly."""

    def __init__(self, steady: Optional[Command] = None, reference_word: int = 0,
                 writes_allowed: bool = True):
        self._steady = steady
        self._reference_word = reference_word
        self._writes_allowed = writes_allowed

    @property
    def writes_allowed(self) -> bool:
        """Return the fixed permission."""
        return self._writes_allowed

    @property
    def steady(self) -> Optional[Command]:
        """Return the fixed steady command (None when writes are not allowed)."""
        return self._steady if self._writes_allowed else None

    @property
    def reference_word(self) -> int:
        """Return the fixed reference word."""
        return self._reference_word


class SlowReadouts:
    """
    When a device's slow readouts are due: at most one poll in ``period_s`` reads them.

    The fast values (status, current, speed) are read every poll; the slow ones (an FC
    drive's frequency, thermal load and status words in turn, an MCD's product registers, the
    LVSG operating parameters) only when due. ``period_s`` 0 reads them every poll. The time
    is the bus's, as the poll began (``now_s`` of :meth:`DeviceProfile.poll`): a schedule of
    its own would follow the wall clock while a bus runs on a virtual one.
    """

    def __init__(self, period_s: float = 1.0):
        self.period_s = period_s
        self._next_s = -float('inf')

    def due(self, now_s: float) -> bool:
        """
        Return whether the poll that began at ``now_s`` reads slow readouts.

        If so, count it as the one that does: the next is due ``period_s`` later.
        """
        if now_s < self._next_s:
            return False
        self._next_s = now_s + self.period_s
        return True


class Freshness:
    """
    What a profile read, each value stamped with the poll that read it: the freshest decides.

    A profile counts its polls (:meth:`begin_poll`), keeps each slowly read value with the
    number of the poll that read it (:meth:`take`), and notes every poll the fast signals it
    reads or is given (the status bits, the command in force) with :meth:`hold`, which says
    since which poll a signal has had its present value. A slow value may decide or refine
    something only while it is :meth:`current`: read at or after the poll in which the
    newest of the fast signals it would override took its value. An LVSG state byte read
    during a start says nothing about the ramp that began when the motor was stopped later,
    and an alarm word read before a trip does not name that trip.
    """

    def __init__(self) -> None:
        self.poll = 0
        self._read: Dict[Any, Tuple[Any, int]] = {}  # key -> (value, poll that read it)
        self._held: Dict[Any, Tuple[Any, int]] = {}  # signal -> (value, poll it began)

    def begin_poll(self) -> int:
        """Count a new poll; return its number."""
        self.poll += 1
        return self.poll

    def take(self, key: Any, value: Any) -> None:
        """Keep ``value`` of ``key``, read in this poll."""
        self._read[key] = (value, self.poll)

    def get(self, key: Any, default: Any = None) -> Any:
        """Return the last value read of ``key``, however old (``default``: never read)."""
        return self._read[key][0] if key in self._read else default

    def read_in(self, key: Any) -> Optional[int]:
        """Return the poll that last read ``key`` (None: never read)."""
        return self._read[key][1] if key in self._read else None

    def hold(self, signal: Any, value: Any) -> int:
        """Note a fast signal's value in this poll; return the poll since which it has it."""
        held = self._held.get(signal)
        if held is None or held[0] != value:
            held = self._held[signal] = (value, self.poll)
        return held[1]

    def current(self, key: Any, since: int, default: Any = None) -> Any:
        """Return the value of ``key`` if it was read in poll ``since`` or later, else default."""
        read = self._read.get(key)
        return read[0] if read is not None and read[1] >= since else default

    def is_current(self, key: Any, since: int) -> bool:
        """Return whether ``key`` was read in poll ``since`` or later."""
        read = self._read.get(key)
        return read is not None and read[1] >= since

    def drop(self, key: Any) -> None:
        """Forget the value of ``key`` (the device refused to read it)."""
        self._read.pop(key, None)

    def forget(self) -> None:
        """Forget every value and signal (offline: the device may come back as another)."""
        self._read.clear()
        self._held.clear()


class DeviceProfile(ABC):
    """
    One device's map, poll cycle, commands and error texts; see the module docstring.

    ``commands``: the commands the device takes (one service each). ``reading_fields``: the
    optional reading fields it can report (one topic each, :data:`READING_FIELDS`).
    """

    family: str = ''
    commands: FrozenSet[Command] = frozenset()

    def __init__(self, configured_model: str):
        self.configured_model = configured_model
        self.resolved_model: Optional[str] = None if configured_model == 'auto' \
            else configured_model

    @property
    def model(self) -> str:
        """Return the model in use: as read from the device, else as configured."""
        return self.resolved_model or self.configured_model

    @property
    def reading_fields(self) -> FrozenSet[str]:
        """Return the optional reading fields this device reports (its topics)."""
        return frozenset()

    @abstractmethod
    def poll(self, control: ControlView, now_s: float) -> PollCycle:
        """
        Return a new poll cycle (a generator, see the module docstring).

        ``now_s``: the time the cycle begins on the bus's clock (the slow readouts' schedule).
        """

    @abstractmethod
    def command_plan(self, command: Command, control: ControlView) -> CommandPlan:
        """Return the writes of ``command``; raise CommandRefused if the device has none."""

    def check_command(self, command: Command, reading: Optional[DeviceReading]) -> None:
        """Raise CommandRefused for a command the device would ignore now (nothing sent)."""

    @abstractmethod
    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a refusal (exception) code of this device."""

    def detail_request(self, code: int) -> Optional[Request]:
        """Return a read that explains refusal ``code`` further (FC: register 7), or None."""
        return None

    def on_offline(self) -> None:
        """Forget what was read: the device is offline (it may come back as another one)."""

    def describe_control(self, control: ControlView) -> str:
        """Return what the cyclic image carries, in words, for /diagnostics."""
        return 'none'

    def poll_shape(self) -> PollShape:
        """Return the most a poll of this device puts on the line (the keepalive rule)."""
        return PollShape()


class CyclicControl(ABC):
    """
    Capability: once a command is in force, the bridge rewrites a control image every poll.

    The image's run bit is the motor-state owner's to decide (``ControlView.steady``): the
    profile writes it as the view says, and nothing while the view's steady command is None.
    """


class SpeedReference(ABC):
    """Capability: the device takes a speed reference in percent (FC scaling)."""

    @abstractmethod
    def reference_word(self, percent: float) -> int:
        """Return the 16-bit word of ``percent``; raise CommandRefused if it is not valid."""


class ParameterAccess(ABC):
    """Capability: parameters by number."""

    @abstractmethod
    def parameter_plan(self, number: int, value: Any = None,
                       options: ParameterOptions = ParameterOptions()) -> ParameterPlan:
        """Return the read (``value`` None) or write of parameter ``number``."""

    def parameter_numbers(self) -> Sequence[int]:
        """Return the numbers of the settings a backup saves, in order."""
        return ()

    def parameter_table(self) -> Mapping[int, Any]:
        """Return what is known of each parameter (ParameterSpec by number; may be empty)."""
        return {}


class SetupWrites(ABC):
    """Capability: settings written each time the device comes online (not monitor-only)."""

    @abstractmethod
    def setup_plan(self) -> Sequence[Request]:
        """Return the set-up writes (may be empty)."""

    def setup_labels(self) -> Sequence[str]:
        """Return what each set-up write sets, in words (``par. 8-03 ... = 5.5 s``)."""
        return [request.describe() for request in self.setup_plan()]


@dataclass(frozen=True)
class Family:
    """
    One device family as configuration, node, CLI and simulators see it.

    ``settings``: the device settings this family takes beyond the common ones.
    ``make_profile(model, protocol, options)`` builds a profile from validated options (the
    common and the family settings by name). The family's simulator is not named here: it
    has its own entry on the simulator side (:mod:`drive_bridge.sim.registry`), which
    imports the family, never the reverse.
    """

    name: str
    description: str
    models: Tuple[str, ...]
    address_range: Tuple[int, int]
    protocols: Tuple[str, ...]
    settings: Tuple[Any, ...]
    make_profile: Callable[[str, str, Mapping[str, Any]], DeviceProfile]
    reference: bool = False  # takes a speed reference (drives)
    # (model, options) -> (low, high, what sets the address): a narrower range than
    # ``address_range`` where the model or a setting decides it (MCD: the module's switches).
    model_address_range: Optional[
        Callable[[str, Mapping[str, Any]], Tuple[int, int, str]]] = None
