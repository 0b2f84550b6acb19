"""
Frames as a master receives them: the framer contract every wire protocol fills. Pure.

A framer turns the bytes received so far into frames, with no I/O and no clock, as
pymodbus's framers do (bytes in; frames, errors and "need N more" out). It answers for the
bytes at the start of a buffer with one :class:`Cut`:

- a whole frame (``frame``), valid or corrupt (a bad checksum, a wrong end byte), of
  ``len(frame.raw)`` bytes;
- "need more" (``needed``: the length the frame at the start takes in all, as far as its
  first bytes tell; read up to it and ask again);
- neither: the bytes begin no frame of the protocol (garbage). What follows until the line
  falls silent belongs to that corrupt frame.

The line discipline (:mod:`drive_bridge.transport.exchange`) owns the clock: it decides
where one frame ends and the next begins by the silence between them, which reply window a
frame fell into, and whether a frame is the answer to the request just sent.
"""

from dataclasses import dataclass
from typing import Optional, Protocol


@dataclass(frozen=True)
class Frame:
    """
    One frame received: its bytes, the unit it names, and why it is corrupt, if it is.

    ``unit`` None: the frame names no unit (the AP ASCII replies). ``error`` '' means whole
    and valid; otherwise it says why not, and ``kind`` is the failure kind of
    :data:`drive_bridge.errors.FAILURE_KINDS` it counts as ('crc', 'bad_frame').
    """

    raw: bytes
    unit: Optional[int] = None
    error: str = ''
    kind: str = ''

    @property
    def valid(self) -> bool:
        """Return whether the frame is whole and its checksum holds."""
        return not self.error

    def describe(self) -> str:
        """Return the frame in words, for messages: its unit and length."""
        named = 'naming no unit' if self.unit is None else f'from address {self.unit}'
        state = '' if self.valid else f', {self.error}'
        return f'a frame {named} ({len(self.raw)} bytes{state})'


@dataclass(frozen=True)
class Cut:
    """What a framer makes of the bytes at the start of a buffer (see the module)."""

    frame: Optional[Frame] = None
    needed: int = 0

    @property
    def garbage(self) -> bool:
        """Return whether the bytes begin no frame of the protocol."""
        return self.frame is None and self.needed == 0


class Framer(Protocol):
    """Turns received bytes into frames for one wire protocol; pure (see the module)."""

    #: The bytes of the longest frame (a line talking longer without a pause is babbling).
    max_bytes: int
    #: The bytes a corrupt or cut frame must have to show the unit and kind it answers.
    header_bytes: int
    #: Whether frames name the unit that sent them (AP ASCII's do not).
    names_units: bool

    def cut(self, buffer: bytes) -> Cut:
        """
        Return the frame at the start of ``buffer``, or what it needs; never raise.

        For no bytes at all, what the shortest frame needs: a reply window's first wait.
        """


def frames_in(framer: Framer, data: bytes) -> tuple:
    """
    Return (the whole valid frames in ``data``, the bytes that belong to none).

    For bytes that were discarded (a quarantine, bytes waiting before a request): each
    position that begins a whole valid frame gives that frame; any other byte is counted as
    noise and the scan goes on at the next byte (a receiver resynchronising).
    """
    frames, noise, start = [], 0, 0
    while start < len(data):
        cut = framer.cut(data[start:])
        if cut.frame is not None and cut.frame.valid:
            frames.append(cut.frame)
            start += len(cut.frame.raw)
            continue
        noise += 1
        start += 1
    return tuple(frames), noise
