"""Record the node's topics to MCAP as `ros2 bag record` does, read them back, plot them."""

from diagnostic_msgs.msg import DiagnosticArray
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.tools.plot_recording import decoded_messages, main as plot_main, read_recording
import pytest
from ros_helpers import LATCHED, running_node, serving
from std_msgs.msg import Float32, String

# pip's mcap and mcap-ros2-support have no rosdep keys: an apt workspace may lack them.
make_reader = pytest.importorskip('mcap.reader', reason='pip install mcap').make_reader
pytest.importorskip('mcap_ros2', reason='pip install mcap-ros2-support')
McapRecorder = pytest.importorskip('drive_bridge.ros.recorder').McapRecorder

DEVICES = {
    'main': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0},
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
             'speed_reference': 60.0},
}
TOPICS = {'/main/state': String, '/main/motor_current': Float32, '/conv/state': String,
          '/conv/speed_feedback': Float32, '/diagnostics': DiagnosticArray}


@pytest.fixture(scope='module')
def node(tmp_path_factory):
    simulator = make_sim_server({20: 'mcd500', 1: 'fc51'},
                                settings={'mcd': {'start_time_s': 1.0, 'stop_time_s': 0.5},
                                          'fc': {'ramp_up_s': 1.0, 'ramp_down_s': 1.0}})
    with serving(simulator) as server, running_node(
            tmp_path_factory.mktemp('params') / 'record.yaml',
            {'port': server.pty_path, 'parity': 'N', 'timeout': 0.1,
             'diagnostics_period': 0.5}, DEVICES, drives=['conv'],
            ready=['main']) as client:
        yield client


def test_record_read_back_and_plot(node, tmp_path):
    path = str(tmp_path / 'run.mcap')
    recorder = McapRecorder(node.node, path, TOPICS,
                            qos={'/main/state': LATCHED, '/conv/state': LATCHED})
    assert node.spin_until(lambda: recorder.counts['/main/state'] >= 1)
    assert node.call('main', 'start').success and node.wait_state('main', 'running')
    assert node.call('main', 'stop').success and node.wait_state('main', 'ready')
    assert node.call('conv', 'start').success
    assert node.spin_until(lambda: node.values('conv', 'speed_feedback')[-1:] == [
        pytest.approx(60.0, abs=0.01)])
    assert node.call('conv', 'stop').success and node.wait_state('conv', 'ready')
    assert node.spin_until(lambda: recorder.counts['/diagnostics'] >= 2)
    recorder.close()

    with open(path, 'rb') as stream:  # the layout rosbag2 writes in Jazzy
        reader = make_reader(stream)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert {schema.encoding for schema in summary.schemas.values()} == {'ros2msg'}
        assert {channel.message_encoding for channel in summary.channels.values()} == {'cdr'}
        names = {schema.name for schema in summary.schemas.values()}
        assert names == {'std_msgs/msg/String', 'std_msgs/msg/Float32',
                         'diagnostic_msgs/msg/DiagnosticArray'}

    by_topic = {}
    for _, channel, _, decoded in decoded_messages(path):  # from the schema text in the file
        by_topic.setdefault(channel.topic, []).append(decoded)
    states = [message.data for message in by_topic['/main/state']]
    assert _contains_in_order(states, ['ready', 'starting', 'running', 'stopping', 'ready'])
    assert max(message.data for message in by_topic['/main/motor_current']) > 50.0
    assert max(message.data for message in by_topic['/conv/speed_feedback']) == \
        pytest.approx(60.0, abs=0.01)
    statuses = {status.name for array in by_topic['/diagnostics'] for status in array.status}
    assert {'drive_bridge: main', 'drive_bridge: conv'} <= statuses

    series = read_recording(path)
    assert set(series) == {'main', 'conv'}
    png = tmp_path / 'run.png'
    assert plot_main([path, str(png), '--title', 'test']) == 0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 10_000


def _contains_in_order(values, wanted):
    iterator = iter(values)
    return all(any(value == item for value in iterator) for item in wanted)


def test_plot_refuses_a_file_that_is_not_a_recording(tmp_path, capsys):
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'not an mcap file')
    assert plot_main([str(bad), str(tmp_path / 'out.png')]) == 2
    assert capsys.readouterr().err.startswith(f'drive_bridge_plot: {bad}: ')
