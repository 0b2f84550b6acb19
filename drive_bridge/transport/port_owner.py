"""
Who holds a serial port: for the one line a second opener gets. Best effort, Linux only.

The node and ``drive-bridge`` open serial ports exclusively (pyserial ``exclusive=True``: an
``flock`` on POSIX). The holder of that lock is found in ``/proc/locks`` (the device's
inode); where that says nothing, the processes that have the device open are found by
scanning ``/proc/*/fd``. Anything unreadable is skipped: a missing answer is never an error.
"""

import os
from typing import Iterable, List, Optional

PROC = '/proc'
COMMAND_CHARACTERS = 72  # of a holder's command line, in the message


def lock_holders(path: str, proc: str = PROC) -> List[int]:
    """Return the pids holding an flock on the device ``path`` (from ``/proc/locks``)."""
    try:
        status = os.stat(path)
        with open(os.path.join(proc, 'locks')) as stream:
            lines = stream.readlines()
    except OSError:
        return []
    wanted = f'{os.major(status.st_dev):02x}:{os.minor(status.st_dev):02x}:{status.st_ino}'
    holders = []
    for line in lines:
        fields = line.split()
        if '->' in fields or 'FLOCK' not in fields:
            continue  # a waiter, or a POSIX record lock (pyserial takes an flock)
        position = fields.index('FLOCK')
        if len(fields) > position + 4 and fields[position + 4] == wanted:
            holders.append(int(fields[position + 3]))
    return holders


def open_by(path: str, proc: str = PROC) -> List[int]:
    """Return the pids that have ``path`` open (scanning ``/proc/*/fd``)."""
    try:
        target = os.path.realpath(path)
        pids = [entry for entry in os.listdir(proc) if entry.isdigit()]
    except OSError:
        return []
    found = []
    for pid in pids:
        fd_dir = os.path.join(proc, pid, 'fd')
        try:
            links = [os.readlink(os.path.join(fd_dir, fd)) for fd in os.listdir(fd_dir)]
        except OSError:
            continue
        if target in links:
            found.append(int(pid))
    return found


def describe_process(pid: int, proc: str = PROC) -> str:
    """Return 'pid 123 (command line)', or 'this process, pid 123'."""
    if pid == os.getpid():
        return f'this process, pid {pid}'
    try:
        with open(os.path.join(proc, str(pid), 'cmdline'), 'rb') as stream:
            words = stream.read().decode(errors='replace').strip('\0').split('\0')
    except OSError:
        words = ['']
    command = ' '.join([os.path.basename(words[0])] + words[1:]).strip()
    if len(command) > COMMAND_CHARACTERS:
        command = command[:COMMAND_CHARACTERS - 3] + '...'
    return f'pid {pid} ({command})' if command else f'pid {pid}'


def port_owner(path: str, proc: str = PROC) -> Optional[str]:
    """Return who holds serial port ``path`` in words, or None if it cannot be found."""
    holders = lock_holders(path, proc) or [pid for pid in open_by(path, proc)
                                           if pid != os.getpid()]
    return _join(describe_process(pid, proc) for pid in holders[:3]) or None


def in_use_text(path: str, proc: str = PROC) -> str:
    """Return the one line for a port another program holds (owner named where found)."""
    owner = port_owner(path, proc) or 'another program'
    return f'{path} is in use by {owner}: a serial line has one master; stop the other ' \
           'program (the node, or another drive-bridge) first'


def _join(texts: Iterable[str]) -> str:
    return ', '.join(texts)
