"""A fake sysfs and /dev tree for the doctor's tests: an FTDI FT232R at ttyUSB0."""

import os

PORT = '/dev/null'  # a character device every machine has


def fake_sysfs(root, port=PORT, latency_ms=16, driver='ftdi_sio'):
    """Build sysfs as Linux shows an FTDI FT232R at ttyUSB0, keyed by ``port``'s number."""
    rdev = os.stat(port).st_rdev
    usb = root / 'devices' / 'usb1' / '1-1'
    interface = usb / '1-1:1.0' / 'ttyUSB0'
    tty = interface / 'tty' / 'ttyUSB0'
    tty.mkdir(parents=True)
    (root / 'drivers' / driver).mkdir(parents=True)
    (root / 'dev' / 'char').mkdir(parents=True)
    (root / 'dev' / 'char' / f'{os.major(rdev)}:{os.minor(rdev)}').symlink_to(tty)
    (tty / 'device').symlink_to(interface)
    (interface / 'driver').symlink_to(root / 'drivers' / driver)
    for name, text in (('idVendor', '0403'), ('idProduct', '6001'), ('manufacturer', 'FTDI'),
                       ('product', 'FT232R USB UART')):
        (usb / name).write_text(text + '\n')
    timer = root / 'bus' / 'usb-serial' / 'devices' / 'ttyUSB0'
    timer.mkdir(parents=True)
    (timer / 'latency_timer').write_text(f'{latency_ms}\n')
    return root


def by_id(root, port=PORT):
    folder = root / 'serial' / 'by-id'
    folder.mkdir(parents=True)
    (folder / 'usb-FTDI_FT232R_USB_UART_A50285BI-if00-port0').symlink_to(port)
    return root
