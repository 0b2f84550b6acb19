"""
A Modbus RTU slave of libmodbus (C, Debian ``libmodbus5``) on a pty, through ctypes.

A peer no one here wrote: libmodbus frames each request by its function code, checks its CRC
and builds the reply from a ``modbus_mapping_t``, and the tests read that mapping to see what
the C side made of the bridge's words.

The arrangement: one pty pair, no second pty and no copy thread. libmodbus serves on the
pty's master, handed to it with ``modbus_set_socket`` (libmodbus's documented call for a
file descriptor of the caller's own); the master under test opens the slave side by its path
(:attr:`LibmodbusSlave.path`), as it opens any serial port. A pty master has no path, and
libmodbus's ``modbus_connect`` only opens a path and sets its termios: on a pty, which has no
wire, baud rate or parity, that set-up changes nothing the tests could see, while each
further pty and thread would be one more hop for the bytes on a busy machine.
``modbus_new_rtu`` still gets the slave's path and 9600 8N2, as a user of libmodbus would
write them. The helper keeps the slave side open too, so the master never reads EIO while
the bridge has its port closed (between reconnects).

libmodbus's own thread loops ``modbus_receive`` / ``modbus_reply`` (ctypes releases the GIL
in each call). An indication timeout of 0.1 s ends each wait for a request, so the loop sees
:meth:`LibmodbusSlave.stop` within that time whatever the other side does. Every request
libmodbus accepted is kept with its CRC (:attr:`LibmodbusSlave.requests`), every one it
refused with libmodbus's reason (:attr:`LibmodbusSlave.errors`: a bad CRC, a frame it could
not make out). A request to another unit makes libmodbus 3.1 take the next frame for that
unit's reply and drop it, so the tests address the peer's unit only.

:func:`load_libmodbus` skips the test, with the package to install, where the library or one
of the calls used here is missing.
"""

import ctypes
import errno
import os
import threading
import tty
from typing import List, Optional, Sequence, Tuple

import pytest

LIBRARY = 'libmodbus.so.5'
SKIP_REASON = 'libmodbus5 not installed: apt install libmodbus5'
MAX_ADU_BYTES = 256  # MODBUS_RTU_MAX_ADU_LENGTH (modbus-rtu.h)
INDICATION_TIMEOUT_US = 100_000
JOIN_TIMEOUT_S = 5.0
Block = Tuple[int, int]  # (first address, count) of one table of the mapping


class Mapping(ctypes.Structure):
    """``modbus_mapping_t`` (modbus.h, libmodbus 3.1): the four tables and their bounds."""

    _fields_ = [
        ('nb_bits', ctypes.c_int), ('start_bits', ctypes.c_int),
        ('nb_input_bits', ctypes.c_int), ('start_input_bits', ctypes.c_int),
        ('nb_input_registers', ctypes.c_int), ('start_input_registers', ctypes.c_int),
        ('nb_registers', ctypes.c_int), ('start_registers', ctypes.c_int),
        ('tab_bits', ctypes.POINTER(ctypes.c_uint8)),
        ('tab_input_bits', ctypes.POINTER(ctypes.c_uint8)),
        ('tab_input_registers', ctypes.POINTER(ctypes.c_uint16)),
        ('tab_registers', ctypes.POINTER(ctypes.c_uint16)),
    ]


# name -> (restype, argtypes) of every libmodbus call used here.
_CONTEXT = ctypes.c_void_p
_QUERY = ctypes.POINTER(ctypes.c_uint8)
_SIGNATURES = {
    'modbus_new_rtu': (_CONTEXT, [ctypes.c_char_p, ctypes.c_int, ctypes.c_char, ctypes.c_int,
                                  ctypes.c_int]),
    'modbus_set_slave': (ctypes.c_int, [_CONTEXT, ctypes.c_int]),
    'modbus_set_socket': (ctypes.c_int, [_CONTEXT, ctypes.c_int]),
    'modbus_set_indication_timeout': (ctypes.c_int, [_CONTEXT, ctypes.c_uint32,
                                                     ctypes.c_uint32]),
    'modbus_mapping_new_start_address': (ctypes.POINTER(Mapping), [ctypes.c_uint] * 8),
    'modbus_receive': (ctypes.c_int, [_CONTEXT, _QUERY]),
    'modbus_reply': (ctypes.c_int, [_CONTEXT, _QUERY, ctypes.c_int, ctypes.POINTER(Mapping)]),
    'modbus_strerror': (ctypes.c_char_p, [ctypes.c_int]),
    'modbus_mapping_free': (None, [ctypes.POINTER(Mapping)]),
    'modbus_free': (None, [_CONTEXT]),
}


def load_libmodbus() -> ctypes.CDLL:
    """Return libmodbus with the signatures used here; skip the test where it is missing."""
    try:
        library = ctypes.CDLL(LIBRARY, use_errno=True)
    except OSError:
        pytest.skip(SKIP_REASON)
    for name, (restype, argtypes) in _SIGNATURES.items():
        function = getattr(library, name, None)
        if function is None:  # modbus_set_indication_timeout: libmodbus 3.1.6 and later
            pytest.skip(f'{LIBRARY} has no {name}: libmodbus 3.1.6 or later is needed')
        function.restype = restype
        function.argtypes = argtypes
    return library


class LibmodbusSlave:
    """
    libmodbus's RTU slave at ``unit`` on a pty of its own; see the module docstring.

    ``coils`` and ``registers`` are the (first address, count) of the mapping's coil and
    holding register tables, in frame addresses; a request outside them gets libmodbus's
    exception 02. Use it as a context manager, or :meth:`start` and :meth:`stop`.
    """

    def __init__(self, unit: int, coils: Block = (0, 0), registers: Block = (0, 0)):
        self.unit = unit
        self.requests: List[bytes] = []
        self.errors: List[str] = []
        self._lib = load_libmodbus()
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._context: Optional[int] = None
        self._mapping = None
        self._master, self._slave = os.openpty()
        try:
            tty.setraw(self._slave)
            self.path = os.ttyname(self._slave)
            self._context = self._new_context()
            self._mapping = self._lib.modbus_mapping_new_start_address(
                coils[0], coils[1], 0, 0, registers[0], registers[1], 0, 0)
            if not self._mapping:
                raise MemoryError('modbus_mapping_new_start_address failed')
        except BaseException:
            self.close()
            raise

    def _new_context(self) -> int:
        lib = self._lib
        context = lib.modbus_new_rtu(self.path.encode(), 9600, b'N', 8, 2)
        if not context:
            raise OSError(ctypes.get_errno(), 'modbus_new_rtu failed')
        lib.modbus_set_slave(context, self.unit)
        lib.modbus_set_socket(context, self._master)
        lib.modbus_set_indication_timeout(context, 0, INDICATION_TIMEOUT_US)
        return context

    # -- the mapping (what libmodbus answers with, and what it stored) ------------------
    def registers(self, address: int, count: int = 1) -> List[int]:
        """Return ``count`` holding registers from frame address ``address``."""
        table = self._mapping.contents
        first = self._index(address, count, table.start_registers, table.nb_registers)
        return [table.tab_registers[first + offset] for offset in range(count)]

    def set_registers(self, address: int, values: Sequence[int]) -> None:
        """Set holding registers from frame address ``address``."""
        table = self._mapping.contents
        first = self._index(address, len(values), table.start_registers, table.nb_registers)
        for offset, value in enumerate(values):
            table.tab_registers[first + offset] = value

    def coils(self, address: int, count: int = 1) -> List[bool]:
        """Return ``count`` coils from coil address ``address`` (coil number - 1)."""
        table = self._mapping.contents
        first = self._index(address, count, table.start_bits, table.nb_bits)
        return [bool(table.tab_bits[first + offset]) for offset in range(count)]

    def set_coils(self, address: int, values: Sequence[bool]) -> None:
        """Set coils from coil address ``address``."""
        table = self._mapping.contents
        first = self._index(address, len(values), table.start_bits, table.nb_bits)
        for offset, value in enumerate(values):
            table.tab_bits[first + offset] = 1 if value else 0

    @staticmethod
    def _index(address: int, count: int, start: int, size: int) -> int:
        if address < start or address + count > start + size:
            raise IndexError(f'addresses {address}-{address + count - 1} are outside the '
                             f'mapping ({start}-{start + size - 1})')
        return address - start

    def requests_seen(self) -> List[bytes]:
        """Return a copy of the requests libmodbus accepted so far, CRC included."""
        with self._lock:
            return list(self.requests)

    # -- the serving thread -------------------------------------------------------------
    def start(self) -> 'LibmodbusSlave':
        """Serve on a thread of its own."""
        self._thread = threading.Thread(target=self._serve, name='libmodbus-slave',
                                        daemon=True)
        self._thread.start()
        return self

    def _serve(self) -> None:
        try:
            self._serve_requests()
        except Exception as error:  # shown by the test's check of errors, not lost
            with self._lock:
                self.errors.append(f'the serving thread failed: {error!r}')

    def _serve_requests(self) -> None:
        lib = self._lib
        query = (ctypes.c_uint8 * MAX_ADU_BYTES)()
        while not self._stopping.is_set():
            length = lib.modbus_receive(self._context, query)
            if length > 0:
                with self._lock:
                    self.requests.append(bytes(query[:length]))
                if lib.modbus_reply(self._context, query, length, self._mapping) < 0:
                    self._note_error('modbus_reply')
            elif length < 0 and ctypes.get_errno() != errno.ETIMEDOUT:
                self._note_error('modbus_receive')
            elif length == 0:  # a request to another unit, or what it took for the reply
                with self._lock:
                    self.errors.append(f'ignored a frame from {query[0]:02x} (not for unit '
                                       f'{self.unit}, or taken for the reply of another)')

    def _note_error(self, call: str) -> None:
        code = ctypes.get_errno()
        reason = self._lib.modbus_strerror(code).decode(errors='replace')
        with self._lock:
            self.errors.append(f'{call}: {reason} (errno {code})')
        if code in (errno.EIO, errno.EBADF):
            self._stopping.set()  # the pty is gone: nothing more will come

    def stop(self) -> None:
        """Stop serving (within the indication timeout) and free everything."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(JOIN_TIMEOUT_S)
            if self._thread.is_alive():  # still in libmodbus: leave it its context
                raise RuntimeError('the libmodbus thread did not stop')
        self.close()

    def close(self) -> None:
        """
        Free the mapping and the context, close the pty (idempotent).

        Not ``modbus_close``: that restores termios saved by ``modbus_connect``, never called
        here, and closes the master, which is the helper's.
        """
        if self._mapping:
            self._lib.modbus_mapping_free(self._mapping)
        self._mapping = None
        if self._context:
            self._lib.modbus_free(self._context)
        self._context = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1

    def __enter__(self) -> 'LibmodbusSlave':
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
