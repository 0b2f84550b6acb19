"""The node on an AP ASCII line (MCD 500 via the module, MCD 3000), driven through rclpy."""

from drive_bridge.sim.ap_ascii_server import make_ap_ascii_server
from ros_helpers import RosClient, start_node, stop_node, write_params


def test_ap_ascii_start_stop_refusal_and_trip(tmp_path):
    line = make_ap_ascii_server({20: 'mcd500', 21: 'mcd3000'}, start_time_s=0.5,
                                stop_time_s=0.5)
    line.open_pty()
    line.start()
    params = write_params(tmp_path / 'ap.yaml', {'protocol': 'ap_ascii', 'port': line.pty_path,
                                                 'parity': 'N', 'timeout': 0.3},
                          {'crusher': {'family': 'mcd', 'model': 'mcd500', 'address': 20,
                                       'poll_rate': 5.0},
                           'press': {'family': 'mcd', 'model': 'mcd3000', 'address': 21,
                                     'poll_rate': 5.0}})
    process = start_node(params)
    client = RosClient(['crusher', 'press'])
    try:
        assert client.wait_state('crusher', 'ready', 15.0)
        line.inject(20, 'nak')  # a bad LRC on the line: retried from the address
        response = client.call('crusher', 'start')
        assert response.success, response.message
        assert client.wait_state('crusher', 'running')
        assert client.spin_until(lambda: client.values('crusher', 'motor_current')[-1:] and
                                 client.values('crusher', 'motor_current')[-1] > 70)
        line.devices[20].hand_on = True
        refused = client.call('crusher', 'stop')
        assert not refused.success and 'refused by the starter (BEL)' in refused.message
        line.devices[20].hand_on = False
        assert client.call('crusher', 'stop').success
        assert client.wait_state('crusher', 'ready')
        with line.lock:
            line.devices[21].trip(0, line.clock())
        assert client.wait_state('press', 'tripped')
        assert client.spin_until(lambda: client.values('press', 'trip')[-1:] == ['Shorted SCR'])
        assert client.spin_until(lambda: client.values('press', 'trip_code')[-1:] == [256])
        assert client.call('press', 'reset').success
        assert client.wait_state('press', 'ready')
        assert list(line.devices[20].commands_received) == [1, 2]
    finally:
        client.close()
        code, output = stop_node(process)
        line.stop()
    assert code == 0, output
