"""
A minimal Modbus RTU master in CPython: about the least a Python master can do a transaction.

The second peer of ``master_cpu.py`` (beside libmodbus). It sends a fixed list of requests
in turn, as fast as the line answers, and does per transaction only what no master can
skip: one ``write``, the terminal's ``VMIN`` set to the whole reply's length (known from the
request; a change of length costs a ``tcsetattr``), one ``select`` until the reply is there,
one ``read``, the reply's length and CRC checked, then one sleep for the 3.5-character gap
before the next request. The requests' CRCs are computed once at the start. No line
discipline, no check of the reply's unit, function or count, no scheduling, no decoding, no
exception replies (a 5-byte exception would wait for the timeout): it is not a master to
use, only one minimal design, the cost that CPython puts under any master on this machine.
Test-only code (the bench's), never the package's.

Usage (as libmodbus_master.c): python_master.py PORT BAUD PARITY STOP GAP_US HEX_REQUEST...
Prints "ready", then at SIGTERM "answered N failed F".
"""

import os
import select
import signal
import sys
import termios
import time

from drive_bridge.protocol.crc import append_crc, crc_ok
import serial

PARITIES = {'N': serial.PARITY_NONE, 'E': serial.PARITY_EVEN, 'O': serial.PARITY_ODD}
TIMEOUT_S = 0.5  # as the libmodbus master's response timeout


def reply_length(request: bytes) -> int:
    """Return the length of the normal reply to ``request`` (functions 1-6, 15, 16)."""
    function, count = request[1], int.from_bytes(request[4:6], 'big')
    if function in (1, 2):
        return 5 + (count + 7) // 8
    if function in (3, 4):
        return 5 + 2 * count
    if function in (5, 6, 15, 16):
        return 8  # the echo of a write
    raise ValueError(f'function 0x{function:02x}: not a request this floor knows the reply of')


def main(arguments) -> int:
    """Poll until SIGTERM; print what was answered."""
    port, baudrate, parity, stopbits, gap_us = arguments[:5]
    requests = [append_crc(bytes.fromhex(text)) for text in arguments[5:]]
    lengths = [reply_length(request) for request in requests]
    line = serial.Serial(port, int(baudrate), parity=PARITIES[parity],
                         stopbits=int(stopbits), timeout=0)
    fd = line.fileno()
    os.set_blocking(fd, False)
    settings = termios.tcgetattr(fd)
    settings[6] = list(settings[6])
    settings[6][termios.VTIME] = 0
    stopped = []
    signal.signal(signal.SIGTERM, lambda *_: stopped.append(True))
    print('ready', flush=True)
    gap_s, vmin, answered, failed, index = int(gap_us) / 1e6, -1, 0, 0, 0
    while not stopped:
        request, length = requests[index], lengths[index]
        index = (index + 1) % len(requests)
        os.write(fd, request)
        if length != vmin:
            settings[6][termios.VMIN] = vmin = length
            termios.tcsetattr(fd, termios.TCSANOW, settings)
        select.select([fd], [], [], TIMEOUT_S)
        try:
            reply = os.read(fd, 256)
        except BlockingIOError:
            reply = b''
        if len(reply) == length and crc_ok(reply):
            answered += 1
        else:
            failed += 1
        time.sleep(gap_s)
    print(f'answered {answered} failed {failed}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
