"""The node with a VLT 6000 (Modbus RTU option card) on a simulated bus, through rclpy."""

from drive_bridge.sim.devices import make_sim_server
from ros_helpers import RosClient, start_node, stop_node, write_params


def test_vlt6000_start_speed_trip_reset_coast(tmp_path):
    ramps = {'ramp_up_s': 0.5, 'ramp_down_s': 0.5}
    server = make_sim_server({1: 'vlt6000'}, settings={'vlt': ramps})
    server.open_pty()
    server.start()
    params = write_params(tmp_path / 'vlt.yaml', {'port': server.pty_path, 'parity': 'N',
                                                  'timeout': 0.2},
                          {'fan': {'family': 'vlt', 'model': 'vlt6000', 'address': 1,
                                   'poll_rate': 20.0, 'speed_reference': 40.0,
                                   'comms_timeout': 5.6}})
    process = start_node(params, namespace='/hvac')
    client = RosClient(['fan'], namespace='/hvac', drives=['fan'])
    drive = server.devices[1].model
    try:
        assert client.wait_state('fan', 'ready', 15.0)
        # register 2 = 5.6 s in 10 ms units, written by the set-up writes after the first poll
        assert client.spin_until(lambda: drive.card_timeouts[0] == 560)
        assert client.call('fan', 'start').success
        assert client.wait_state('fan', 'running')
        assert drive.reference_word == 0x1999
        assert client.spin_until(
            lambda: abs(client.values('fan', 'speed_feedback')[-1] - 40.0) < 0.01)
        assert client.spin_until(lambda: client.values('fan', 'motor_current')[-1] > 0.5)
        with server.lock:
            drive.trip(5, server.clock())
        assert client.wait_state('fan', 'tripped')
        assert client.spin_until(lambda: client.values('fan', 'alarm_word')[-1:] == [32])
        assert client.spin_until(lambda: client.values('fan', 'trip')[-1:] ==
                                 ['alarm word bit 5'])
        assert client.call('fan', 'reset').success
        assert client.wait_state('fan', 'ready')
        assert client.call('fan', 'start').success
        assert client.wait_state('fan', 'running')
        assert client.call('fan', 'coast_stop').success
        assert drive.control_word == 0x0434 and drive.output_pct == 0.0
        assert client.wait_state('fan', 'ready')
        assert client.spin_until(lambda: client.diagnostics('fan') is not None)
        assert client.diagnostics('fan').hardware_id == 'vlt vlt6000 address 1'
    finally:
        client.close()
        code, output = stop_node(process)
        server.stop()
    assert code == 0, output
