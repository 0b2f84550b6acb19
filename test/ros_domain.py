"""
A ROS domain of this test process's own, held by a lock file until the process ends.

Each pytest process (a serial run, or each pytest-xdist worker) takes one domain id with an
exclusive ``flock`` on ``/tmp/drive_bridge_ros_domains/<id>.lock``. The kernel drops the lock
when the process ends, however it ends, so a crashed run leaves nothing to clean up, and two
test processes on one machine, of one suite or of two, never share a domain. The ids are tried
from the top of the range down, away from ``100 + pid % 100``, which older checkouts take.

A serial run honours an exported ``ROS_DOMAIN_ID`` and locks it too: a second test process
that asks for the same id is refused instead of mixing its nodes into the first one's.
"""

import errno
import fcntl
import os
from typing import Optional

LOCK_DIR = '/tmp/drive_bridge_ros_domains'
# 0-232 are the domain ids whose Fast DDS ports fit in 16 bits; below 100 is left to the
# ids that developers export in their shells.
FIRST_ID, LAST_ID = 100, 232


class DomainTaken(Exception):
    """The exported ROS_DOMAIN_ID is held by another test process."""


class DomainLock:
    """The lock file of one domain id, held open (and so locked) while this object lives."""

    def __init__(self, domain_id: int, descriptor: int):
        self.domain_id = domain_id
        self._descriptor = descriptor

    def release(self) -> None:
        os.close(self._descriptor)


def _try_lock(domain_id: int) -> Optional[DomainLock]:
    """Lock ``domain_id``'s file and write this pid in it, or return None if it is held."""
    os.makedirs(LOCK_DIR, mode=0o1777, exist_ok=True)
    path = os.path.join(LOCK_DIR, f'{domain_id}.lock')
    descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as error:
        os.close(descriptor)
        if error.errno in (errno.EWOULDBLOCK, errno.EACCES):
            return None
        raise
    os.ftruncate(descriptor, 0)
    os.write(descriptor, f'{os.getpid()}\n'.encode())
    return DomainLock(domain_id, descriptor)


def holder(domain_id: int) -> str:
    """Return the pid written by the process that holds ``domain_id`` (for messages)."""
    try:
        with open(os.path.join(LOCK_DIR, f'{domain_id}.lock')) as lock_file:
            return lock_file.read().strip() or 'unknown'
    except OSError:
        return 'unknown'


def take_exported(domain_id: int) -> DomainLock:
    """Lock the exported ``domain_id``; raise DomainTaken if another test process holds it."""
    lock = _try_lock(domain_id)
    if lock is None:
        raise DomainTaken(
            f'ROS_DOMAIN_ID={domain_id} is in use by another test process (pid '
            f'{holder(domain_id)}): export another id, or unset it to be given a free one')
    return lock


def take_free() -> DomainLock:
    """Lock the highest free domain id of the range and return its lock."""
    for domain_id in range(LAST_ID, FIRST_ID - 1, -1):
        lock = _try_lock(domain_id)
        if lock is not None:
            return lock
    raise DomainTaken(f'every ROS domain id {FIRST_ID}-{LAST_ID} is held by a test process '
                      f'(lock files in {LOCK_DIR})')
