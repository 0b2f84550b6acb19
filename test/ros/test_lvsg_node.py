"""The node with an MCD 200 behind a simulated Profibus gateway (Modbus TCP), through rclpy."""

from drive_bridge.devices.mcd import STATE_CODES
from drive_bridge.sim.lvsg_gateway import make_lvsg_gateway
from drive_bridge.sim.mcd_model import READY, RUNNING
from ros_helpers import RosClient, start_node, stop_node, write_params


def gateway_and_node(tmp_path, **starter):
    """Serve an MCD 202 (extended module) behind a gateway; return (server, node, client)."""
    server = make_lvsg_gateway({0: ('mcd202', 100, 'extended')}, **starter)
    port = server.open_tcp()
    server.start()
    params = write_params(tmp_path / 'lvsg.yaml', {'protocol': 'modbus_tcp', 'tcp_port': port,
                                                   'timeout': 0.3},
                          {'mixer': {'family': 'lvsg', 'address': 1, 'poll_rate': 10.0,
                                     'gateway_input_register': 0,
                                     'gateway_output_register': 100}})
    return server, start_node(params), RosClient(['mixer'])


def test_lvsg_start_trip_reset_quick_stop(tmp_path):
    server, process, client = gateway_and_node(tmp_path, start_time_s=0.5, stop_time_s=0.5)
    slave = server.devices[1].slaves[0]
    try:
        assert client.wait_state('mixer', 'ready', 15.0)
        assert client.call('mixer', 'start').success
        assert client.wait_state('mixer', 'running')
        assert client.spin_until(lambda: client.values('mixer', 'motor_current')[-1:] and
                                 client.values('mixer', 'motor_current')[-1] > 70)
        with server.lock:
            slave.model.trip(3, server.clock())
        assert client.wait_state('mixer', 'tripped')
        assert client.spin_until(lambda: client.values('mixer', 'trip')[-1:] ==
                                 ['Motor thermistor'])
        assert client.call('mixer', 'reset').success
        assert client.wait_state('mixer', 'ready')
        assert slave.model.state == READY  # the reset did not restart the motor
        assert client.call('mixer', 'start').success
        assert client.wait_state('mixer', 'running')
        assert client.call('mixer', 'quick_stop').success
        assert client.wait_state('mixer', 'ready')
        assert client.spin_until(lambda: client.diagnostics('mixer') is not None)
        assert client.diagnostics('mixer').hardware_id == 'lvsg mcd202 address 1'
    finally:
        client.close()
        code, output = stop_node(process)
        server.stop()
    assert code == 0, output


def test_lvsg_extended_a_stop_is_stopping_never_starting(tmp_path):
    """
    Start, run, stop: ``state`` is exactly starting, running, stopping, ready (issue 26).

    The state byte (operating parameter 2) is read in turn once every other readout period
    (default 1 s): a 3 s start ramp is sure to read it as starting, and the stop follows
    the first running reading, before its turn comes again. The simulated starter's own
    states, sampled while the test waits, must be the same sequence.
    """
    server, process, client = gateway_and_node(tmp_path, start_time_s=3.0, stop_time_s=1.0)
    model = server.devices[1].slaves[0].model
    starter = []  # the simulated starter's states, as the test saw them change

    def sample(done) -> bool:
        with server.lock:
            state = STATE_CODES[model.state]
        if not starter or starter[-1] != state:
            starter.append(state)
        return done()
    try:
        assert client.wait_state('mixer', 'ready', 15.0)
        before = len(client.values('mixer', 'state'))
        starter.clear()
        assert client.call('mixer', 'start').success
        assert client.spin_until(lambda: sample(lambda: client.state('mixer') == 'running'))
        with server.lock:
            assert model.state == RUNNING  # running, as the bridge says
        assert client.call('mixer', 'stop').success
        assert client.spin_until(lambda: sample(lambda: client.state('mixer') == 'ready' and
                                                starter[-1] == 'ready'))
        states = client.values('mixer', 'state')[before:]
        while states[:1] == ['ready']:  # the state before the start, told again at activation
            states.pop(0)
        assert states in (['starting', 'running', 'stopping', 'ready'],
                          ['starting', 'running', 'stopping', 'restart_delay', 'ready'])
        assert starter == states, 'the simulated starter went through other states'
        with server.lock:
            assert model.state == READY and model.motor_current_a == 0.0  # stopped
    finally:
        client.close()
        code, output = stop_node(process)
        server.stop()
    assert code == 0, output
