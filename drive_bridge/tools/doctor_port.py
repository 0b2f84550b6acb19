"""
The doctor's checks of a serial port before anything is sent: files only, nothing opened.

Does the path exist, may this user open it (group ``dialout``), which stable name in
``/dev/serial/by-id/`` leads to it, which USB adapter and driver it is (sysfs), and, for an
FTDI adapter, its latency timer. The sysfs and /dev roots are parameters, so that tests
give a fake tree.
"""

import getpass
import grp
import os
import stat
from typing import Callable, List, NamedTuple, Optional

from drive_bridge.tools.doctor_findings import (
    Finding, FTDI_UDEV_FILE, FTDI_UDEV_RULE, note, ok, problem)

SYSFS_ROOT, DEV_ROOT = '/sys', '/dev'
GOOD_LATENCY_MS = 1
USB_STRINGS = ('manufacturer', 'product')


class PortAccess(NamedTuple):
    """May this user open the port, and if not, which group would let it."""

    allowed: bool  # read and write
    group: str  # the device file's group (dialout on Debian and Ubuntu)
    member_now: bool  # this process has the group
    member_configured: bool  # /etc/group lists the user (a new login has it)


def port_access(path: str, access: Callable[[str, int], bool] = os.access) -> PortAccess:
    """Return whether this process may read and write ``path``, and its group."""
    status = os.stat(path)
    try:
        group = grp.getgrgid(status.st_gid)
        name, members = group.gr_name, group.gr_mem
    except KeyError:
        name, members = str(status.st_gid), []
    return PortAccess(access(path, os.R_OK | os.W_OK), name,
                      status.st_gid in os.getgroups() or status.st_gid == os.getgid(),
                      getpass.getuser() in members)


def access_finding(path: str, access: PortAccess) -> Finding:
    """Return whether the user may open ``path``, with the fix if not."""
    if access.allowed:
        return ok('permissions', f'{path} may be read and written by this user')
    if access.member_configured and not access.member_now:
        return problem('permissions', f'{path} belongs to group {access.group}, which lists '
                       'you, but this login does not have it yet: log out and back in (or run '
                       f'newgrp {access.group})')
    return problem('permissions', f'{path} belongs to group {access.group} and you are not in '
                   f'it: sudo usermod -aG {access.group} $USER, then log out and back in')


def by_id_finding(port: str, dev_root: str = DEV_ROOT) -> Optional[Finding]:
    """Return which ``/dev/serial/by-id/`` name leads to ``port`` (None: none does)."""
    folder = os.path.join(dev_root, 'serial', 'by-id')
    try:
        names = sorted(os.listdir(folder))
    except OSError:
        return None
    target = os.path.realpath(port)
    for name in names:
        link = os.path.join(folder, name)
        if os.path.realpath(link) != target:
            continue
        shown = f'/dev/serial/by-id/{name}'
        if os.path.dirname(os.path.abspath(port)).endswith('serial/by-id'):
            return ok('name', f'{port} is a stable name (by id)')
        return note('name', f'{shown} leads to {port}: use it as port (it stays the same '
                    'whatever order the adapters are plugged in)')
    return None


class Adapter(NamedTuple):
    """A serial port's device as sysfs tells it."""

    tty: str  # ttyUSB0
    driver: str  # ftdi_sio, cp210x, ch341, cdc_acm, pl2303 ('' if none)
    usb_id: str  # 0403:6001 ('' if no USB device)
    words: str  # manufacturer and product strings


def find_adapter(port: str, sysfs_root: str = SYSFS_ROOT) -> Optional[Adapter]:
    """Return the adapter behind ``port`` from sysfs (by its device number), or None."""
    try:
        rdev = os.stat(port).st_rdev
    except OSError:
        return None
    node = os.path.join(sysfs_root, 'dev', 'char', f'{os.major(rdev)}:{os.minor(rdev)}')
    if not os.path.exists(node):
        return None
    tty_dir = os.path.realpath(node)
    device = os.path.join(tty_dir, 'device')
    driver = os.path.join(device, 'driver')
    driver_name = os.path.basename(os.path.realpath(driver)) if os.path.exists(driver) else ''
    usb = _usb_device(os.path.realpath(device), sysfs_root) if os.path.exists(device) else ''
    usb_id = words = ''
    if usb:
        usb_id = f'{_read(usb, "idVendor")}:{_read(usb, "idProduct")}'
        words = ' '.join(text for text in (_read(usb, name) for name in USB_STRINGS) if text)
    return Adapter(os.path.basename(tty_dir), driver_name, usb_id, words)


def _usb_device(folder: str, sysfs_root: str) -> str:
    """Return the USB device folder at or above ``folder`` (the one with idVendor), or ''."""
    root = os.path.realpath(sysfs_root)
    while folder.startswith(root) and folder != root:
        if os.path.exists(os.path.join(folder, 'idVendor')):
            return folder
        folder = os.path.dirname(folder)
    return ''


def _read(folder: str, name: str) -> str:
    try:
        with open(os.path.join(folder, name), encoding='utf-8', errors='replace') as file:
            return file.read().strip()
    except OSError:
        return ''


def adapter_findings(port: str, sysfs_root: str = SYSFS_ROOT) -> List[Finding]:
    """Return what the adapter is and, for an FTDI adapter, whether its latency timer fits."""
    adapter = find_adapter(port, sysfs_root)
    if adapter is None:
        return [note('adapter', f'{port} has no device in sysfs: no USB or on-board serial '
                     'port (a pty, e.g. the simulator?)')]
    if not adapter.usb_id:
        return [ok('adapter', f'{adapter.tty}: not a USB adapter (driver '
                   f'{adapter.driver or "unknown"})')]
    found = [ok('adapter', f'{adapter.tty}: USB {adapter.usb_id} {adapter.words} (driver '
                f'{adapter.driver or "unknown"})'.replace('  ', ' '))]
    latency = latency_finding(adapter, sysfs_root)
    return found + ([latency] if latency else [])


def latency_finding(adapter: Adapter, sysfs_root: str = SYSFS_ROOT) -> Optional[Finding]:
    """Return the latency timer of a USB serial adapter that has one (FTDI), or None."""
    shown = f'/sys/bus/usb-serial/devices/{adapter.tty}/latency_timer'
    text = _read(os.path.join(sysfs_root, 'bus', 'usb-serial', 'devices', adapter.tty),
                 'latency_timer')
    if not text.isdigit():
        return None
    latency_ms = int(text)
    if latency_ms <= GOOD_LATENCY_MS:
        return ok('latency timer', f'{latency_ms} ms ({shown})')
    return problem('latency timer', f'{latency_ms} ms ({shown}): each reply waits up to '
                   f'{latency_ms} ms in the adapter; set 1 ms now with echo 1 | sudo tee '
                   f'{shown}, and for good with the udev rule {FTDI_UDEV_RULE} in '
                   f'{FTDI_UDEV_FILE} (then sudo udevadm control --reload and replug)')


def port_findings(port: str, sysfs_root: str = SYSFS_ROOT, dev_root: str = DEV_ROOT,
                  access: Callable[[str, int], bool] = os.access) -> List[Finding]:
    """
    Return the findings of ``port`` from files alone; a problem last means stop here.

    A missing path or one that is no character device ends the checks (one line).
    """
    if not os.path.exists(port):
        hint = f' (by id: ls {dev_root}/serial/by-id/)' if dev_root == DEV_ROOT else ''
        return [problem('port', f'{port} does not exist: plug the adapter in, or give the '
                        f'port it has{hint}')]
    if not stat.S_ISCHR(os.stat(port).st_mode):
        return [problem('port', f'{port} is not a serial port (no character device): give '
                        "the adapter's port, e.g. /dev/ttyUSB0")]
    findings = [ok('port', f'{port} exists'), access_finding(port, port_access(port, access))]
    stable = by_id_finding(port, dev_root)
    if stable is not None:
        findings.append(stable)
    return findings + adapter_findings(port, sysfs_root)
