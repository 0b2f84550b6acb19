"""
Property-based tests: every decoder fed random and mutated input never raises unexpectedly.

Byte decoders (frames, fragments, replies) must never raise at all: they return "need more"
or an error. Value decoders raise only the typed errors their callers catch. Transports fed
random wire bytes raise only TransportError; simulated devices answer any frame or stay
silent. Seeded by hypothesis's database-free default settings, so failures reproduce.
"""

from drive_bridge.config.model import build_device
from drive_bridge.devices.contracts import FixedControl
from drive_bridge.errors import ModelMismatch, ProtocolError, TransportError
from drive_bridge.protocol import ap_ascii, fc_telegram, lvsg, rtu
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.crc import append_crc, crc_ok
from drive_bridge.protocol.fc_profile import StatusWord
from drive_bridge.protocol.requests import (
    AsciiCommand, AsciiRequest, ReadCoils, ReadRegisters, WriteCoils, WriteRegister,
    WriteRegisters)
from drive_bridge.protocol.words import registers_to_text
from drive_bridge.sim.devices import make_device
from drive_bridge.sim.lvsg_gateway import LvsgGatewaySim, LvsgSlave
from drive_bridge.sim.mcd_model import McdModel, McdSimConfig
from drive_bridge.transport.ap_ascii import ApAsciiTransport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from fakes import drive_cycle, FakeClock, ScriptedLine
from hypothesis import given, HealthCheck, settings, strategies as st

FUZZ = settings(max_examples=300, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])
WIRE = st.binary(max_size=300)
FUNCTIONS = st.sampled_from([0x01, 0x03, 0x05, 0x06, 0x0F, 0x10, 0x04, 0x2B, 0x83, 0x00])

VALID_REQUESTS = [
    rtu.read_registers_request(20, 1, 6).encode(),
    rtu.write_register_request(1, 49999, 0x047C).encode(),
    rtu.write_coils_request(1, 0, [True, False] * 16).encode(),
    rtu.write_registers_request(5, 100, [0x0100, 0x0300]).encode(),
    rtu.read_coils_request(1, 32, 32).encode(),
]
VALID_REPLIES = [
    (rtu.registers_response(20, 3, [1, 255, 0, 0, 57, 1]).encode(), 20, 3),
    (rtu.exception_response(1, 0x0F, 4).encode(), 1, 0x0F),
    (rtu.RtuFrame(1, 1, bytes([4, 7, 6, 0, 0])).encode(), 1, 1),
    (rtu.write_register_request(1, 49999, 0x047C).encode(), 1, 6),
]


@st.composite
def mutated(draw, frames):
    """Return a valid frame with bytes flipped, cut, inserted or appended."""
    frame = bytearray(draw(st.sampled_from(frames)))
    for _ in range(draw(st.integers(0, 4))):
        action = draw(st.sampled_from(['flip', 'cut', 'insert', 'append']))
        position = draw(st.integers(0, max(0, len(frame) - 1)))
        if action == 'flip' and frame:
            frame[position] ^= 1 << draw(st.integers(0, 7))
        elif action == 'cut':
            frame = frame[:position]
        elif action == 'insert':
            frame.insert(position, draw(st.integers(0, 255)))
        else:
            frame += draw(st.binary(min_size=1, max_size=8))
    return bytes(frame)


# -- Modbus RTU --------------------------------------------------------------------------
@FUZZ
@given(st.one_of(WIRE, mutated(VALID_REQUESTS)), st.booleans())
def test_request_decoder_never_raises(buffer, gap_elapsed):
    result = rtu.decode_request(buffer, gap_elapsed)
    assert 0 <= result.consumed <= len(buffer)
    if result.frame is not None:
        assert crc_ok(buffer[:result.consumed])


@FUZZ
@given(st.one_of(WIRE, mutated([reply for reply, _, _ in VALID_REPLIES])))
def test_reply_framers_never_raise(buffer):
    for framer in (rtu.ReplyFramer, ap_ascii.ReplyFramer, fc_telegram.ReplyFramer):
        result = framer.cut(buffer)
        if result.frame is not None:
            assert buffer.startswith(result.frame.raw) and result.frame.raw
        elif not result.garbage:
            assert result.needed > len(buffer)  # "need more" always asks for more
    frame = rtu.ReplyFramer.cut(buffer).frame
    if frame is not None and frame.valid:
        assert crc_ok(frame.raw) and frame.unit == buffer[0]


@FUZZ
@given(st.sampled_from(VALID_REPLIES), st.data())
def test_the_rtu_framer_reads_a_reply_arriving_in_pieces(case, data):
    reply, unit, function = case
    buffer, cuts = b'', sorted(data.draw(st.lists(st.integers(1, len(reply)), max_size=4)))
    for end in cuts + [len(reply)]:
        buffer = reply[:end]
        result = rtu.ReplyFramer.cut(buffer)
        if end < len(reply):
            assert result.frame is None and not result.garbage and result.needed > len(buffer)
    assert result.frame is not None and result.frame.valid and result.frame.raw == reply


def _transport(kind, reply: bytes):
    """Return a transport of ``kind`` whose line answers every request with ``reply``."""
    settings_ = LinkSettings(protocol='modbus_rtu', port='/dev/null', timeout_s=0.05)
    clock = FakeClock()
    line = ScriptedLine(clock, lambda request, now: [(0.001, reply)])
    transport = kind(settings_, clock=clock, line=line)
    transport.connect()
    return transport


RTU_TRANSACTIONS = [ReadRegisters(1, 6), ReadCoils(32, 32), WriteRegister(1, 1),
                    WriteCoils(0, (True,) * 32), WriteRegisters(100, (1, 2)),
                    ReadRegisters(16139, 10, exact=False)]


@FUZZ
@given(st.one_of(WIRE, mutated([reply for reply, _, _ in VALID_REPLIES]),
                 st.builds(lambda body: append_crc(bytes([20]) + body), WIRE)),
       st.sampled_from(RTU_TRANSACTIONS))
def test_rtu_transport_turns_any_wire_bytes_into_a_result_or_a_transport_error(reply,
                                                                               transaction):
    try:
        _transport(RtuSerialTransport, reply).execute(20, transaction)
    except TransportError:
        pass


# -- AP ASCII ----------------------------------------------------------------------------
ASCII_FRAMES = [ap_ascii.address_fragment(20), ap_ascii.message_fragment('C22'),
                ap_ascii.data_fragment(ap_ascii.encode_status(0x0203)),
                ap_ascii.data_fragment(ap_ascii.encode_data(123)), bytes([ap_ascii.ACK])]


@FUZZ
@given(st.one_of(WIRE, mutated(ASCII_FRAMES)))
def test_ap_ascii_decoders_never_raise(buffer):
    reply = ap_ascii.ReplyFramer.cut(buffer)
    assert reply.frame is not None or reply.garbage or reply.needed > len(buffer)
    fragment, consumed = ap_ascii.decode_fragment(buffer)
    assert 0 <= consumed <= len(buffer)


@FUZZ
@given(st.binary(max_size=12))
def test_ap_ascii_digit_decoders_raise_only_value_error(digits):
    for decode in (ap_ascii.decode_status, ap_ascii.decode_data):
        try:
            decode(digits)
        except ValueError:
            pass


@FUZZ
@given(st.one_of(WIRE, mutated(ASCII_FRAMES)),
       st.sampled_from([AsciiCommand('B10'), AsciiRequest('C22'),
                        AsciiRequest('D10', reply='data')]))
def test_ap_ascii_transport_turns_any_wire_bytes_into_a_result_or_a_transport_error(
        reply, transaction):
    transport = _transport(ApAsciiTransport, bytes([ap_ascii.ACK]) + reply)
    try:
        transport.execute(20, transaction)
    except TransportError:
        pass


# -- LVSG, FC words, text ----------------------------------------------------------------
@FUZZ
@given(st.binary(max_size=12))
def test_lvsg_decoders_raise_only_protocol_errors(data):
    for decode in (lvsg.decode_status, lvsg.Control.decode, lvsg.decode_diagnostic):
        try:
            decode(data)
        except (ProtocolError, ValueError):
            pass


@FUZZ
@given(st.integers(0, 0xFFFF), st.booleans(), st.booleans())
def test_status_word_state_is_always_a_contract_state(word, commanded, reached):
    assert StatusWord(word).state(commanded, reached) in (
        'ready', 'starting', 'running', 'stopping', 'tripped', 'not_ready')


@FUZZ
@given(st.lists(st.integers(0, 0xFFFF), max_size=40))
def test_text_registers_always_decode(registers):
    assert isinstance(registers_to_text(registers), str)


# -- device profiles ---------------------------------------------------------------------
PROFILES = {
    'mcd500': ({'family': 'mcd', 'model': 'auto', 'address': 20}, 'modbus_rtu'),
    'mcd3000': ({'family': 'mcd', 'model': 'mcd3000', 'address': 20}, 'modbus_rtu'),
    'ascii': ({'family': 'mcd', 'model': 'auto', 'address': 20}, 'ap_ascii'),
    'fc51': ({'family': 'fc', 'model': 'auto', 'address': 1}, 'modbus_rtu'),
    'vlt': ({'family': 'vlt', 'model': 'vlt5000', 'address': 1}, 'modbus_rtu'),
    'lvsg': ({'family': 'lvsg', 'model': 'auto', 'address': 1, 'gateway_input_register': 0,
              'gateway_output_register': 100}, 'modbus_rtu'),
}


def _random_result(transaction, data):
    if isinstance(transaction, ReadRegisters):
        count = transaction.count if transaction.exact else \
            data.draw(st.integers(1, transaction.count))
        return data.draw(st.lists(st.integers(0, 0xFFFF), min_size=count, max_size=count))
    if isinstance(transaction, ReadCoils):
        return data.draw(st.lists(st.booleans(), min_size=transaction.count,
                                  max_size=transaction.count))
    if isinstance(transaction, AsciiRequest):
        return data.draw(st.integers(0, 9999))
    return None


@FUZZ
@given(st.sampled_from(sorted(PROFILES)), st.sampled_from([None, Command.START, Command.STOP]),
       st.data())
def test_profiles_decode_any_register_values_into_a_reading_or_a_typed_error(name, steady,
                                                                             data):
    values, protocol = PROFILES[name]
    profile = build_device(name, values, protocol).make_spec().profile
    control = FixedControl(steady, writes_allowed=data.draw(st.booleans()))
    for _ in range(3):  # a few polls: identification, rotation, parameter cycling
        try:
            requests, reading = drive_cycle(
                profile, lambda request: _random_result(request, data), control)
        except (ModelMismatch, ProtocolError):
            continue
        assert isinstance(reading.state, str) and 0 <= reading.status_word <= 0xFFFF
        assert 0 <= reading.trip_code <= 0xFFFF
        assert control.writes_allowed or not any(request.writes for request in requests)


# -- simulators --------------------------------------------------------------------------
def _sim_devices():
    lvsg_slave = LvsgSlave(McdModel(McdSimConfig(model='mcd202'), 0.0), 0, 100)
    return [make_device('mcd500', 0.0), make_device('mcd3000', 0.0), make_device('fc51', 0.0),
            make_device('vlt5000', 0.0), LvsgGatewaySim([lvsg_slave])]


@FUZZ
@given(st.one_of(st.binary(max_size=64).map(lambda data: (3, data)),
                 st.tuples(FUNCTIONS, st.binary(max_size=64)),
                 mutated(VALID_REQUESTS).map(lambda raw: (raw[1] if len(raw) > 1 else 0,
                                                          raw[2:]))))
def test_simulated_devices_answer_any_frame_or_stay_silent(request):
    function, data = request
    frame = rtu.RtuFrame(1, function, data)
    for device in _sim_devices():
        reply = device.handle(frame, 1.0)
        assert reply is None or isinstance(reply, rtu.RtuFrame)
