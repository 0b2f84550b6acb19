"""The node on a Danfoss FC-protocol line (VLT 5000 and FC 51, no option card), via rclpy."""

import signal

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.protocol.fc_profile import RAMP_STOP_WORD, START_WORD
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
from ros_helpers import running_node, serving

DEVICES = {
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
             'speed_reference': 40.0, 'comms_timeout': 4.0, 'comms_timeout_function': 2,
             'reference_timeout': 0.0},
    'fan': {'family': 'vlt', 'model': 'vlt5000', 'address': 2, 'poll_rate': 10.0},
}


def diagnostic_values(device, client):
    status = client.diagnostics(device)
    return {kv.key: kv.value for kv in status.values} if status is not None else {}


def test_start_reference_trip_reset_and_sigterm_on_the_fc_protocol(tmp_path):
    server = make_fc_protocol_server({1: 'fc51', 2: 'vlt5000'},
                                     {'ramp_up_s': 0.3, 'ramp_down_s': 0.3})
    with serving(server), running_node(
            tmp_path / 'fc_protocol.yaml',
            {'protocol': 'fc_protocol', 'port': server.pty_path, 'parity': 'N',
             'timeout': 0.3, 'diagnostics_period': 0.5}, DEVICES, drives=list(DEVICES),
            ready=list(DEVICES)) as client:
        drive = server.devices[1].model
        assert client.call('conv', 'start').success
        assert client.wait_state('conv', 'running')
        assert drive.control_word == START_WORD and drive.reference_word == 0x1999
        client.publish_reference('conv', -20.0)
        assert client.spin_until(lambda: client.values('conv', 'speed_feedback')[-1:] and
                                 abs(client.values('conv', 'speed_feedback')[-1] + 20.0) < 0.1)
        assert client.spin_until(lambda: (client.values('conv', 'motor_current') or [0])[-1]
                                 > 0.3)
        # The latest status may have been built before the start: wait for one built after.
        assert client.spin_until(lambda: diagnostic_values('conv', client).get(
            'control_image') == '0x047C')
        assert client.diagnostics('conv').level == DiagnosticStatus.OK
        assert diagnostic_values('conv', client)['link'].endswith('N1')
        fan = server.devices[2].model
        with server.lock:
            fan.trip(5, server.clock())
        assert client.wait_state('fan', 'tripped')
        assert client.call('fan', 'reset').success
        assert client.wait_state('fan', 'ready')
        client.process.send_signal(signal.SIGTERM)
        client.process.wait(timeout=15)
        assert client.process.returncode == 0
        assert drive.control_word == RAMP_STOP_WORD  # stopped by the node on its way out
