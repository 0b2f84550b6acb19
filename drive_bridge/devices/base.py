"""Types every device family shares: transactions it asks for and readings it returns."""

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

# The commands of the ROS contract (std_srvs/Trigger services).
COMMANDS = ('start', 'stop', 'quick_stop', 'reset', 'coast_stop')

# State names of the ROS contract (`<name>/state`).
STATES = (
    'ready', 'starting', 'running', 'stopping', 'restart_delay', 'tripped', 'program_mode',
    'jog_forward', 'jog_reverse', 'not_ready', 'offline', 'unknown',
)


@dataclass(frozen=True)
class ReadRegisters:
    """Read ``count`` holding registers (function 03) from frame address ``address``."""

    address: int
    count: int


@dataclass(frozen=True)
class WriteRegister:
    """Write one holding register (function 06) at frame address ``address``."""

    address: int
    value: int


Transaction = object  # ReadRegisters | WriteRegister; later families add their own.


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
    """The writes that carry out one command, in order."""

    command: str
    writes: Tuple[object, ...]
