"""Typed exceptions shared by every layer; the ROS edge turns them into messages."""

from typing import Any


class DriveBridgeError(Exception):
    """Base class of every error raised by drive_bridge."""


class ConfigError(DriveBridgeError):
    """A configuration value is missing, of the wrong type or out of range."""


class ProtocolError(DriveBridgeError):
    """Bytes or values that do not follow the protocol."""


class TransportError(DriveBridgeError):
    """A transaction failed on the wire; ``kind`` names the failure for statistics."""

    kind = 'transport'


class LinkDown(TransportError):
    """The serial port or TCP connection is not open (missing, refused, unplugged)."""

    kind = 'link'


class NoResponse(TransportError):
    """The device did not answer within the timeout (silence)."""

    kind = 'timeout'


class BadFrame(TransportError):
    """Bytes came back but did not form a valid reply (CRC, garbage, wrong address)."""

    kind = 'bad_frame'


class CrcError(BadFrame):
    """A reply of the right length from the right address whose CRC is wrong (line noise)."""

    kind = 'crc'


class WrongAddress(BadFrame):
    """A reply that starts with another device's address."""

    kind = 'wrong_address'


class TruncatedFrame(BadFrame):
    """Part of a reply came back, then silence until the timeout."""

    kind = 'truncated'


class Nak(BadFrame):
    """AP ASCII: the slave answered NAK: it saw a bad LRC and did not act on the fragment."""

    kind = 'nak'


class AmbiguousReply(BadFrame):
    """Two frames of the unit in one reply window: neither is provably the answer."""

    kind = 'ambiguous'


class MismatchedReply(BadFrame):
    """
    A frame of the unit that cannot answer the request: a late reply to an earlier one.

    It carries another function, register count, echo or parameter, or it was whole before
    the request and a reply could have crossed the wire.
    """

    kind = 'mismatch'


class LineBabble(LinkDown):
    """The line keeps talking past a failed transaction's guard: another master or a fault."""

    kind = 'babble'


# Every transaction failure kind, in the order /diagnostics lists them. Frames discarded as
# late (a reply to an earlier request) are not failures of a transaction: /diagnostics counts
# them apart, against the unit they name (``late_replies``).
FAILURE_KINDS = ('timeout', 'crc', 'wrong_address', 'truncated', 'bad_frame', 'ambiguous',
                 'mismatch', 'exception', 'nak', 'link', 'babble')


class DeviceException(TransportError):
    """The device answered with a Modbus exception code; it did not execute the request."""

    kind = 'exception'

    def __init__(self, code: int, text: str = '', reply: object = None):
        self.code = code
        self.text = text or f'exception code {code:02d}'
        self.reply = reply  # the refusal's own reply, where it carries more (FC protocol)
        super().__init__(self.text)


class CommandRefused(DriveBridgeError):
    """The bridge refused a command before sending anything."""


class MonitorOnly(CommandRefused):
    """A write to a monitor-only device (allow_control false): nothing was sent."""


class CommandExpired(CommandRefused):
    """A command that did not reach the wire within its deadline: it is never sent."""


class ReadBackMismatch(DriveBridgeError):
    """A parameter written reads back another value: the device holds that one (``read``)."""

    def __init__(self, message: str, read: Any = None):
        super().__init__(message)
        self.read = read


class ReadBackFailed(DriveBridgeError):
    """A parameter was written (acknowledged), but reading it back failed: the value is unsure."""


class ModelMismatch(DriveBridgeError):
    """The device reports another model than the configuration names."""


class RecordingError(DriveBridgeError):
    """A bag cannot be recorded or read: unknown topic or type, output exists, not a bag."""
