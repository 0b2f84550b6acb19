"""
The bridge's own wire trace, read back by tshark with the shipped Lua dissectors (issue 41).

End to end against the simulators on a pty: the bus (the ``wire_trace`` parameter) or
``drive-bridge --wire-trace`` writes the trace, and tshark loads
``drive_bridge/wireshark/*.lua`` and decodes it. The tests check the decoded fields (unit,
direction, control and status words, the starter's status) against what the simulated
devices' models hold, not bytes; skipped without tshark.
"""

import io

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.protocol.fc_profile import RAMP_STOP_WORD, START_WORD
from drive_bridge.sim.ap_ascii_server import make_ap_ascii_server
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
from drive_bridge.sim.lvsg_gateway import make_lvsg_gateway
from drive_bridge.sim.mcd_model import READY, RUNNING
from drive_bridge.tools.cli import main
from drive_bridge.tools.cli_wireshark import dissector_files
from integration_helpers import wait_until
from trace_helpers import needs_tshark, on_a_pty, outcomes, tshark

pytestmark = needs_tshark
LUA = {entry.name[:-len('.lua')]: str(entry) for entry in dissector_files()}
TIMEOUT_S = 0.5
ERROR_SEVERITY = '8388608'  # _ws.expert.severity of an error (PI_ERROR)
WARNING_SEVERITY = '6291456'  # (PI_WARN; a trace comment is PI_COMMENT, 1048576)


def flagged(row, *severities: str) -> bool:
    """Return whether a frame has an expert info of one of ``severities``."""
    return bool(set(row['_ws.expert.severity'].split(';')) & set(severities))


def hex_word(word: int) -> str:
    """Return a 16-bit word as tshark prints a base.HEX field (0x047c)."""
    return f'0x{word:04x}'


# -- the FC protocol: the bus starts a drive, a reply comes back with a bad BCC -----------
FC_FIELDS = ['frame.number', 'frame.p2p_dir', 'frame.comment', 'danfoss_fc.direction',
             'danfoss_fc.address', 'danfoss_fc.telegram_type', 'danfoss_fc.ctw',
             'danfoss_fc.ctw.start', 'danfoss_fc.ctw.data_valid', 'danfoss_fc.stw',
             'danfoss_fc.stw.running', 'danfoss_fc.stw.on_reference', 'danfoss_fc.bcc_bad',
             '_ws.expert.severity']


def test_fc_protocol_start_its_status_words_and_a_bad_bcc(tmp_path):
    on_a_pty(fc_line_traced, tmp_path)


def fc_line_traced(directory) -> None:
    path = directory / 'fc.pcapng'
    server = make_fc_protocol_server({1: 'fc51'}, {'ramp_up_s': 0.2, 'ramp_down_s': 0.2})
    server.open_pty()
    server.start()
    drive = server.devices[1].model
    devices = {'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
                        'speed_reference': 40.0}}
    config = build_config({'protocol': 'fc_protocol', 'port': server.pty_path, 'parity': 'N',
                           'timeout': TIMEOUT_S, 'devices': list(devices),
                           'wire_trace': str(path)}, devices)
    bus = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                    config.timing).start()
    try:
        assert wait_until(lambda: bus.snapshot('conv').reading, 10.0)
        idle = drive_status(server, drive)
        assert bus.submit_command('conv', 'start').result(5)
        assert wait_until(lambda: drive_on_reference(server, drive), 10.0)
        running = drive_status(server, drive)
        telegrams = len(server.devices[1].process_received)
        assert wait_until(lambda: len(server.devices[1].process_received) > telegrams + 3, 10.0)
        server.faults.inject(1, 'bcc')
        assert wait_until(lambda: bus.snapshot('conv').stats['errors_crc'] == '1', 10.0)
    finally:
        bus.shutdown(stop_motors=True)
        server.stop()
    check_fc_trace(tshark(path, LUA['danfoss_fc'], FC_FIELDS), idle, running)


def drive_status(server, drive) -> int:
    """Return the simulated drive's status word now."""
    with server.lock:
        return drive.status_word()


def drive_on_reference(server, drive) -> bool:
    """Return whether the simulated drive runs at its reference (its ramp is done)."""
    with server.lock:
        return drive.output_pct != 0.0 and drive.output_pct == drive.target_pct()


def check_fc_trace(rows, idle: int, running: int) -> None:
    """Check the decoded telegrams against the drive's idle and running status words."""
    requests = [row for row in rows if row['frame.p2p_dir'] == '0']
    replies = [row for row in rows if row['frame.p2p_dir'] == '1']
    assert len(requests) > 10 and len(replies) > 10
    assert {row['danfoss_fc.address'] for row in rows} == {'1'}
    assert {row['danfoss_fc.direction'] for row in requests} == {'0'}
    assert {row['danfoss_fc.direction'] for row in replies} == {'1'}
    assert {row['danfoss_fc.telegram_type'] for row in rows} <= {'1', '2', '3'}
    assert all(row['danfoss_fc.ctw'] and not row['danfoss_fc.stw'] for row in requests)
    assert all(row['danfoss_fc.stw'] and not row['danfoss_fc.ctw'] for row in replies)
    words = [row['danfoss_fc.ctw'] for row in requests]
    started = words.index(hex_word(START_WORD))  # the start, sent once the command came
    assert requests[started]['danfoss_fc.ctw.start'] == '1'
    assert all(row['danfoss_fc.ctw.data_valid'] == '0' for row in requests[:started])
    assert words[-1] == hex_word(RAMP_STOP_WORD)  # the shutdown's stop
    first_start = int(requests[started]['frame.number'])
    before = [row for row in replies if int(row['frame.number']) < first_start]
    assert before and {row['danfoss_fc.stw'] for row in before} == {hex_word(idle)}
    assert {row['danfoss_fc.stw.running'] for row in before} == {'0'}
    at_speed = [row for row in replies if row['danfoss_fc.stw'] == hex_word(running)]
    assert len(at_speed) >= 3 and int(at_speed[0]['frame.number']) > first_start
    assert all(row['danfoss_fc.stw.running'] == row['danfoss_fc.stw.on_reference'] == '1'
               for row in at_speed)
    check_bad_bcc(rows)


def check_bad_bcc(rows) -> None:
    """Check that the one reply with a bad BCC is an expert error traced as ``outcome=crc``."""
    bad = [row for row in rows if row['danfoss_fc.bcc_bad'] == '1']
    assert len(bad) == 1 and bad[0]['frame.p2p_dir'] == '1', bad
    assert outcomes([[bad[0]['frame.comment']]]) == ['crc']
    assert flagged(bad[0], ERROR_SEVERITY)
    replies_crc = [row['frame.number'] for row in rows if row['frame.p2p_dir'] == '1'
                   and outcomes([[row['frame.comment']]]) == ['crc']]
    assert replies_crc == [bad[0]['frame.number']]
    assert not any(flagged(row, ERROR_SEVERITY) for row in rows if row is not bad[0])


# -- AP ASCII: drive-bridge status of an MCD 3000 -----------------------------------------
AP_FIELDS = ['frame.p2p_dir', 'frame.comment', 'danfoss_ap_ascii.direction',
             'danfoss_ap_ascii.kind', 'danfoss_ap_ascii.address', 'danfoss_ap_ascii.request',
             'danfoss_ap_ascii.answers', 'danfoss_ap_ascii.status.state',
             'danfoss_ap_ascii.lrc_bad', '_ws.expert.severity']


def test_ap_ascii_status_names_the_unit_its_ack_and_the_starter_s_state(tmp_path):
    on_a_pty(ap_ascii_traced, tmp_path)


def ap_ascii_traced(directory) -> None:
    path = directory / 'ap.pcapng'
    server = make_ap_ascii_server({20: 'mcd3000'})
    pty_path = server.open_pty()
    server.start()
    try:
        code = main(['--wire-trace', str(path), 'status', '--protocol', 'ap_ascii', '--port',
                     pty_path, '--family', 'mcd', '--model', 'mcd3000', '--address', '20',
                     '--quiet'], out=io.StringIO())
        with server.lock:
            state = server.devices[20].state
    finally:
        server.stop()
    assert code == 0 and state == READY
    rows = tshark(path, LUA['danfoss_ap_ascii'], AP_FIELDS)
    ap = [{name.split('.')[-1]: value for name, value in row.items()} for row in rows]
    assert len(rows) >= 4 and set(outcomes([[row['frame.comment']] for row in rows])) == {'ok'}
    assert [row['direction'] for row in ap] == [row['frame.p2p_dir'] for row in rows]
    assert {row['address'] for row in ap} == {'20'}  # replies: of the address fragment
    assert [row['kind'] for row in ap[:2]] == ['1', '5']  # address fragment, its ACK
    asked = [index for index, row in enumerate(ap) if row['request'] == 'status']
    assert asked and ap[asked[0]]['direction'] == '0'
    reply = ap[asked[0] + 1]
    assert (reply['direction'], reply['kind'], reply['answers']) == ('1', '4', 'C22')
    assert reply['state'] == str(state)
    assert {row['lrc_bad'] for row in ap} <= {'0', ''}
    assert not any(flagged(row, ERROR_SEVERITY, WARNING_SEVERITY) for row in rows)


# -- LVSG: drive-bridge status --config of a starter behind a Modbus RTU gateway ------------
LVSG_FIELDS = ['frame.p2p_dir', 'mbrtu.unit_id', 'danfoss_lvsg.unit', 'danfoss_lvsg.image',
               'danfoss_lvsg.register', 'danfoss_lvsg.ready', 'danfoss_lvsg.on',
               'danfoss_lvsg.fault', 'danfoss_lvsg.fwd_run', 'danfoss_lvsg.state',
               '_ws.expert.severity']
LVSG_PARAMETERS = """\
/**/drive_bridge:
  ros__parameters:
    protocol: modbus_rtu
    port: {port}
    parity: "N"
    timeout: {timeout_s}
    devices: [mixer]
    mixer:
      family: lvsg
      model: mcd202
      address: 1
      gateway_input_register: 0
      gateway_output_register: 100
      gateway_byte_order: big
      lvsg_module: extended
"""


def test_lvsg_status_bits_of_a_ready_and_a_running_starter(tmp_path):
    on_a_pty(lvsg_traced, tmp_path)


def lvsg_traced(directory) -> None:
    server = make_lvsg_gateway({0: ('mcd202', 100, 'extended')}, start_time_s=0.3)
    parameters = directory / 'gateway.yaml'
    parameters.write_text(LVSG_PARAMETERS.format(port=server.open_pty(), timeout_s=TIMEOUT_S))
    server.start()
    starter = server.devices[1].slaves[0].model
    try:
        ready = lvsg_status(server, parameters, directory / 'ready.pcapng', starter)
        with server.lock:
            starter.write_register(1, 1, server.clock())  # started at its own terminals
        assert wait_until(lambda: starter_state(server, starter) == RUNNING, 10.0)
        running = lvsg_status(server, parameters, directory / 'running.pcapng', starter)
    finally:
        server.stop()
    assert ready[0] == READY and running[0] == RUNNING
    check_lvsg_trace(ready[1], ('1', '0', '0'), READY)
    check_lvsg_trace(running[1], ('0', '1', '0'), RUNNING)


def starter_state(server, starter) -> int:
    """Return the simulated starter's state now."""
    with server.lock:
        starter.advance(server.clock())
        return starter.state


def lvsg_status(server, parameters, path, starter):
    """Run drive-bridge status into the trace ``path``; return (state, decoded rows)."""
    code = main(['status', '--config', str(parameters), '--device', 'mixer', '--quiet',
                 '--wire-trace', str(path)], out=io.StringIO())
    assert code == 0
    state = starter_state(server, starter)
    return state, tshark(path, LUA['danfoss_lvsg'], LVSG_FIELDS,
                         '-o', 'danfoss_lvsg.slaves:1:0:100:extended:big')


def check_lvsg_trace(rows, bits, state: int) -> None:
    """Check the status images read: (ready, on, fault) ``bits``, the state ``state``."""
    assert not any(flagged(row, ERROR_SEVERITY) for row in rows)  # (parameter 0: a warning)
    lv = [{name.split('.')[-1]: value for name, value in row.items()} for row in rows]
    assert {row['unit_id'] for row in lv} == {'1'}
    images = [row for row in lv if row['image']]
    assert {row['unit'] for row in images} == {'1'}
    status = [row for row in images if row['image'] == '1']
    assert status and {row['p2p_dir'] for row in status} == {'1'}
    assert {row['register'] for row in status} == {'0'}
    assert {(row['ready'], row['on'], row['fault']) for row in status} == {bits}
    states = {row['state'] for row in status} - {''}  # the answer carries it when asked
    assert states <= {str(state)}
    control = [row for row in images if row['image'] == '0']  # the bridge started nothing
    assert {(row['register'], row['fwd_run']) for row in control} <= {('100', '0')}
