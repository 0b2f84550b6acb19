"""
The wire trace file: every frame both ways, in pcapng or as text, bounded and rotated.

A :class:`WireTrace` takes :class:`TraceRecord` batches (a frame's bytes, direction, first
and last byte times, the transaction's outcome) from the thread that owns the line and
writes them to ``path`` in the format its extension names (:func:`trace_format`):
``.pcapng`` (Wireshark, :mod:`drive_bridge.protocol.pcapng`) or ``.txt``/``.log`` (one line
a frame, :func:`text_line`). The file is buffered and flushed after each batch (a
transaction's window, a quarantine), so a crash loses at most the transaction under way.

Bounded: once a file would pass ``max_mb``, it is renamed ``trace.1.pcapng`` (the older
ones shift up to ``trace.<files - 1>``, the oldest dropped) and a new one begins with its
own headers, so each file opens alone; the file of a run before (another process) is shifted
so too. A trace reopened in the same process (a command's search that opens the port at each
setting, a node configured again) goes on in the same file: a new pcapng section, which
Wireshark reads as one capture. A write
error (disk full, permission) disables the trace with one logged line; the bus goes on.
Standard library only: the simulator writes its side of the line with the same class.
"""

from dataclasses import dataclass
from datetime import datetime, timedelta
import logging
import os
from typing import BinaryIO, Callable, Iterable, Optional, Tuple

from drive_bridge.errors import ConfigError
from drive_bridge.protocol import pcapng

LOG = logging.getLogger(__name__)
# The trace files this process has written: a trace opened again goes on in its file.
_WRITTEN_IN_THIS_PROCESS: set = set()
FORMATS = {'.pcapng': 'pcapng', '.txt': 'text', '.log': 'text'}
NOMINAL_MODBUS_TCP_PORT = 502  # the server's port in the trace (Wireshark's mbtcp default)
CLIENT_TCP_PORT = 49152  # the master's, in the trace (a nominal ephemeral port)


@dataclass(frozen=True)
class TraceSettings:
    """Where a line's trace goes and how large it may grow: ``path`` '' is off."""

    path: str = ''
    max_mb: float = 10.0
    files: int = 5

    @property
    def enabled(self) -> bool:
        """Return whether a trace is asked for."""
        return bool(self.path)

    @property
    def max_bytes(self) -> int:
        """Return the size one file may reach."""
        return max(4096, int(self.max_mb * 1e6))


@dataclass(frozen=True)
class TraceRecord:
    """
    One frame as the read loop saw it, or one request as it left.

    ``start_ns``/``end_ns``: wall-clock nanoseconds at its first and last byte; ``inbound``:
    received by whoever writes the trace; ``outcome``: see ``docs/wire_trace.md`` ('' none);
    ``protocol``: a key of :data:`~drive_bridge.protocol.pcapng.DISSECTORS` ('' the trace's).
    """

    inbound: bool
    data: bytes
    start_ns: int
    end_ns: int
    outcome: str = ''
    unit: Optional[int] = None
    protocol: str = ''  # whose dissector decodes it, if not the trace's protocol


def trace_format(path: str) -> str:
    """Return 'pcapng' or 'text' by ``path``'s extension; raise ConfigError for others."""
    extension = os.path.splitext(path)[1].lower()
    if extension not in FORMATS:
        raise ConfigError(f'wire trace {path!r}: name the file *.pcapng (Wireshark) or *.txt / '
                          '*.log (text, one line a frame)')
    return FORMATS[extension]


def comment(record: TraceRecord) -> str:
    """Return the record's comment: ``outcome=ok end=+4.62ms unit=3`` (fields as known)."""
    fields = [f'outcome={record.outcome}'] if record.outcome else []
    fields.append(f'end=+{(record.end_ns - record.start_ns) / 1e6:.2f}ms')
    if record.unit is not None:
        fields.append(f'unit={record.unit}')
    return ' '.join(fields)


def text_line(record: TraceRecord, interface: str) -> str:
    """Return one line of the text form (no newline), candump-like; see the docs."""
    seconds, nanoseconds = divmod(record.start_ns, 1_000_000_000)
    moment = datetime.fromtimestamp(seconds) + timedelta(microseconds=nanoseconds // 1000)
    direction = 'RX' if record.inbound else 'TX'
    tail = ' '.join(field for field in (
        record.outcome, f'{(record.end_ns - record.start_ns) / 1e6:.2f}ms',
        '' if record.unit is None else f'unit={record.unit}') if field)
    return (f'{moment:%Y-%m-%d %H:%M:%S.%f} {interface} {direction}  '
            f'{record.data.hex(" ").upper()}  {tail}')


def rotated_name(path: str, index: int) -> str:
    """Return the name of rotated file ``index`` of ``path``: trace.pcapng -> trace.1.pcapng."""
    stem, extension = os.path.splitext(path)
    return f'{stem}.{index}{extension}'


class PcapngForm:
    """Records as pcapng blocks: one interface (the line), upper-PDU packets."""

    def __init__(self, interface: str, protocol: str, server_side: bool = False):
        self.interface = interface
        self.protocol = protocol
        self.server_side = server_side  # the simulator's trace: its inbound frames are queries

    def header(self) -> bytes:
        """Return the Section Header and Interface Description blocks."""
        return pcapng.section_header() + pcapng.interface_description(
            self.interface, f'drive_bridge {self.protocol}')

    def encode(self, record: TraceRecord) -> bytes:
        """Return the Enhanced Packet Block of ``record``."""
        protocol = record.protocol or self.protocol
        ports: Optional[Tuple[int, int]] = None
        if protocol == 'modbus_tcp':  # a query goes to port 502: mbtcp tells them apart so
            ports = (NOMINAL_MODBUS_TCP_PORT, CLIENT_TCP_PORT) if record.inbound != \
                self.server_side else (CLIENT_TCP_PORT, NOMINAL_MODBUS_TCP_PORT)
        packet = pcapng.exported_pdu(pcapng.DISSECTORS[protocol], record.data, ports)
        return pcapng.enhanced_packet(0, record.start_ns, packet, record.inbound,
                                      comment(record))


class TextForm:
    """Records as lines of text, after one header line."""

    def __init__(self, interface: str, protocol: str, server_side: bool = False):
        self.interface = interface
        self.protocol = protocol

    def header(self) -> bytes:
        """Return the header line (starts with '#')."""
        return f'# drive_bridge wire trace: {self.interface} {self.protocol}\n'.encode()

    def encode(self, record: TraceRecord) -> bytes:
        """Return the line of ``record``."""
        return (text_line(record, self.interface) + '\n').encode()


class WireTrace:
    """
    One line's trace file; see the module docstring. One thread uses it at a time.

    The bus's lines write it from a thread of its own (:mod:`.trace_writer`); closed, it
    goes on in its file at the next record.
    """

    def __init__(self, settings: TraceSettings, interface: str, protocol: str,
                 server_side: bool = False,
                 opener: Callable[[str], BinaryIO] = lambda path: open(path, 'wb'),
                 appender: Callable[[str], BinaryIO] = lambda path: open(path, 'ab')):
        self.settings = settings
        self.format = trace_format(settings.path)
        form = PcapngForm if self.format == 'pcapng' else TextForm
        self.form = form(interface, protocol, server_side)
        self._open = opener
        self._append = appender
        self._file: Optional[BinaryIO] = None
        self._size = 0
        self._started = False  # a file was opened (the one of a run before shifted first)
        self.enabled = True
        self.records = 0  # written since the start (all files)

    def write(self, records: Iterable[TraceRecord]) -> None:
        """Write ``records`` and flush; a write error disables the trace (one log line)."""
        if not self.enabled:
            return
        try:
            for record in records:
                self._put(self.form.encode(record))
                self.records += 1
            if self._file is not None:
                self._file.flush()
        except (OSError, ValueError) as error:
            self.fail(error)

    def close(self) -> None:
        """Flush and close the file (idempotent)."""
        file, self._file = self._file, None
        if file is not None:
            try:
                file.close()
            except OSError as error:
                self.fail(error)

    def _put(self, block: bytes) -> None:
        if self._file is None:
            self._begin()
        elif self._size + len(block) > self.settings.max_bytes:
            self._rotate()
        self._file.write(block)
        self._size += len(block)

    def _begin(self) -> None:
        """Open the file at the first record: go on in this process's, else start anew."""
        path = os.path.abspath(self.settings.path)
        if path in _WRITTEN_IN_THIS_PROCESS and os.path.exists(path):
            self._started = True
            self._file = self._append(self.settings.path)
            self._size = os.path.getsize(path)
            self._write_header()
            return
        if not self._started and os.path.exists(path):
            self._shift()  # the file of a run before: kept as trace.1
        self._start()

    def _start(self) -> None:
        """Open the file and write its headers."""
        self._started = True
        _WRITTEN_IN_THIS_PROCESS.add(os.path.abspath(self.settings.path))
        self._file = self._open(self.settings.path)
        self._size = 0
        self._write_header()

    def _write_header(self) -> None:
        header = self.form.header()
        self._file.write(header)
        self._size += len(header)

    def _rotate(self) -> None:
        """Close the file, shift the files and start a new one."""
        self._file.close()
        self._file = None
        self._shift()
        self._start()

    def _shift(self) -> None:
        """Rename trace.N to trace.N+1 and the trace to trace.1 (the oldest dropped)."""
        path, keep = self.settings.path, self.settings.files - 1
        if keep < 1:
            os.remove(path)
        else:
            for index in range(keep - 1, 0, -1):
                if os.path.exists(rotated_name(path, index)):
                    os.replace(rotated_name(path, index), rotated_name(path, index + 1))
            os.replace(path, rotated_name(path, 1))

    def fail(self, error: Exception) -> None:
        """Disable the trace with one line (once); the line goes on untraced."""
        if not self.enabled:
            return
        self.enabled = False
        file, self._file = self._file, None
        if file is not None:
            try:
                file.close()
            except OSError:
                pass
        LOG.error('wire trace %s stopped: %s (the bus goes on untraced; free the disk or fix '
                  'the permission and restart to trace again)', self.settings.path, error)
