"""The bus against the simulated Profibus gateway over Modbus TCP and RTU over TCP."""

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.sim.lvsg_gateway import make_lvsg_gateway
from drive_bridge.sim.mcd_model import READY, RUNNING, TRIPPED
from integration_helpers import wait_until
import pytest

SLAVES = {0: ('mcd202', 100, 'extended'), 10: ('mcd201', 110, 'basic')}
DEVICES = {
    'conveyor': {'family': 'lvsg', 'model': 'auto', 'address': 1, 'poll_rate': 20.0,
                 'gateway_input_register': 0, 'gateway_output_register': 100},
    'fan': {'family': 'lvsg', 'model': 'mcd201', 'address': 1, 'poll_rate': 20.0,
            'gateway_input_register': 10, 'gateway_output_register': 110,
            'lvsg_module': 'basic'},
}


@pytest.fixture(params=[pytest.param('modbus_tcp', marks=pytest.mark.pymodbus),
                        'rtu_over_tcp'])  # Modbus TCP runs through pymodbus
def gateway(request):
    server = make_lvsg_gateway(SLAVES, start_time_s=0.3, stop_time_s=0.3)
    port = server.open_tcp(framing='mbap' if request.param == 'modbus_tcp' else 'rtu')
    server.start()
    config = build_config({'protocol': request.param, 'tcp_port': port, 'timeout': 0.3,
                           'devices': list(DEVICES)}, DEVICES)
    bus = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                    config.timing).start()
    bus.slaves = server.devices[1].slaves
    bus.gateway = server.devices[1]
    yield bus
    bus.shutdown(stop_motors=False)
    server.stop()


def reading(bus, name):
    return bus.snapshot(name).reading


def test_start_current_quick_stop_trip_reset(gateway):
    bus, slave = gateway, gateway.slaves[0]
    assert wait_until(lambda: bus.snapshot('conveyor').model == 'mcd202', 3.0)
    assert slave.model.state == READY  # adopting the image started nothing
    assert bus.submit_command('conveyor', 'start').result(3)
    assert wait_until(lambda: reading(bus, 'conveyor').state == 'running', 3.0)
    assert wait_until(lambda: (reading(bus, 'conveyor').motor_current_a or 0) > 70, 3.0)
    assert bus.submit_command('conveyor', 'quick_stop').result(3)
    assert slave.model.commands_received[-1] == 4  # Fwd Run 1 -> 0 with Quick Stop: coast
    assert wait_until(lambda: reading(bus, 'conveyor').state == 'ready', 3.0)
    slave.model.trip(2, slave.model.now_s)
    assert wait_until(lambda: reading(bus, 'conveyor').trip_name == 'Motor overload', 3.0)
    assert reading(bus, 'conveyor').trip_code == 2
    assert bus.submit_command('conveyor', 'reset').result(3)
    assert wait_until(lambda: reading(bus, 'conveyor').state == 'ready', 3.0)
    assert slave.model.state == READY


def test_basic_module_mcd201(gateway):
    bus, slave = gateway, gateway.slaves[1]
    assert wait_until(lambda: reading(bus, 'fan') is not None, 3.0)
    assert list(slave.writes) == []  # basic module: nothing written before a command
    assert bus.submit_command('fan', 'start').result(3)
    assert wait_until(lambda: reading(bus, 'fan').state == 'running', 3.0)
    assert reading(bus, 'fan').motor_current_a is None  # the MCD 201 reports no current
    assert bus.submit_command('fan', 'stop').result(3)
    assert wait_until(lambda: slave.model.state == READY, 3.0)


def test_network_failure_past_the_comms_timeout_trips_and_clear_mode(gateway):
    bus, slave = gateway, gateway.slaves[0]
    assert wait_until(lambda: reading(bus, 'conveyor') is not None, 3.0)
    assert bus.submit_command('conveyor', 'start').result(3)
    assert wait_until(lambda: slave.model.state == RUNNING, 3.0)
    slave.set_clear_mode(True, slave.model.now_s)  # Global Clear: quick stop
    assert wait_until(lambda: reading(bus, 'conveyor').state == 'ready', 3.0)
    slave.comms_timeout_s = 0.2
    slave.network_failed_at = slave.model.now_s
    assert wait_until(lambda: reading(bus, 'conveyor').state == 'tripped', 3.0)
    assert wait_until(lambda: reading(bus, 'conveyor').trip_code == 16, 3.0)
    assert slave.model.state == TRIPPED
