"""The FC-protocol transport against the FC-protocol simulator over a pty, and on fake ports."""

import logging
import time

from drive_bridge.errors import (
    BadFrame, CrcError, DeviceException, LineBabble, LinkDown, NoResponse, TransportError,
    TruncatedFrame, WrongAddress)
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.fc_profile import RAMP_STOP_WORD, START_WORD
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
from drive_bridge.transport.fc_protocol import FcProtocolParameterError, FcProtocolTransport
from drive_bridge.transport.link import LinkSettings
from fakes import always_readable_fd
from hypothesis import given, HealthCheck, settings, strategies as st
import pytest

FC51, VLT5000, VLT6000, NOBODY = 1, 2, 3, 9
TIMEOUT_S = 0.2
HALF_SPEED = 0x2000


def fc_settings(port: str, **kwargs) -> LinkSettings:
    return LinkSettings(protocol='fc_protocol', port=port, parity=kwargs.pop('parity', 'N'),
                        timeout_s=kwargs.pop('timeout_s', TIMEOUT_S), **kwargs)


@pytest.fixture
def line():
    server = make_fc_protocol_server({FC51: 'fc51', VLT5000: 'vlt5000', VLT6000: 'vlt6000'},
                                     {'ramp_up_s': 0.2, 'ramp_down_s': 0.2})
    server.open_pty()
    server.start()
    transport = FcProtocolTransport(fc_settings(server.pty_path))
    transport.connect()
    yield server, transport
    transport.close()
    server.stop()


def model(server, address):
    return server.devices[address].model


def test_a_pty_with_the_fc_protocol_s_8e1_opens_every_time_and_says_so_once(line, caplog):
    server, first = line
    first.close()  # one master on the line
    caplog.set_level(logging.INFO, logger='drive_bridge')
    transport = FcProtocolTransport(fc_settings(server.pty_path, parity='E'))
    for _ in range(3):
        transport.connect()
        reply = transport.execute(FC51, fc_telegram.process_request(0, 0))
        assert reply.pcd1 == model(server, FC51).status_word()
        transport.close()
    notes = [record.getMessage() for record in caplog.records
             if record.name.startswith('drive_bridge')]
    assert notes == [f'{server.pty_path} is a pty: opened without parity (a pty has no wire, '
                     'so no parity); timing as configured, 9600 baud 8E1']


def test_process_data_and_a_parameter_read_in_one_telegram(line):
    server, transport = line
    reply = transport.execute(FC51, fc_telegram.process_request(START_WORD, HALF_SPEED))
    assert reply.pke is None and reply.pcd1 == model(server, FC51).status_word()
    assert model(server, FC51).control_word == START_WORD
    read = fc_telegram.read_parameter_request(1614, control_word=START_WORD, reference=HALF_SPEED)
    deadline = time.monotonic() + 5.0
    while reply.pcd2 != HALF_SPEED:
        assert time.monotonic() < deadline
        reply = transport.execute(FC51, read)
    assert reply.ak == fc_telegram.AK_REPLY_DOUBLE and reply.pwe == model(server,
                                                                          FC51).readout(1614)
    reply = transport.execute(FC51, fc_telegram.process_request(RAMP_STOP_WORD, 0))
    assert model(server, FC51).control_word == RAMP_STOP_WORD


@pytest.mark.parametrize('address, pnu', [(VLT5000, 520), (VLT6000, 514), (FC51, 1614)])
def test_motor_current_of_each_model(line, address, pnu):
    server, transport = line
    reply = transport.execute(address, fc_telegram.read_parameter_request(pnu))
    assert (reply.pnu, reply.pwe) == (pnu, 0)  # stopped: no current


def test_an_ak7_reply_is_a_device_exception_with_the_code_and_the_status(line):
    server, transport = line
    with pytest.raises(DeviceException) as error:
        transport.execute(FC51, fc_telegram.write_parameter_request(804, 9))
    assert isinstance(error.value,
                      FcProtocolParameterError) and error.value.code == fc_telegram.OUT_OF_LIMITS
    assert 'parameter 804: the value is outside the parameter limits' in str(error.value)
    assert error.value.reply.pcd1 == model(server, FC51).status_word()
    assert error.value.kind == 'exception'


def test_writes_and_text(line):
    server, transport = line
    assert transport.execute(VLT5000, fc_telegram.write_parameter_request(104, 60,
                                                                          eeprom=True)).pwe \
        == 60
    reply = transport.execute(FC51, fc_telegram.read_text_request(1540))
    assert reply.text_value.decode() == model(server, FC51).config.type_text
    assert transport.execute(VLT6000, fc_telegram.write_text_request(533,
                                                                     'FAN 2')).text == b'FAN 2'


def test_the_1_31_format_and_a_broadcast(line):
    server, transport = line
    transport.address_format = fc_telegram.ADDRESS_FORMAT_31
    assert transport.execute(VLT5000, fc_telegram.read_parameter_request(520)).adr == VLT5000
    assert transport.execute(fc_telegram.BROADCAST, fc_telegram.process_request(START_WORD,
                                                                                0)) is None
    deadline = time.monotonic() + 2.0
    while server.broadcasts == 0:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert all(model(server, address).control_word == START_WORD
               for address in (FC51, VLT5000, VLT6000))


def test_an_unserved_address_is_no_response_in_one_timeout(line):
    server, transport = line
    started = time.monotonic()
    with pytest.raises(NoResponse, match='no reply within 0.2 s'):
        transport.execute(NOBODY, fc_telegram.process_request(0, 0))
    assert TIMEOUT_S <= time.monotonic() - started < TIMEOUT_S + 0.5
    assert server.stats.unserved == 1


@pytest.mark.parametrize('kind, error_type, error_kind', [
    ('bcc', CrcError, 'crc'), ('no_reply', NoResponse, 'timeout'),
    ('garbage', BadFrame, 'bad_frame'), ('truncated', TruncatedFrame, 'truncated'),
    ('wrong_address', WrongAddress, 'wrong_address')])
def test_each_fault_kind_is_its_typed_error_and_the_next_exchange_is_clean(
        line, kind, error_type, error_kind):
    server, transport = line
    request = fc_telegram.read_parameter_request(520)
    server.faults.inject(VLT5000, kind)
    started = time.monotonic()
    with pytest.raises(error_type) as error:
        transport.execute(VLT5000, request)
    assert error.value.kind == error_kind
    assert time.monotonic() - started < TIMEOUT_S + 0.5
    assert transport.execute(VLT5000, request).pnu == 520
    assert server.faults.injected == {(VLT5000, kind): 1}


def test_a_slow_reply_inside_the_timeout_is_taken(line):
    server, transport = line
    server.faults.inject(VLT6000, 'slow')
    started = time.monotonic()
    assert transport.execute(VLT6000, fc_telegram.read_parameter_request(514)).pnu == 514
    assert time.monotonic() - started >= server.faults.plan.slow_s == 0.1


def test_a_reply_that_does_not_answer_the_request_is_a_bad_frame(line):
    server, transport = line

    def other_parameter(address, data):
        reply = fc_telegram.decode(data).telegram
        return fc_telegram.FcTelegram(reply.adr, reply.pcd1, reply.pcd2, fc_telegram.make_pke(2,
                                                                                              514),
                                      pwe=1).encode()
    server.reply_hook = other_parameter
    with pytest.raises(BadFrame, match='reply for parameter 514, asked for 520'):
        transport.execute(VLT5000, fc_telegram.read_parameter_request(520))


def test_a_missing_port_is_link_down_with_its_name():
    transport = FcProtocolTransport(fc_settings('/dev/ttyDOESNOTEXIST'))
    with pytest.raises(LinkDown, match='bus offline: /dev/ttyDOESNOTEXIST not found'):
        transport.connect()


# -- fake ports: a babbling line, random bytes ------------------------------------------
class FakePort:
    """A port that answers ``incoming`` once written to (then silence), or babbles."""

    def __init__(self, incoming: bytes = b'', babble_s: float = 0.0):
        self.incoming = bytearray(incoming)
        self.babble_until = time.monotonic() + babble_s
        self.timeout = 0.1
        self.written = b''

    def read(self, count: int) -> bytes:
        if time.monotonic() < self.babble_until:
            return b'\xFF' * count
        data = bytes(self.incoming[:count]) if self.written else b''
        del self.incoming[:len(data)]
        return data

    def write(self, data: bytes) -> None:
        self.written += data

    def reset_input_buffer(self) -> None:
        pass

    @property
    def in_waiting(self) -> int:
        return len(self.incoming) if self.written else 0

    def fileno(self) -> int:
        return always_readable_fd()

    def close(self) -> None:
        pass


def fake_transport(port: FakePort, **kwargs) -> FcProtocolTransport:
    transport = FcProtocolTransport(fc_settings('loop://', **kwargs),
                                    open_port=lambda *args, **kw: port)
    transport.connect()
    return transport


def test_a_babbling_line_cannot_hold_the_transaction_past_its_deadline():
    transport = fake_transport(FakePort(babble_s=5.0), timeout_s=0.1)
    started = time.monotonic()
    with pytest.raises(LineBabble, match='keeps talking'):
        transport.execute(FC51, fc_telegram.process_request(0, 0))
    assert time.monotonic() - started < 2.0  # the line babbles for 5 s


def test_local_echo_is_read_before_the_reply():
    request = fc_telegram.process_request(START_WORD, HALF_SPEED)
    sent = request.telegram(FC51).encode()
    reply = fc_telegram.reply_to(fc_telegram.decode(sent).telegram, 0x0607, 0).encode()
    transport = fake_transport(FakePort(sent + reply), local_echo=True)
    assert transport.execute(FC51, request).pcd1 == 0x0607
    transport = fake_transport(FakePort(b'\x00' * 8 + reply), local_echo=True)
    with pytest.raises(BadFrame, match='did not echo'):
        transport.execute(FC51, request)


@settings(max_examples=300, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=60), st.sampled_from([
    fc_telegram.process_request(START_WORD, 0), fc_telegram.read_parameter_request(1614),
    fc_telegram.read_text_request(1540)]))
def test_random_wire_bytes_raise_only_transport_errors(wire, request):
    # A guard of 5 ms, not the protocol's 0.1 s: each failed example waits out its quarantine
    # (the guard, then 20 ms of silence), and the outcome does not depend on how long.
    transport = fake_transport(FakePort(wire), timeout_s=0.05, reply_guard_s=0.005)
    try:
        reply = transport.execute(FC51, request)
    except TransportError:
        return
    assert fc_telegram.reply_problem(request, reply) == '' and not reply.is_error


def test_the_same_line_over_tcp():
    server = make_fc_protocol_server({VLT5000: 'vlt5000'})
    port = server.open_tcp()
    server.start()
    transport = FcProtocolTransport(fc_settings(f'socket://127.0.0.1:{port}', timeout_s=1.0))
    transport.connect()
    try:
        reply = transport.execute(VLT5000, fc_telegram.read_parameter_request(
            520, control_word=START_WORD, reference=HALF_SPEED))
        assert reply.pnu == 520 and model(server, VLT5000).control_word == START_WORD
        with pytest.raises(NoResponse):
            transport.execute(NOBODY, fc_telegram.process_request(0, 0))
    finally:
        transport.close()
        server.stop()
