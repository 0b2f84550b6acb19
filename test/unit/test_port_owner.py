"""Finding who holds a serial port, from a /proc tree laid out by the test."""

import os

from drive_bridge.transport.port_owner import (
    describe_process, in_use_text, lock_holders, open_by, port_owner)


def fake_proc(tmp_path, locks='', processes=None):
    proc = tmp_path / 'proc'
    proc.mkdir()
    (proc / 'locks').write_text(locks)
    for pid, (command, fds) in (processes or {}).items():
        (proc / str(pid) / 'fd').mkdir(parents=True)
        (proc / str(pid) / 'cmdline').write_bytes(b'\0'.join(command) + b'\0')
        for fd, target in enumerate(fds):
            os.symlink(target, proc / str(pid) / 'fd' / str(fd))
    return str(proc)


def lock_key(path):
    status = os.stat(path)
    return f'{os.major(status.st_dev):02x}:{os.minor(status.st_dev):02x}:{status.st_ino}'


def test_the_flock_holder_is_read_from_proc_locks(tmp_path):
    device = tmp_path / 'ttyUSB0'
    device.write_text('')
    key = lock_key(device)
    proc = fake_proc(tmp_path, locks=(
        f'1: POSIX  ADVISORY  WRITE 111 {key} 0 EOF\n'  # a record lock: not pyserial's
        f'2: FLOCK  ADVISORY  WRITE 4242 {key} 0 EOF\n'
        f'2: -> FLOCK  ADVISORY  WRITE 5151 {key} 0 EOF\n'  # a waiter, not the holder
        '3: FLOCK  ADVISORY  WRITE 777 00:05:1 0 EOF\n'), processes={
        4242: ([b'/opt/ros/jazzy/bin/python3', b'/x/drive_bridge_node', b'--ros-args'], [])})
    assert lock_holders(str(device), proc) == [4242]
    assert port_owner(str(device), proc) == 'pid 4242 (python3 /x/drive_bridge_node --ros-args)'
    assert in_use_text(str(device), proc) == (
        f'{device} is in use by pid 4242 (python3 /x/drive_bridge_node --ros-args): a serial '
        'line has one master; stop the other program (the node, or another drive-bridge) first')


def test_without_a_lock_the_processes_that_have_it_open_are_named(tmp_path):
    device = tmp_path / 'ttyUSB0'
    device.write_text('')
    proc = fake_proc(tmp_path, processes={
        300: ([b'minicom', b'-D', b'ttyUSB0'], [str(device)]),
        301: ([b'bash'], ['/dev/null'])})
    assert open_by(str(device), proc) == [300]
    assert port_owner(str(device), proc) == 'pid 300 (minicom -D ttyUSB0)'


def test_nobody_found_is_said_plainly(tmp_path):
    device = tmp_path / 'ttyUSB0'
    device.write_text('')
    proc = fake_proc(tmp_path)
    assert port_owner(str(device), proc) is None
    assert in_use_text(str(device), proc).startswith(f'{device} is in use by another program:')
    assert port_owner(str(tmp_path / 'missing'), str(tmp_path / 'no_proc')) is None


def test_a_long_command_line_is_shortened_and_this_process_named_as_such(tmp_path):
    proc = fake_proc(tmp_path, processes={9: ([b'python3', b'-m', b'x' * 200], [])})
    assert describe_process(9, proc).endswith('...)') and len(describe_process(9, proc)) < 90
    assert describe_process(os.getpid(), proc) == f'this process, pid {os.getpid()}'
