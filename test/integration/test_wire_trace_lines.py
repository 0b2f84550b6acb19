"""
Wire traces on a pty and TCP against the simulators, read back with tshark (skipped without).

The bridge's trace (``make_transport`` with a trace, ``drive-bridge --wire-trace``) and the
simulator's (``drive_bridge_sim --wire-trace``): Modbus frames decoded by Wireshark's own
dissectors, the FC protocol and AP ASCII named for the Lua dissectors with their bytes, the
direction, and each outcome the simulator's faults make.
"""

import argparse
import io
import os
import signal
import subprocess
import sys

from drive_bridge.protocol.requests import ReadRegisters
from drive_bridge.sim import cli as sim_cli
from drive_bridge.sim.ap_ascii_server import make_ap_ascii_server
from drive_bridge.sim.faults import FaultPlan
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
from drive_bridge.tools import trace_text
from drive_bridge.tools.cli import main
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.wire_trace import TraceSettings
import pytest
from trace_helpers import needs_tshark, on_a_pty, outcomes, tshark_fields

TIMEOUT_S = 0.5
READ = ReadRegisters(2, 2)
pytestmark = needs_tshark


def modbus_sim(*argv):
    """Return a started simulator of ``drive_bridge_sim`` arguments, no random faults."""
    server = sim_cli.build_server(sim_cli.build_parser().parse_args(list(argv)))
    server.faults.set_plan(FaultPlan(master_timeout_s=TIMEOUT_S))
    return server


def attempt(transport, unit=20):
    """Run one read; return its failure's kind, or 'ok'."""
    try:
        transport.execute(unit, READ)
    except Exception as error:  # noqa: B902 - every failure is an outcome here
        return getattr(error, 'kind', type(error).__name__)
    return 'ok'


def test_modbus_rtu_on_a_pty_ok_crc_timeout_late_and_quarantined_frames(tmp_path):
    on_a_pty(modbus_rtu_faults_traced, tmp_path)


def modbus_rtu_faults_traced(tmp_path) -> None:
    server = modbus_sim('--device', 'mcd500:20', '--device', 'mcd202:21')
    path = tmp_path / 'rtu.pcapng'
    link = LinkSettings(port=server.open_pty(), parity='N', timeout_s=TIMEOUT_S)
    server.start()
    transport = make_transport(link, {}, TraceSettings(str(path)))
    transport.connect()
    try:
        seen = []
        for fault in (None, 'crc', 'no_reply', None, 'wrong_address', 'late', None):
            if fault:
                sim_cli.run_console_command(server, f'fault 20 {fault}')
            seen.append(attempt(transport))
    finally:
        transport.close()
        server.stop()
    assert seen[:3] == ['ok', 'crc', 'timeout'] and seen[5] == 'timeout', seen
    rows = tshark_fields(path, 'frame.p2p_dir', 'mbrtu.unit_id', 'modbus.func_code',
                         'frame.interface_name', 'frame.comment')
    assert {row[3] for row in rows} == {link.port[len('/dev/'):]}
    assert all(row[2] == '3' for row in rows if row[0] == '0')  # every request decoded
    words = list(zip([row[0] for row in rows], outcomes(rows), [row[1] for row in rows]))
    assert words[:5] == [('0', 'ok', '20'), ('1', 'ok', '20'), ('0', 'crc', '20'),
                         ('1', 'crc', '20'), ('0', 'timeout', '20')]
    assert ('1', 'late', '21') in words  # the wrong address's frame, in the window
    late_request = [index for index, word in enumerate(words) if word == ('0', 'timeout', '20')]
    assert len(late_request) >= 2
    after = words[late_request[1] + 1:]  # the late reply: in the guard or before the next
    assert after[0][0] == '1' and after[0][2] == '20' and \
        after[0][1] in ('quarantined', 'late', 'ambiguous'), after
    assert words[-1] == ('1', 'ok', '20')


def test_rtu_over_tcp_is_traced_as_modbus_rtu_named_by_host_and_port(tmp_path):
    server = modbus_sim('--device', 'mcd500:20', '--no-pty')
    port = server.open_tcp(framing='rtu')
    server.start()
    path = tmp_path / 'rtu_tcp.pcapng'
    transport = make_transport(LinkSettings(protocol='rtu_over_tcp', tcp_port=port,
                                            timeout_s=TIMEOUT_S), {}, TraceSettings(str(path)))
    transport.connect()
    try:
        assert [attempt(transport), attempt(transport, 23)] == ['ok', 'timeout']
    finally:
        transport.close()
        server.stop()
    rows = tshark_fields(path, 'frame.p2p_dir', 'mbrtu.unit_id', 'modbus.regval_uint16',
                         'frame.interface_name', 'frame.comment')
    line = f'127.0.0.1:{port}'
    shown = [row[:2] + [row[3]] for row in rows]
    assert shown == [['0', '20', line], ['1', '20', line], ['0', '23', line]]
    assert rows[1][2] and outcomes(rows) == ['ok', 'ok', 'timeout']


@pytest.mark.pymodbus
def test_modbus_tcp_is_traced_as_modbus_tcp_through_pymodbus(tmp_path):
    server = modbus_sim('--device', 'mcd500:20', '--no-pty')
    port = server.open_tcp(framing='mbap')
    server.start()
    path = tmp_path / 'tcp.pcapng'
    transport = make_transport(LinkSettings(protocol='modbus_tcp', tcp_port=port,
                                            timeout_s=TIMEOUT_S), {}, TraceSettings(str(path)))
    transport.connect()
    try:
        assert [attempt(transport), attempt(transport, 23)] == ['ok', 'timeout']
    finally:
        transport.close()
        server.stop()
    rows = tshark_fields(path, 'frame.p2p_dir', 'mbtcp.trans_id', 'mbtcp.unit_id',
                         'modbus.func_code', 'modbus.exception_code', 'modbus.regval_uint16',
                         'frame.comment')
    assert [row[:5] for row in rows] == [['0', '1', '20', '3', ''], ['1', '1', '20', '3', ''],
                                         ['0', '2', '23', '3', ''], ['1', '2', '23', '3', '11']]
    assert rows[1][5] and outcomes(rows) == ['ok', 'ok', 'timeout', 'timeout']


def pdu_rows(path):
    """Return (direction, dissector, bytes in hex, comment) of each packet, as tshark reads."""
    return tshark_fields(path, 'frame.p2p_dir', 'exported_pdu.prot_name',
                         'exported_pdu.exported_pdu', 'frame.comment')


def test_the_fc_protocol_through_drive_bridge_names_the_lua_dissector_with_its_bytes(tmp_path):
    on_a_pty(fc_protocol_traced, tmp_path)


def fc_protocol_traced(tmp_path) -> None:
    server = make_fc_protocol_server({1: 'fc51'})
    pty_path = server.open_pty()
    server.start()
    path = tmp_path / 'fc.pcapng'
    try:
        code = main(['status', '--protocol', 'fc_protocol', '--port', pty_path, '--family',
                     'fc', '--address', '1', '--quiet', '--wire-trace', str(path)],
                    out=io.StringIO())
        server.faults.inject(1, 'bcc')
        failed = main(['get', '--protocol', 'fc_protocol', '--port', pty_path, '--family',
                       'fc', '--address', '1', '--quiet', '--wire-trace',
                       str(tmp_path / 'fc_crc.txt'), '3-41'], out=io.StringIO())
    finally:
        server.stop()
    assert code == 0
    rows = pdu_rows(path)
    assert len(rows) >= 4 and {row[1] for row in rows} == {'danfoss_fc'}
    assert [row[0] for row in rows[:2]] == ['0', '1']
    assert all(row[2].startswith('02') for row in rows)  # STX: whole telegrams
    assert set(outcomes(rows, 3)) == {'ok'} and 'unit=1' in rows[1][3]
    lines = (tmp_path / 'fc_crc.txt').read_text().splitlines()
    assert lines[0].startswith('# drive_bridge wire trace: ')
    assert any(' RX  02 ' in line and '  crc ' in line for line in lines), (failed, lines)


def test_ap_ascii_through_drive_bridge_names_the_lua_dissector(tmp_path):
    on_a_pty(ap_ascii_traced, tmp_path)


def ap_ascii_traced(tmp_path) -> None:
    server = make_ap_ascii_server({20: 'mcd3000'})
    tap = sim_cli.wire_tap(server, argparse.Namespace(
        wire_trace=str(tmp_path / 'sim.pcapng'), link='ap', protocol='ap_ascii'))
    pty_path = server.open_pty()
    server.start()
    path = tmp_path / 'ap.pcapng'
    try:
        code = main(['--wire-trace', str(path), 'status', '--protocol', 'ap_ascii', '--port',
                     pty_path, '--family', 'mcd', '--model', 'mcd3000', '--address', '20',
                     '--quiet'], out=io.StringIO())  # the option before the command too
    finally:
        server.stop()
        tap.close()
    assert code == 0
    rows = pdu_rows(path)
    assert {row[1] for row in rows} == {'danfoss_ap_ascii'}
    sim_rows = pdu_rows(tmp_path / 'sim.pcapng')  # the simulator's side: the same bytes
    for sent, received in (('0', '1'), ('1', '0')):  # (a read may hold part of a fragment)
        assert ''.join(row[2] for row in rows if row[0] == sent) == \
            ''.join(row[2] for row in sim_rows if row[0] == received)
    assert [row[0] for row in rows[:2]] == ['0', '1']
    assert rows[0][2].startswith('04')  # EOT: the address fragment
    assert rows[1][2] == '06'  # the ACK
    assert set(outcomes(rows, 3)) == {'ok'}


def test_the_simulator_s_trace_holds_the_requests_inbound_and_matches_the_bridge_s(tmp_path):
    sim_trace, bridge_trace = tmp_path / 'sim.pcapng', tmp_path / 'bridge.pcapng'
    sim = subprocess.Popen(
        [sys.executable, '-m', 'drive_bridge.sim.cli', '--device', 'mcd500:20',
         '--wire-trace', str(sim_trace)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL, text=True)
    try:
        pty_path = ''
        for line in sim.stdout:
            if line.startswith('pty: '):
                pty_path = line.split()[1]
            if line.startswith('ready'):
                break
        assert pty_path, 'the simulator printed no pty'
        done = subprocess.run(
            [sys.executable, '-m', 'drive_bridge.tools.cli', 'status', '--port', pty_path,
             '--parity', 'N', '--family', 'mcd', '--address', '20', '--quiet',
             '--wire-trace', str(bridge_trace)], capture_output=True, text=True, timeout=120,
            stdin=subprocess.DEVNULL)
        assert done.returncode == 0, done.stderr
    finally:
        sim.send_signal(signal.SIGTERM)
        sim.wait(timeout=30)
    sim_rows = tshark_fields(sim_trace, 'frame.p2p_dir', 'mbrtu.unit_id', 'frame.interface_name')
    assert {('1', '20'), ('0', '20')} <= {(row[0], row[1]) for row in sim_rows}
    assert sim_rows[0][:2] == ['1', '20']  # a request comes in first
    assert {row[2] for row in sim_rows} == {pty_path}
    bridge = [record for _, record in trace_text.records(bridge_trace.read_bytes())]
    simulated = [record for _, record in trace_text.records(sim_trace.read_bytes())]
    for inbound in (False, True):  # the same bytes each way, the direction seen from the other
        assert b''.join(record.data for record in bridge if record.inbound == inbound) == \
            b''.join(record.data for record in simulated if record.inbound != inbound)
    assert os.path.getsize(sim_trace) > 0
