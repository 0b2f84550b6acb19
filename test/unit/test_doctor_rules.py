"""The doctor's rules on files alone: a fake sysfs and /dev tree, access, settings, fixes."""

import argparse
import os

from drive_bridge.sim.adapter import parse_device_line, SerialSetting
from drive_bridge.tools import doctor_search as search
from drive_bridge.tools.doctor import listen_seconds
from drive_bridge.tools.doctor_findings import exit_status, FTDI_UDEV_RULE, ok, problem
from drive_bridge.tools.doctor_line import echo_finding
from drive_bridge.tools.doctor_port import access_finding, port_findings, PortAccess
from drive_bridge.transport.port_probe import PROBE_BYTES
from fake_sysfs import by_id, fake_sysfs, PORT
import pytest


def test_an_ftdi_latency_timer_of_16_ms_is_a_problem_with_the_udev_rule(tmp_path):
    findings = port_findings(PORT, str(fake_sysfs(tmp_path / 'sys')), str(tmp_path / 'dev'))
    lines = {finding.topic: finding for finding in findings}
    assert lines['adapter'] == ok('adapter', 'ttyUSB0: USB 0403:6001 FTDI FT232R USB UART '
                                  '(driver ftdi_sio)')
    timer = lines['latency timer']
    assert timer.level == 'problem' and timer.text.startswith('16 ms')
    assert FTDI_UDEV_RULE in timer.text
    assert 'echo 1 | sudo tee /sys/bus/usb-serial/devices/ttyUSB0/latency_timer' in timer.text
    assert FTDI_UDEV_RULE == ('ACTION=="add", SUBSYSTEM=="usb-serial", DRIVERS=="ftdi_sio", '
                              'ATTR{latency_timer}="1"')


def test_a_latency_timer_of_1_ms_is_ok(tmp_path):
    findings = port_findings(PORT, str(fake_sysfs(tmp_path / 'sys', latency_ms=1)),
                             str(tmp_path / 'dev'))
    assert ok('latency timer', '1 ms (/sys/bus/usb-serial/devices/ttyUSB0/latency_timer)') in \
        findings
    assert not any(finding.level == 'problem' for finding in findings)


def test_a_port_without_sysfs_entry_is_told_as_no_adapter(tmp_path):
    findings = port_findings(PORT, str(tmp_path / 'empty'), str(tmp_path / 'dev'))
    assert [f.topic for f in findings] == ['port', 'permissions', 'adapter']
    assert findings[-1].level == 'note' and 'no device in sysfs' in findings[-1].text


def test_a_by_id_name_is_suggested_as_port(tmp_path):
    findings = port_findings(PORT, str(tmp_path / 'sys'), str(by_id(tmp_path / 'dev')))
    name = [finding for finding in findings if finding.topic == 'name']
    assert name and name[0].level == 'note'
    assert name[0].text.startswith('/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A50285BI-if00-'
                                   'port0 leads to /dev/null: use it as port')


def test_a_missing_port_is_one_line_and_ends_the_checks(tmp_path):
    findings = port_findings(str(tmp_path / 'ttyUSB7'), str(tmp_path), str(tmp_path))
    assert len(findings) == 1 and findings[0].level == 'problem'
    assert 'ttyUSB7 does not exist: plug the adapter in' in findings[0].line()


def test_a_file_that_is_no_device_is_refused(tmp_path):
    (tmp_path / 'notes.txt').write_text('x')
    findings = port_findings(str(tmp_path / 'notes.txt'), str(tmp_path), str(tmp_path))
    assert len(findings) == 1 and 'is not a serial port' in findings[0].text


def test_no_permission_without_the_group_gives_the_usermod_fix():
    finding = access_finding('/dev/ttyUSB0', PortAccess(False, 'dialout', False, False))
    assert finding == problem('permissions', '/dev/ttyUSB0 belongs to group dialout and you are '
                              'not in it: sudo usermod -aG dialout $USER, then log out and '
                              'back in')


def test_a_group_added_but_not_yet_in_this_login_says_log_in_again():
    finding = access_finding('/dev/ttyUSB0', PortAccess(False, 'dialout', False, True))
    assert finding.level == 'problem' and 'log out and back in (or run newgrp dialout)' in \
        finding.text


def test_no_permission_through_port_findings_is_a_problem(tmp_path):
    findings = port_findings(PORT, str(tmp_path), str(tmp_path), access=lambda path, mode: False)
    assert findings[1].topic == 'permissions' and findings[1].level == 'problem'
    assert 'usermod -aG' in findings[1].text or 'log out' in findings[1].text


@pytest.mark.parametrize('back, configured, echo, level', [
    (PROBE_BYTES, False, True, 'problem'),
    (PROBE_BYTES, True, True, 'ok'),
    (b'', False, False, 'ok'),
    (b'', True, False, 'problem'),
    (b'\x01\x02', False, None, 'note'),
])
def test_the_echo_rule(back, configured, echo, level):
    found, finding = echo_finding(back, False, configured)
    assert (found, finding.level) == (echo, level)


def test_settings_are_tried_nearest_to_the_configured_first():
    configured = search.Setting('modbus_rtu', 19200, 'E')
    settings = search.settings_to_try(configured)
    assert settings[0] == configured
    # one difference first (the configured protocol's first), then two, then three
    assert settings[1:5] == [search.Setting('modbus_rtu', 19200, 'N'),
                             search.Setting('modbus_rtu', 9600, 'E'),
                             search.Setting('modbus_rtu', 38400, 'E'),
                             search.Setting('fc_protocol', 19200, 'E')]
    assert settings[-1] == search.Setting('fc_protocol', 38400, 'N')
    assert len(settings) == len(set(settings))
    assert all(s.parity == 'N' for s in settings if s.protocol == 'ap_ascii')
    # three protocols, three baud rates, two parities; AP ASCII is always 8N1
    assert len(settings) == 3 * 2 + 3 * 2 + 3


def test_on_a_pty_settings_that_differ_only_in_parity_are_tried_once(tmp_path):
    import pty as pty_module
    master, slave = pty_module.openpty()
    try:
        settings = search.settings_to_try(search.Setting('modbus_rtu', 9600, 'E'),
                                          port=os.ttyname(slave))
    finally:
        os.close(master)
        os.close(slave)
    fc = [s for s in settings if s.protocol == 'fc_protocol']
    assert len(fc) == 3  # 8E1 and 8N1 are one on a pty (no parity, 1 stop bit)
    assert len([s for s in settings if s.protocol == 'modbus_rtu']) == 6  # 8N2 differs


def test_the_fix_names_the_device_parameters_and_the_bridge_settings():
    configured = search.Setting('modbus_rtu', 19200, 'E')
    assert search.fix(search.Setting('fc_protocol', 19200, 'E'), configured, 'fc') == \
        'set 8-30 to Modbus RTU, or set protocol: fc_protocol'
    assert search.fix(search.Setting('modbus_rtu', 9600, 'N'), configured, 'fc') == \
        'set 8-32 to 19200 baud and 8-33 to parity E, or set baudrate: 9600, parity: "N"'


def test_exit_status_needs_a_device_and_no_problem():
    assert exit_status([ok('port', 'x')], 1) == 0
    assert exit_status([ok('port', 'x')], 0) == 1
    assert exit_status([problem('line', 'x')], 2) == 1


def test_the_device_line_option():
    assert parse_device_line('9600:E') == SerialSetting(9600, 1)
    assert parse_device_line('19200:N') == SerialSetting(19200, 2)
    assert parse_device_line('19200:N:1') == SerialSetting(19200, 1)
    with pytest.raises(ValueError, match='give BAUD'):
        parse_device_line('9601')


@pytest.mark.parametrize('text', ['nan', 'inf', '1e20', '-5', '61', 'soon'])
def test_the_listening_time_is_checked_in_one_line(text):
    with pytest.raises(argparse.ArgumentTypeError, match='give the seconds to listen, 0-60'):
        listen_seconds(text)
    assert listen_seconds('0') == 0.0 and listen_seconds('2.5') == 2.5
