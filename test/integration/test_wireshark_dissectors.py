"""
The shipped Wireshark Lua dissectors, read back by tshark (skipped without it).

Traces are built with :mod:`drive_bridge.protocol.pcapng` from frames the project's own
codecs encode, and from the manuals' worked frames (the VLT 5000 / FC 300 Design Guides' FC
telegrams quoted in ``fc_telegram.py``, the AP ASCII start command of manual 000 10.4).
"""

import io
import os
import random
import struct
import subprocess

from drive_bridge.protocol import ap_ascii, fc_profile, lvsg, pcapng
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.crc import append_crc
from drive_bridge.protocol.fc_profile_scaling import percent_to_word
from drive_bridge.protocol.words import bytes_to_registers
from drive_bridge.tools import cli
from drive_bridge.tools.cli_wireshark import dissector_files
import pytest
from trace_helpers import needs_tshark, TSHARK, tshark

pytestmark = needs_tshark

T0_NS = 1_764_000_000_000_000_000
LUA = {entry.name[:-len('.lua')]: str(entry) for entry in dissector_files()}
SENT, RECEIVED = False, True


def write_trace(path, dissector, frames):
    """Write ``frames`` [(inbound, payload)] as exported PDUs for ``dissector``."""
    with open(path, 'wb') as trace:
        trace.write(pcapng.section_header())
        trace.write(pcapng.interface_description('/dev/ttyUSB0'))
        for index, (inbound, payload, *ports) in enumerate(frames):
            trace.write(pcapng.enhanced_packet(
                0, T0_NS + index * 1_000_000,
                pcapng.exported_pdu(dissector, payload, ports[0] if ports else None),
                inbound))


def errors(path, script, *options):
    """Return the frame numbers with an expert info of severity error."""
    rows = tshark(path, script, ['frame.number'], *options,
                  display_filter='_ws.expert.severity == error')
    return [int(row['frame.number']) for row in rows]


# -- every shipped file loads -----------------------------------------------------------
@pytest.mark.parametrize('name', ['danfoss_fc', 'danfoss_ap_ascii', 'danfoss_lvsg'])
def test_every_shipped_dissector_loads_without_error_and_registers_its_name(tmp_path, name):
    path = tmp_path / 'empty.pcapng'
    write_trace(path, 'mbrtu', [(SENT, append_crc(bytes([1, 3, 0, 0, 0, 1])))])
    assert sorted(LUA) == ['danfoss_ap_ascii', 'danfoss_fc', 'danfoss_lvsg']
    assert tshark(path, LUA[name], [name]) == [{name: ''}]  # an unknown field fails tshark


# -- the FC protocol --------------------------------------------------------------------
def fc_frames():
    """Return (inbound, bytes) of the manuals' worked telegrams and the codec's."""
    text_body = bytes.fromhex('02 11 01 F0 01 00 01') + b'ENGLISH' + bytes(4)
    quick_stop = fc_profile.COMMAND_WORDS[fc_profile.Command.QUICK_STOP]
    request = fc_telegram.FcTelegram(fc_telegram.encode_address(5), quick_stop,
                                     percent_to_word(-25.0),
                                     fc_telegram.make_pke(fc_telegram.AK_WRITE_WORD, 1614), 2, 300)
    bad_bcc = bytearray(fc_telegram.FcTelegram(fc_telegram.encode_address(5), 0x0E07, 0).encode())
    bad_bcc[-1] ^= 0x01
    return [
        # VLT 5000 Design Guide MG.52.B2.02: start at 50 % (ADR 4, format 1-31) and its reply
        (SENT, bytes.fromhex('02 06 04 04 7C 20 00 58')),
        (RECEIVED, bytes.fromhex('02 06 04 06 07 00 00 01')),
        # read par. 520 and the reply: 524 (5.24 A), status 0607h
        (SENT, bytes.fromhex('02 0E 01 12 08 00 00 00 00 00 00 00 00 00 00 17')),
        (RECEIVED, bytes.fromhex('02 0E 01 22 08 00 00 00 00 02 0C 06 07 00 00 28')),
        # "Additional Text": a text reply (AK 15, PNU 1, IND 1) "ENGLISH"
        (RECEIVED, text_body + bytes([fc_telegram.bcc(text_body)])),
        # the codec: a quick stop at -25 % writing 300 to 16-14 (format 1-126), an AK 7 reply
        (SENT, request.encode()),
        (RECEIVED, fc_telegram.error_reply(request, fc_telegram.NOT_WHILE_RUNNING, 0x0F0F,
                                           0).encode()),
        # a broadcast start, a running drive on reference with a warning, a tripped drive
        (SENT, fc_telegram.FcTelegram(fc_telegram.encode_address(0), fc_profile.START_WORD,
                                      percent_to_word(100.0)).encode()),
        (RECEIVED, fc_telegram.FcTelegram(fc_telegram.encode_address(5), 0x0F87,
                                          percent_to_word(75.0)).encode()),
        (RECEIVED, bytes(bad_bcc)),  # 10: bad BCC
        (SENT, b'\x03\x06\x04'),  # 11: unknown start byte
        (SENT, bytes.fromhex('02 07 04 04 7C 20 00 58')),  # 12: LGE 7
        (RECEIVED, bytes.fromhex('02 06 04 06 07 00 00 01 00')),  # 13: a byte too many
        (RECEIVED, bytes.fromhex('02 06 04 06 07')),  # 14: cut
    ]


@pytest.fixture(scope='module')
def fc_trace(tmp_path_factory):
    path = tmp_path_factory.mktemp('fc') / 'fc.pcapng'
    write_trace(path, 'danfoss_fc', fc_frames())
    return path


FC_FIELDS = ['frame.p2p_dir', 'danfoss_fc.direction', 'danfoss_fc.address',
             'danfoss_fc.address_format', 'danfoss_fc.broadcast', 'danfoss_fc.telegram_type',
             'danfoss_fc.lge', 'danfoss_fc.ak', 'danfoss_fc.pnu', 'danfoss_fc.ind',
             'danfoss_fc.pwe', 'danfoss_fc.error_code', 'danfoss_fc.text', 'danfoss_fc.ctw',
             'danfoss_fc.ctw.start', 'danfoss_fc.ctw.quick_stop_off', 'danfoss_fc.ctw.coast_off',
             'danfoss_fc.ctw.data_valid', 'danfoss_fc.ref', 'danfoss_fc.ref_percent',
             'danfoss_fc.stw', 'danfoss_fc.stw.running', 'danfoss_fc.stw.trip',
             'danfoss_fc.stw.warning', 'danfoss_fc.stw.on_reference', 'danfoss_fc.stw.bus_control',
             'danfoss_fc.mav_percent', 'danfoss_fc.bcc_bad', '_ws.col.Info']


@pytest.fixture(scope='module')
def fc_rows(fc_trace):
    return tshark(fc_trace, LUA['danfoss_fc'], FC_FIELDS)


def pick(row, *names):
    return [row[f'danfoss_fc.{name}'] for name in names]


def test_fc_manual_start_and_its_reply(fc_rows):
    start, reply = fc_rows[0], fc_rows[1]
    assert start['frame.p2p_dir'] == '0' and reply['frame.p2p_dir'] == '1'
    assert pick(start, 'direction', 'address', 'address_format', 'telegram_type', 'ctw',
                'ctw.start', 'ctw.data_valid', 'ref', 'ref_percent', 'bcc_bad') == \
        ['0', '4', '1-31', '1', '0x047c', '1', '1', '0x2000', '50', '0']
    assert start['danfoss_fc.stw'] == '' and start['danfoss_fc.ak'] == ''
    assert start['_ws.col.Info'] == 'Request ADR 4 process: CTW 0x047C (run) REF 50.0 %'
    assert pick(reply, 'direction', 'stw', 'stw.running', 'stw.trip', 'stw.bus_control',
                'mav_percent', 'ctw') == ['1', '0x0607', '0', '0', '1', '0', '']
    assert reply['_ws.col.Info'] == 'Reply ADR 4 process: STW 0x0607 (ready) MAV 0.0 %'


def test_fc_manual_parameter_read_text_reply_and_the_codecs_write(fc_rows):
    read, value, text, write, refused = fc_rows[2:7]
    assert pick(read, 'telegram_type', 'lge', 'ak', 'pnu', 'pwe', 'ctw.data_valid') == \
        ['2', '14', '1', '520', '0', '0']
    assert pick(value, 'ak', 'pnu', 'pwe', 'stw') == ['2', '520', '524', '0x0607']
    assert 'AK 2 value (double word) PNU 520' in value['_ws.col.Info']
    assert pick(text, 'telegram_type', 'ak', 'pnu', 'ind', 'text', 'bcc_bad') == \
        ['3', '15', '1', '0x0001', 'ENGLISH', '0']
    assert pick(write, 'address', 'address_format', 'ak', 'pnu', 'ind', 'pwe', 'ctw',
                'ctw.quick_stop_off', 'ctw.start', 'ref_percent') == \
        ['5', '1-126', '2', '1614', '0x0002', '300', '0x042c', '0', '0', '-25']
    assert 'CTW 0x042C (quick stop) REF -25.0 %' in write['_ws.col.Info']
    assert pick(refused, 'ak', 'pnu', 'error_code') == ['7', '1614', '17']
    assert 'error 17 (not possible while running' in refused['_ws.col.Info']


def test_fc_broadcast_and_status_bits(fc_rows):
    broadcast, running = fc_rows[7], fc_rows[8]
    assert pick(broadcast, 'address', 'broadcast', 'ctw', 'ref_percent') == \
        ['0', '1', '0x047c', '100']
    assert broadcast['_ws.col.Info'].startswith('Request broadcast process:')
    assert pick(running, 'stw', 'stw.running', 'stw.warning', 'stw.on_reference',
                'mav_percent') == ['0x0f87', '1', '1', '1', '75']
    assert 'STW 0x0F87 (running, on reference, warning) MAV 75.0 %' in running['_ws.col.Info']


def test_fc_errors_are_expert_errors(fc_trace, fc_rows):
    assert [row['danfoss_fc.bcc_bad'] for row in fc_rows[:10]] == ['0'] * 9 + ['1']
    assert fc_rows[9]['_ws.col.Info'].endswith('[BAD BCC]')
    assert fc_rows[10]['_ws.col.Info'] == 'Request: unknown start byte 03h'
    assert fc_rows[11]['_ws.col.Info'] == 'Request: wrong length, LGE 7'
    assert fc_rows[12]['_ws.col.Info'].endswith('[WRONG LENGTH]')
    assert errors(fc_trace, LUA['danfoss_fc']) == [10, 11, 12, 13, 14]
    bad = tshark(fc_trace, LUA['danfoss_fc'], ['frame.number'],
                 display_filter='danfoss_fc.bcc_bad == 1')
    assert bad == [{'frame.number': '10'}]


# -- AP ASCII ---------------------------------------------------------------------------
def exchange(address, code, answer):
    """Return a master's exchange with ``address``: fragments, ACKs, the starter's answer."""
    return [(SENT, ap_ascii.address_fragment(address)), (RECEIVED, bytes([ap_ascii.ACK])),
            (SENT, ap_ascii.message_fragment(code)), (RECEIVED, answer)]


def ap_frames():
    ack = bytes([ap_ascii.ACK])
    bad_lrc = ap_ascii.message_fragment('B12')[:-3] + b'00\x03'
    return (
        exchange(7, 'B10', ack)  # 1-4; frame 3 is the manual's 02 42 31 30 35 42 03
        + exchange(7, 'C22', ap_ascii.data_fragment(ap_ascii.encode_status(0x43)))  # 5-8
        + exchange(7, 'C22', ap_ascii.data_fragment(ap_ascii.encode_status(0xC8, 'offset')))
        + exchange(7, 'C18', ap_ascii.data_fragment(ap_ascii.encode_status(2)))  # 13-16
        + exchange(7, 'D10', ap_ascii.data_fragment(ap_ascii.encode_data(123)))  # 17-20
        + exchange(12, 'D12', ap_ascii.data_fragment(ap_ascii.encode_data(105)))  # 21-24
        + [(SENT, ap_ascii.address_fragment(12)), (RECEIVED, ack),  # 25, 26
           (SENT, bad_lrc), (RECEIVED, bytes([ap_ascii.NAK])),  # 27, 28
           (SENT, ap_ascii.message_fragment('B16')), (RECEIVED, bytes([ap_ascii.BEL])),  # 29, 30
           (RECEIVED, b'\x99'),  # 31: unknown start byte
           (RECEIVED, ap_ascii.data_fragment(b'0012')[:6])]  # 32: cut
        # manual 001: "status byte = 1Fh, response is: STX 30h 30h 31h 46h LRC1 LRC2 ETX"
        + exchange(7, 'C22', bytes([2, 0x30, 0x30, 0x31, 0x46]) + b'%02X\x03' % (
            -(2 + 0x30 + 0x30 + 0x31 + 0x46) & 0xFF)))  # 33-36


@pytest.fixture(scope='module')
def ap_trace(tmp_path_factory):
    path = tmp_path_factory.mktemp('ap') / 'ap.pcapng'
    write_trace(path, 'danfoss_ap_ascii', ap_frames())
    return path


AP_FIELDS = ['danfoss_ap_ascii.direction', 'danfoss_ap_ascii.kind', 'danfoss_ap_ascii.address',
             'danfoss_ap_ascii.code', 'danfoss_ap_ascii.command', 'danfoss_ap_ascii.request',
             'danfoss_ap_ascii.data', 'danfoss_ap_ascii.answers', 'danfoss_ap_ascii.status',
             'danfoss_ap_ascii.status.state', 'danfoss_ap_ascii.status.initialised',
             'danfoss_ap_ascii.status.positive_rotation',
             'danfoss_ap_ascii.status.comms_fault', 'danfoss_ap_ascii.trip_code',
             'danfoss_ap_ascii.trip_name', 'danfoss_ap_ascii.current_a',
             'danfoss_ap_ascii.temperature_pct', 'danfoss_ap_ascii.reply',
             'danfoss_ap_ascii.lrc_bad', '_ws.col.Info']


@pytest.fixture(scope='module')
def ap_rows(ap_trace):
    return tshark(ap_trace, LUA['danfoss_ap_ascii'], AP_FIELDS)


def ap(row, *names):
    return [row[f'danfoss_ap_ascii.{name}'] for name in names]


def test_ap_ascii_manual_start_command_and_its_acknowledgements(ap_rows):
    assert ap_ascii.message_fragment('B10') == bytes.fromhex('02 42 31 30 35 42 03')
    address, ack, start, accepted = ap_rows[:4]
    assert ap(address, 'direction', 'kind', 'address', 'lrc_bad') == ['0', '1', '7', '0']
    assert address['_ws.col.Info'] == 'Master unit 7: address fragment'
    assert ap(ack, 'direction', 'kind', 'address', 'reply') == ['1', '5', '7', '0x06']
    assert ack['_ws.col.Info'] == 'Starter unit 7: ACK to the address'
    assert ap(start, 'kind', 'address', 'code', 'command', 'lrc_bad') == \
        ['2', '7', 'B10', 'start', '0']
    assert start['_ws.col.Info'] == 'Master unit 7: command B10 (start)'
    assert ap(accepted, 'kind', 'answers') == ['5', 'B10']
    assert accepted['_ws.col.Info'] == 'Starter unit 7: ACK to B10'


def test_ap_ascii_replies_decoded_as_their_request_asked(ap_rows):
    status, offset_status, trip = ap_rows[7], ap_rows[11], ap_rows[15]
    assert ap(ap_rows[6], 'kind', 'request') == ['3', 'status']
    assert ap(status, 'direction', 'kind', 'address', 'answers', 'data', 'status',
              'status.state', 'status.initialised', 'status.comms_fault', 'lrc_bad') == \
        ['1', '4', '7', 'C22', '0043', '0x43', '3', '1', '0', '0']
    assert status['_ws.col.Info'] == 'Starter unit 7: status 0x43 (running)'
    assert ap(offset_status, 'data', 'status', 'status.state', 'status.comms_fault') == \
        ['00<8', '0xc8', '8', '1']  # the manual's text: 30h + nibble
    assert offset_status['_ws.col.Info'] == \
        'Starter unit 7: status 0xC8 (jog forward), communications device fault'
    assert ap(trip, 'answers', 'trip_code', 'trip_name') == \
        ['C18', '2', 'Motor overload (thermal model)']
    assert ap(ap_rows[19], 'answers', 'current_a') == ['D10', '123']
    assert ap(ap_rows[23], 'address', 'answers', 'temperature_pct') == ['12', 'D12', '105']
    assert ap_rows[23]['_ws.col.Info'] == 'Starter unit 12: motor temperature 105 %'
    assert ap(ap_rows[35], 'data', 'status', 'status.state', 'status.positive_rotation',
              'lrc_bad') == ['001F', '0x1f', '15', '1', '0']


def test_ap_ascii_errors_nak_and_bel(ap_trace, ap_rows):
    assert [row['danfoss_ap_ascii.lrc_bad'] for row in ap_rows[24:27]] == ['0', '', '1']
    assert ap_rows[26]['_ws.col.Info'].endswith('[BAD LRC]')
    assert ap(ap_rows[27], 'kind', 'answers') == ['6', 'B12']
    assert ap_rows[27]['_ws.col.Info'] == 'Starter unit 12: NAK to B12 (the starter saw a bad LRC)'
    assert ap(ap_rows[29], 'kind', 'answers') == ['7', 'B16']
    assert 'BEL to B16 (refused)' in ap_rows[29]['_ws.col.Info']
    assert ap_rows[30]['_ws.col.Info'] == 'Starter unknown start byte 99h'
    assert 'WRONG LENGTH' in ap_rows[31]['_ws.col.Info']
    assert errors(ap_trace, LUA['danfoss_ap_ascii']) == [27, 28, 31, 32]


# -- the LVSG image ---------------------------------------------------------------------
def read(unit, register, count):
    return append_crc(struct.pack('>BBHH', unit, 3, register, count))


def answer(unit, registers):
    return append_crc(struct.pack(f'>BBB{len(registers)}H', unit, 3, 2 * len(registers),
                                  *registers))


def write_single(unit, register, value):
    return append_crc(struct.pack('>BBHH', unit, 6, register, value))


def write_multiple(unit, register, registers):
    return append_crc(struct.pack(f'>BBHHB{len(registers)}H', unit, 16, register,
                                  len(registers), 2 * len(registers), *registers))


def lvsg_frames():
    """Two slaves behind unit 1 (extended big-endian at 0/100, basic little at 10/110)."""
    running = lvsg.encode_status(True, True, False, True, lvsg.current_raw_from_pct(100.0),
                                 (lvsg.PARAMETER_STATE, 255 << 8 | 0x43, False))
    current = lvsg.encode_status(True, True, False, False, 20, (lvsg.PARAMETER_CURRENT, 517,
                                                                False))
    start = lvsg.Control(fwd_run=True, parameter_request=lvsg.PARAMETER_CURRENT).encode(True)
    tripped = lvsg.encode_status(False, False, True, False, 0)
    quick = lvsg.Control(quick_stop=True, reset=True).encode(False)
    return [
        (SENT, write_single(1, 101, bytes_to_registers(start)[1])),  # 1, 2: the request
        (RECEIVED, write_single(1, 101, bytes_to_registers(start)[1])),
        (SENT, read(1, 0, 3)), (RECEIVED, answer(1, bytes_to_registers(running))),  # 3, 4
        (SENT, write_multiple(1, 100, bytes_to_registers(start))),  # 5
        (RECEIVED, append_crc(struct.pack('>BBHH', 1, 16, 100, 2))),  # 6
        (SENT, read(1, 0, 3)), (RECEIVED, answer(1, bytes_to_registers(current))),  # 7, 8
        (SENT, read(1, 10, 1)),  # 9, 10: the basic slave, little-endian
        (RECEIVED, answer(1, bytes_to_registers(tripped, 'little'))),
        (SENT, write_single(1, 110, bytes_to_registers(quick, 'little')[0])),  # 11
        (SENT, read(2, 0, 3)), (RECEIVED, answer(2, bytes_to_registers(running))),  # 12, 13
    ]


SLAVES = '1:0:100:extended:big, 1:10:110:basic:little'
LVSG_FIELDS = ['danfoss_lvsg.unit', 'danfoss_lvsg.image', 'danfoss_lvsg.register',
               'danfoss_lvsg.fwd_run', 'danfoss_lvsg.reset', 'danfoss_lvsg.quick_stop',
               'danfoss_lvsg.parameter_request', 'danfoss_lvsg.ready', 'danfoss_lvsg.on',
               'danfoss_lvsg.fault', 'danfoss_lvsg.ramping', 'danfoss_lvsg.current_raw',
               'danfoss_lvsg.current_pct_flc', 'danfoss_lvsg.parameter', 'danfoss_lvsg.value',
               'danfoss_lvsg.trip_code', 'danfoss_lvsg.state', 'danfoss_lvsg.current_a',
               'danfoss_lvsg.rotation_validated', '_ws.col.Info']


@pytest.fixture(scope='module')
def lvsg_trace(tmp_path_factory):
    path = tmp_path_factory.mktemp('lvsg') / 'lvsg.pcapng'
    write_trace(path, 'mbrtu', lvsg_frames())
    return path


@pytest.fixture(scope='module')
def lvsg_rows(lvsg_trace):
    return tshark(lvsg_trace, LUA['danfoss_lvsg'], LVSG_FIELDS, '-o',
                  f'danfoss_lvsg.slaves:{SLAVES}')


def lv(row, *names):
    return [row[f'danfoss_lvsg.{name}'] for name in names]


def test_lvsg_control_image_written_by_the_codec(lvsg_rows):
    request, write, quick = lvsg_rows[0], lvsg_rows[4], lvsg_rows[10]
    assert lv(request, 'unit', 'image', 'register', 'parameter_request', 'fwd_run') == \
        ['1', '0', '100', '3', '']  # only output byte 2 is in register 101
    assert lv(write, 'image', 'fwd_run', 'reset', 'quick_stop', 'parameter_request') == \
        ['0', '1', '0', '0', '3']
    assert write['_ws.col.Info'].endswith('| LVSG unit 1 control @100: Fwd Run, request '
                                          'parameter 3')
    assert lv(quick, 'image', 'register', 'fwd_run', 'reset', 'quick_stop') == \
        ['0', '110', '0', '1', '1']
    assert lv(lvsg_rows[2], 'image') == ['']  # a read request carries no image


def test_lvsg_status_image_read_with_the_extended_answer(lvsg_rows):
    running, current, tripped = lvsg_rows[3], lvsg_rows[7], lvsg_rows[9]
    assert lv(running, 'image', 'register', 'ready', 'on', 'fault', 'ramping', 'current_raw',
              'parameter', 'value', 'trip_code', 'state', 'rotation_validated') == \
        ['1', '0', '1', '1', '0', '1', '32', '2', '65347', '255', '3', '1']
    assert running['danfoss_lvsg.current_pct_flc'].startswith('101.5')
    assert 'LVSG unit 1 status @0: Ready On, Ramping, 102 % FLC, state running, trip no trip' \
        in running['_ws.col.Info']
    assert lv(current, 'parameter', 'value', 'current_a', 'ramping') == \
        ['3', '517', '517', '0']
    assert lv(tripped, 'register', 'ready', 'on', 'fault', 'parameter') == \
        ['10', '0', '0', '1', '']
    assert lv(lvsg_rows[12], 'unit') == ['']  # unit 2 is no slave of the preference


def test_lvsg_over_modbus_tcp(tmp_path):
    mbap = struct.pack('>HHHB', 9, 0, 6, 1) + bytes([3, 0, 0, 0, 3])
    status = bytes_to_registers(lvsg.encode_status(True, False, False, False, 0,
                                                   (lvsg.PARAMETER_TEMPERATURE, 41, False)))
    body = bytes([3, 6]) + struct.pack('>3H', *status)
    reply = struct.pack('>HHHB', 9, 0, len(body) + 1, 1) + body
    path = tmp_path / 'tcp.pcapng'
    write_trace(path, 'mbtcp', [(SENT, mbap, (50123, 502)), (RECEIVED, reply, (502, 50123))])
    rows = tshark(path, LUA['danfoss_lvsg'], ['mbtcp.unit_id', 'danfoss_lvsg.ready',
                                              'danfoss_lvsg.parameter',
                                              'danfoss_lvsg.temperature_pct'],
                  '-o', 'danfoss_lvsg.slaves:1:0:100')
    assert rows[1] == {'mbtcp.unit_id': '1', 'danfoss_lvsg.ready': '1',
                       'danfoss_lvsg.parameter': '4', 'danfoss_lvsg.temperature_pct': '41'}


def test_lvsg_does_nothing_unconfigured_and_names_a_bad_preference(lvsg_trace):
    rows = tshark(lvsg_trace, LUA['danfoss_lvsg'], ['danfoss_lvsg.unit', 'modbus.func_code'])
    assert [row['danfoss_lvsg.unit'] for row in rows] == [''] * 13
    assert errors(lvsg_trace, LUA['danfoss_lvsg'], '-o', 'danfoss_lvsg.slaves:1:0') == \
        list(range(1, 14))
    assert errors(lvsg_trace, LUA['danfoss_lvsg'], '-o', f'danfoss_lvsg.slaves:{SLAVES}') == []


# -- drive-bridge wireshark -------------------------------------------------------------
def test_install_puts_them_where_tshark_loads_them(tmp_path, fc_trace, monkeypatch):
    home = tmp_path / 'home'
    monkeypatch.setenv('HOME', str(home))  # the default folder is the personal one under it
    assert cli.main(['wireshark', '--install'], io.StringIO()) == 0
    env = dict(os.environ, HOME=str(home))
    plugins = home / '.local' / 'lib' / 'wireshark' / 'plugins'
    assert sorted(os.listdir(plugins)) == ['danfoss_ap_ascii.lua', 'danfoss_fc.lua',
                                           'danfoss_lvsg.lua']
    done = subprocess.run([TSHARK, '-n', '-r', str(fc_trace), '-T', 'fields', '-e',
                           'danfoss_fc.address'], capture_output=True, text=True, env=env,
                          timeout=120, check=True)
    assert done.stdout.splitlines()[:2] == ['4', '4']


def test_path_names_a_shipped_file_and_refuses_an_unknown_name(capsys):
    out = io.StringIO()
    assert cli.main(['wireshark', '--path', 'danfoss_fc'], out) == 0
    assert out.getvalue().strip() == LUA['danfoss_fc']
    assert cli.main(['wireshark', '--path', 'danfoss_xyz'], io.StringIO()) == 2
    assert capsys.readouterr().err.startswith("drive-bridge: no dissector 'danfoss_xyz'")


# -- any bytes --------------------------------------------------------------------------
def garbage(rng, starts, count=300):
    """Return ``count`` frames of random bytes, most beginning with one of ``starts``."""
    frames = []
    for _ in range(count):
        body = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 24)))
        if body and rng.random() < 0.8:
            body = bytes([rng.choice(starts)]) + body[1:]
        frames.append((rng.random() < 0.5, body))
    return frames


def modbus_garbage(rng, count=300):
    """Return Modbus RTU frames of functions 3, 6 and 16 cut or padded at random."""
    frames = []
    for _ in range(count):
        unit, code = rng.choice([1, 2]), rng.choice([3, 6, 16, 0x83])
        body = bytes([unit, code]) + struct.pack('>HH', rng.choice([0, 1, 2, 10, 100, 101]),
                                                 rng.randrange(0, 5))
        body += bytes(rng.randrange(256) for _ in range(rng.randrange(0, 12)))
        frames.append((rng.random() < 0.5, append_crc(body[:rng.randrange(1, len(body) + 1)])))
    return frames


@pytest.mark.parametrize('dissector, frames, options', [
    ('danfoss_fc', lambda rng: garbage(rng, [fc_telegram.STX, fc_telegram.STX, 0x06, 0x0E, 0x11]),
     ()),
    ('danfoss_ap_ascii', lambda rng: garbage(rng, [2, 4, 6, 0x15, 7]), ()),
    ('danfoss_lvsg', modbus_garbage, ('-o', f'danfoss_lvsg.slaves:{SLAVES}, 2:0:1')),
])
def test_any_bytes_decode_without_a_lua_error(tmp_path, dissector, frames, options):
    rng = random.Random(41)
    path = tmp_path / 'garbage.pcapng'
    carrier = 'mbrtu' if dissector == 'danfoss_lvsg' else dissector
    write_trace(path, carrier, frames(rng))
    rows = tshark(path, LUA[dissector], ['frame.number', '_ws.col.Info'], *options)
    assert len(rows) == 300
    if dissector != 'danfoss_lvsg':  # Wireshark's Modbus dissector names no cut frame
        assert all(row['_ws.col.Info'] for row in rows)
