"""A pty pair for a simulated serial line, with an optional stable symlink to its slave side."""

import os
import tty
from typing import List


class PtyLink:
    """
    Open a raw pty pair; the simulator serves on ``master``, clients open ``path``.

    The slave side stays open in the simulator too, so the master never sees EIO while no
    client has it open. A pty moves bytes at once and has no wire, so it has no parity:
    Linux clears the parity a client asks for (and refuses a later open that asks again),
    which is why the bridge's transports open a pty without parity, whatever the link's
    framing (:func:`drive_bridge.transport.link.port_framing`). A wire's framing and timing
    are the wire pacer's (:mod:`drive_bridge.sim.wire_pacer`).
    """

    def __init__(self, link_path: str = ''):
        master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(master)
        os.set_blocking(master, False)
        self.master = master
        self.slave = slave  # its terminal settings are the client's (baud rate, stop bits)
        self._fds: List[int] = [master, slave]
        self.path = os.ttyname(slave)
        self.link_path = link_path
        if link_path:
            if os.path.islink(link_path):
                os.unlink(link_path)
            os.symlink(self.path, link_path)

    def close(self) -> None:
        """Close both sides and remove the symlink (idempotent)."""
        for fd in self._fds:
            try:
                os.close(fd)
            except OSError:
                pass
        self._fds.clear()
        if self.link_path and os.path.islink(self.link_path):
            os.unlink(self.link_path)
