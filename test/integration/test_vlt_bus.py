"""The native RTU engine and the bus against the simulated VLT 5000/6000 option card."""

from drive_bridge.bus.master import BusMaster, BusTiming
from drive_bridge.config.model import build_config
from drive_bridge.errors import CommandRefused, DeviceException
from drive_bridge.protocol.requests import ReadRegisters
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from integration_helpers import wait_until
import pytest


@pytest.fixture
def sim():
    server = make_sim_server({1: 'vlt6000', 2: 'vlt5000'},
                             settings={'vlt': {'ramp_up_s': 0.5, 'ramp_down_s': 0.5}})
    server.open_pty()
    server.start()
    yield server
    server.stop()


def test_option_card_exception_codes_come_back_as_they_are(sim):
    transport = make_transport(LinkSettings(port=sim.pty_path, parity='N', timeout_s=0.2))
    transport.connect()
    try:
        with pytest.raises(DeviceException) as error:  # code 0: no such parameter
            transport.execute(1, ReadRegisters(10 * 999 - 1, 1))
        assert error.value.code == 0
        with pytest.raises(DeviceException) as error:  # text without IND 0x0400
            transport.execute(1, ReadRegisters(5329, 10, exact=False))
        assert error.value.code == 5
    finally:
        transport.close()


def test_two_vlt_models_on_one_bus(sim):
    config = build_config(
        {'port': sim.pty_path, 'parity': 'N', 'timeout': 1.0, 'devices': ['fan', 'pump']},
        {'fan': {'family': 'vlt', 'model': 'vlt6000', 'address': 1, 'poll_rate': 20.0,
                 'speed_reference': 40.0, 'comms_timeout': 29.3,
                 'drive_link_timeout': 0.8},
         'pump': {'family': 'vlt', 'model': 'vlt5000', 'address': 2, 'poll_rate': 10.0}})
    bus = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                    BusTiming(backoff_max_s=2.0))
    bus.start()
    try:
        assert wait_until(lambda: bus.snapshot('fan').online and bus.snapshot('pump').online)
        assert wait_until(lambda: sim.devices[1].model.card_timeouts == [2930, 80], 2.0)
        assert sim.devices[2].model.card_timeouts[0] == 0  # comms_timeout 0: left alone
        assert bus.submit_command('fan', 'start').result(3)
        assert wait_until(lambda: bus.snapshot('fan').reading.state == 'running', 3.0)
        reading = bus.snapshot('fan').reading
        assert reading.speed_feedback_pct == pytest.approx(40.0, abs=0.01)
        assert reading.motor_current_a > 0.5
        assert bus.write_parameter('fan', 533, '1234567890').result(3)
        assert sim.devices[1].model.parameters[533] == '1234567890'
        assert sim.devices[1].model.index == 0  # IND cleared after the text access
        assert bus.read_parameter('fan', 533).result(3) == '1234567890'
        with pytest.raises(CommandRefused, match='not possible in the present mode'):
            bus.write_parameter('fan', 104, 60).result(3)  # motor running
        assert bus.submit_command('fan', 'stop').result(3)
        assert wait_until(lambda: bus.snapshot('fan').reading.state == 'ready', 3.0)
        assert bus.write_parameter('fan', 104, 60).result(3)
        assert sim.devices[1].model.parameters[104] == 60
        with sim.lock:
            sim.devices[2].model.trip(9, sim.clock())
        assert wait_until(lambda: bus.snapshot('pump').reading.state == 'tripped', 2.0)
        assert bus.snapshot('pump').reading.trip_name == 'alarm word bit 9'
        assert bus.snapshot('pump').reading.trip_code == 1009
    finally:
        bus.shutdown(stop_motors=False)
