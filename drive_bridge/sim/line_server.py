"""
The byte streams of one simulated line, served on their own thread.

A pty (RTU on a serial port) and TCP clients (Modbus TCP, RTU over TCP, raw FC protocol):
:class:`LineServer` watches them with one selector, keeps each stream's receive buffer in
a :class:`Connection`, and hands a connection to its :class:`StreamHandler` whenever bytes
arrive or a partial frame has gone quiet. Framing and answering are the handler's (the
Modbus and FC protocol servers); the line's own faults (an unplugged adapter, a gateway
restart) are here. A reply is written with :meth:`LineServer.send` at the time it is due
(at once, after a ``slow`` fault's delay, at wire time, after the master's timeout), or
held until the connection's next request (:meth:`LineServer.hold`): the serving thread
never sleeps for a reply (:mod:`drive_bridge.sim.scheduled_writes`). Standard library only.
"""

import os
import selectors
import socket
import threading
import time
from typing import Callable, List, Optional, Protocol, Union

from drive_bridge.sim.pty_link import PtyLink
from drive_bridge.sim.scheduled_writes import ScheduledWrites

STALE_PARTIAL_FRAME_S = 0.05  # a partial frame older than this is dropped (pty has no gaps)
# The serving loop waits for bytes, the next due reply or the next partial frame going stale,
# and at most this long: stop() and the actions run on the loop wake it through a pipe, so
# an idle simulator does not wake (a 5 ms poll cost an idle simulator 2-3 % of a core).
IDLE_WAIT_S = 1.0
STALE_MARGIN_S = 0.001  # woken this long after a partial frame went stale (> its age)
FRAMINGS = ('mbap', 'rtu')  # Modbus TCP's MBAP header, or the bytes as on a serial line


class Connection:
    """One byte stream (pty master or TCP client) and its receive buffer."""

    def __init__(self, fd_or_socket: Union[int, socket.socket], framing: str):
        self.io = fd_or_socket
        self.framing = framing  # 'rtu' or 'mbap'
        self.buffer = b''
        self.first_byte_s = 0.0  # when the buffer's first byte arrived
        self.last_byte_s = 0.0
        self.closed = False  # set when the line stops watching it: nothing more is written
        self.tap = None  # the wire trace's WireTap (drive_bridge_sim --wire-trace), or None

    def fileno(self) -> int:
        """Return the stream's file descriptor."""
        return self.io if isinstance(self.io, int) else self.io.fileno()

    def read(self) -> bytes:
        """Return what the stream has (b'' when it is closed or failed)."""
        try:
            data = os.read(self.io, 4096) if isinstance(self.io, int) else self.io.recv(4096)
        except OSError:
            return b''
        if data and self.tap is not None:
            self.tap.frame(True, data, self.framing)
        return data

    def write(self, data: bytes) -> None:
        """Send ``data``; a stream that has gone is ignored (the master sees silence)."""
        if self.tap is not None:
            self.tap.frame(False, data, self.framing)
        try:
            if isinstance(self.io, int):
                os.write(self.io, data)
            else:
                self.io.sendall(data)
        except OSError:
            pass


class StreamHandler(Protocol):
    """What the line hands its bytes to: the framing and answering of one protocol."""

    def take_bytes(self, connection: Connection, gap_elapsed: bool) -> None:
        """
        Consume what ``connection.buffer`` holds (on the serving thread).

        ``gap_elapsed``: no byte came for :data:`STALE_PARTIAL_FRAME_S`, so a partial frame
        left in the buffer will not be completed.
        """


class LineServer:
    """The endpoints of one simulated line and the thread that serves them."""

    def __init__(self, handler: StreamHandler, clock: Callable[[], float] = time.monotonic):
        self.handler = handler
        self.clock = clock
        self.pty_path = ''
        self.tcp_port = 0
        self._selector = selectors.DefaultSelector()
        self._ptys: List[PtyLink] = []
        self._wake_r, self._wake_w = os.pipe()
        self._selector.register(self._wake_r, selectors.EVENT_READ, None)
        self._thread: Optional[threading.Thread] = None
        self._running = False
        self._loop_actions: List[tuple] = []
        self._unplugged_links: List[str] = []
        self.writes = ScheduledWrites(clock)
        self.tap = None  # set before start: every connection's bytes go to this WireTap

    # -- replies (on the serving thread) ------------------------------------------------
    def send(self, connection: Connection, data: bytes, due_s: float = 0.0) -> None:
        """Write ``data`` to ``connection`` at ``due_s`` (0 or past: now), without waiting."""
        self.writes.write_at(due_s, connection, data)

    def hold(self, connection: Connection, data: bytes) -> None:
        """Hold ``data`` until the next request on ``connection`` (:meth:`release_held`)."""
        self.writes.hold(connection, data)

    def release_held(self, connection: Connection) -> None:
        """Write the replies held for ``connection`` now: its next request has come."""
        self.writes.release_held(connection)

    # -- endpoints ----------------------------------------------------------------------
    def open_pty(self, link_path: str = '') -> str:
        """Open a pty pair, serve RTU on its master; return the slave's path for clients."""
        pty = PtyLink(link_path)
        self._ptys.append(pty)
        self.pty_path = pty.path
        connection = Connection(pty.master, 'rtu')
        connection.tap = self.tap
        self._selector.register(pty.master, selectors.EVENT_READ, connection)
        return self.pty_path

    @property
    def pty_master(self) -> int:
        """Return the master end of the newest pty: bytes written there reach the client."""
        return self._ptys[-1].master

    def open_tcp(self, host: str = '127.0.0.1', port: int = 0, framing: str = 'mbap') -> int:
        """Listen for TCP clients; ``framing`` 'mbap' (Modbus TCP) or 'rtu' (RTU over TCP)."""
        if framing not in FRAMINGS:
            raise ValueError(f'framing must be mbap or rtu, not {framing!r}')
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((host, port))
        listener.listen(8)
        listener.setblocking(False)
        self._selector.register(listener, selectors.EVENT_READ, ('listen', framing))
        self.tcp_port = listener.getsockname()[1]
        return self.tcp_port

    # -- faults of the line itself ------------------------------------------------------
    def unplug(self) -> None:
        """Close every pty, as a USB adapter pulled out: the port and its symlink vanish."""
        self._in_loop(self._close_ptys)

    def replug(self) -> str:
        """Open a new pty at the same symlink after :meth:`unplug`; return the new path."""
        links = self._unplugged_links
        self._unplugged_links = []
        for link in links or ['']:
            self._in_loop(lambda link=link: self.open_pty(link))
        return self.pty_path

    def close_tcp(self) -> None:
        """Close the TCP listeners and every client connection, as a gateway restarting."""
        self._in_loop(self._close_sockets)

    def _in_loop(self, action: Callable[[], None]) -> None:
        """Run ``action`` on the serving thread (the selector is not shared) and wait."""
        if self._thread is None or not self._thread.is_alive():
            action()
            return
        done = threading.Event()
        self._loop_actions.append((action, done))
        os.write(self._wake_w, b'x')
        done.wait(5.0)

    def _close_ptys(self) -> None:
        for pty in self._ptys:
            self._forget(pty.master)
            self._unplugged_links.append(pty.link_path)
            pty.close()
        self._ptys = []

    def _close_sockets(self) -> None:
        for key in list(self._selector.get_map().values()):
            if isinstance(key.fileobj, socket.socket):
                self._close_key(key)

    def _forget(self, fileobj) -> bool:
        """Stop watching ``fileobj``, its replies not yet written dropped; False if unwatched."""
        try:
            key = self._selector.unregister(fileobj)
        except (KeyError, ValueError):
            return False
        if isinstance(key.data, Connection):
            key.data.closed = True
            self.writes.forget(key.data)
        return True

    # -- thread -------------------------------------------------------------------------
    def start(self) -> None:
        """Serve on a background thread."""
        self._running = True
        self._thread = threading.Thread(target=self._serve, name='modbus-sim', daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop serving and close every endpoint."""
        self._running = False
        os.write(self._wake_w, b'x')
        if self._thread:
            self._thread.join(timeout=5)
        for key in list(self._selector.get_map().values()):
            self._close_key(key)
        for pty in self._ptys:
            pty.close()
        self.writes.clear()
        os.close(self._wake_w)

    def _close_key(self, key) -> None:
        if not self._forget(key.fileobj):
            return
        if isinstance(key.fileobj, socket.socket):
            key.fileobj.close()
        elif key.fileobj == self._wake_r:
            os.close(self._wake_r)

    def _serve(self) -> None:
        while self._running:
            while self._loop_actions:
                action, done = self._loop_actions.pop(0)
                action()
                done.set()
            events = self._selector.select(timeout=self._wait_s())
            now = self.clock()
            for key, _ in events:
                self._on_readable(key, now)
            self._flush_stale(now)
            self.writes.flush_due(self.clock())

    def _wait_s(self) -> float:
        """
        Return how long the loop may wait: until a reply is due or a partial frame goes stale.

        A partial frame already handed over as stale and kept (Modbus TCP's handler keeps a
        partial frame until the rest comes) does not shorten the wait: only its next bytes
        can change it, and they wake the loop.
        """
        now = self.clock()
        wait_s = self.writes.timeout_s(now, IDLE_WAIT_S)
        for key in self._selector.get_map().values():
            connection = key.data
            if isinstance(connection, Connection) and connection.buffer:
                stale_s = connection.last_byte_s + STALE_PARTIAL_FRAME_S + STALE_MARGIN_S
                if stale_s > now:
                    wait_s = min(wait_s, stale_s - now)
        return wait_s

    def _on_readable(self, key, now: float) -> None:
        if key.data is None:
            os.read(self._wake_r, 64)
            return
        if isinstance(key.data, tuple):
            client, _ = key.fileobj.accept()
            client.setblocking(True)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            connection = Connection(client, key.data[1])
            connection.tap = self.tap
            self._selector.register(client, selectors.EVENT_READ, connection)
            return
        connection: Connection = key.data
        data = connection.read()
        if not data:
            if isinstance(connection.io, socket.socket):
                self._close_key(key)
            return
        if not connection.buffer:
            connection.first_byte_s = now
        connection.buffer += data
        connection.last_byte_s = now
        self.handler.take_bytes(connection, gap_elapsed=False)

    def _flush_stale(self, now: float) -> None:
        for key in list(self._selector.get_map().values()):
            connection = key.data
            if isinstance(connection, Connection) and connection.buffer and \
                    now - connection.last_byte_s > STALE_PARTIAL_FRAME_S:
                self.handler.take_bytes(connection, gap_elapsed=True)
