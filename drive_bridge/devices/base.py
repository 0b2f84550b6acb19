"""Types every device family shares: transactions it asks for and readings it returns."""

from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Tuple

# The commands of the ROS contract (std_srvs/Trigger services).
COMMANDS = ('start', 'stop', 'quick_stop', 'reset', 'coast_stop')

# State names of the ROS contract (`<name>/state`).
STATES = (
    'ready', 'starting', 'running', 'stopping', 'restart_delay', 'tripped', 'program_mode',
    'jog_forward', 'jog_reverse', 'not_ready', 'offline', 'unknown',
)


@dataclass(frozen=True)
class ReadRegisters:
    """
    Read ``count`` holding registers (function 03) from frame address ``address``.

    ``exact``: the reply must carry ``count`` registers; False for text parameters, which
    the FC series answers with fewer registers when the text is shorter (manual 004, 5.4.4).
    """

    address: int
    count: int
    exact: bool = True


@dataclass(frozen=True)
class WriteRegister:
    """Write one holding register (function 06) at frame address ``address``."""

    address: int
    value: int


@dataclass(frozen=True)
class WriteRegisters:
    """Write several holding registers (function 10) from frame address ``address``."""

    address: int
    values: Tuple[int, ...]


@dataclass(frozen=True)
class ReadCoils:
    """Read ``count`` coils (function 01) from coil address ``address`` (coil number - 1)."""

    address: int
    count: int


@dataclass(frozen=True)
class WriteCoils:
    """Write coils (function 0F) from coil address ``address``; ``values`` one bool a coil."""

    address: int
    values: Tuple[bool, ...]


@dataclass(frozen=True)
class WriteCoil:
    """Write one coil (function 05) at coil address ``address``."""

    address: int
    value: bool


@dataclass(frozen=True)
class AsciiCommand:
    """AP ASCII: send command ``code`` (e.g. ``B10``); acknowledged with ACK."""

    code: str


@dataclass(frozen=True)
class AsciiRequest:
    """AP ASCII: send request ``code`` (e.g. ``C22``); the reply is 'status' or 'data'."""

    code: str
    reply: str = 'status'


WRITES = (WriteRegister, WriteRegisters, WriteCoils, WriteCoil, AsciiCommand)
Transaction = object  # one of the dataclasses above


@dataclass
class DeviceReading:
    """
    One decoded poll of a device, in the units of the ROS contract.

    Optional fields are None where the device or model does not report them.
    ``details`` carries every decoded field as text for /diagnostics; ``warnings`` lists
    conditions that make the diagnostics level WARN; ``fault`` (tripped) makes it ERROR.
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


@dataclass(frozen=True)
class CommandPlan:
    """
    The writes that carry out one command, in order.

    ``on_acknowledged`` runs on the bus thread once every write was acknowledged: a profile
    that keeps state (the drives' control word) commits it there, never before.
    ``on_failed`` runs when a write was refused or got no valid reply (then the device may
    or may not have executed it): a profile that rewrites its command every cycle must then
    never rewrite a run over the stop that was asked for (it keeps the stop, drops a start).
    """

    command: str
    writes: Tuple[object, ...]
    on_acknowledged: Optional[Callable[[], None]] = None
    on_failed: Optional[Callable[[], None]] = None


@dataclass(frozen=True)
class PollItem:
    """
    One transaction of a poll, with the key its result is decoded under.

    An ``optional`` item that the device refuses (a Modbus exception) does not fail the
    poll: its result is the :class:`~drive_bridge.errors.DeviceException` instead.
    """

    transaction: object
    key: str = ''
    optional: bool = False


@dataclass(frozen=True)
class ParameterPlan:
    """The transactions of one parameter access and how to turn their results into a value."""

    label: str
    transactions: Tuple[object, ...]
    decode: Callable[[list], object]
