"""
Record the node's topics with drive_bridge_record, read the bag back three ways, plot it.

The node runs one bus in the namespace /line1 with the devices of config/mixed_bus.yaml
(crusher: MCD 500, feeder: FC 51) against the simulators, so the layouts in docs/ are checked
against a bag recorded through the node.
"""

from dataclasses import dataclass
import json
import math
import os
from pathlib import Path
import re
import select
import signal
import subprocess
import sys
import time
from typing import Dict, List, Tuple
from xml.etree import ElementTree

from drive_bridge.bag_metadata import REFERENCE_AT_START
from drive_bridge.ros.record.recorder import BagRecorder
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.tools.plot_recording import main as plot_main, panels_of, read_recording
import fork_server
from missing_module import run_without
import pytest
from ros_helpers import running_node, serving
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability, QosReliability
from rosbags.rosbag2 import Reader
import yaml

# One worker runs this module's tests: its node, a module fixture, then starts once, not
# once on every worker that takes one of them.
pytestmark = pytest.mark.xdist_group('recording')

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NAMESPACE = '/line1'
CONFIGURED_PCT = 20.0  # the feeder's speed_reference parameter; the topic sends REFERENCE_PCT
DEVICES = {  # config/mixed_bus.yaml's devices, polled faster
    'crusher': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0},
    'feeder': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
               'speed_reference': CONFIGURED_PCT},
}
LATCHED_TOPICS = [f'{NAMESPACE}/{name}/{topic}' for name in DEVICES for topic in ('state', 'trip')]
STARTER_TOPICS = ('state', 'trip', 'status_word', 'motor_current', 'trip_code',
                  'motor_temperature')
DRIVE_TOPICS = STARTER_TOPICS + ('speed_feedback', 'alarm_word', 'warning_word',
                                 'speed_reference')
EXPECTED_TOPICS = {f'{NAMESPACE}/crusher/{topic}' for topic in STARTER_TOPICS} | \
    {f'{NAMESPACE}/feeder/{topic}' for topic in DRIVE_TOPICS} | \
    {'/diagnostics', f'{NAMESPACE}/drive_bridge/transition_event'}
REFERENCE_PCT = 60.0


@dataclass
class Recording:
    """A bag recorded through the node by the drive_bridge_record command."""

    path: str
    returncode: int
    stderr: str


def start_recorder(args: List[str]) -> subprocess.Popen:
    """Start drive_bridge_record with Ctrl-C restored (a background test has SIGINT ignored)."""
    return fork_server.ForkedPopen(
        [sys.executable, '-m', 'drive_bridge.ros.record.cli'] + args, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
        preexec_fn=fork_server.default_signals)


def wait_for_output(process: subprocess.Popen, prefix: str, timeout_s: float = 20.0) -> str:
    """Return the first stdout line of ``process`` that starts with ``prefix``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ready, _, _ = select.select([process.stdout], [], [], 0.2)
        if ready:
            line = process.stdout.readline()
            if line.startswith(prefix):
                return line
            assert line, f'recorder ended: {process.wait()} {process.stderr.read()}'
    raise AssertionError(f'no "{prefix}" from the recorder within {timeout_s} s')


def run_recorder(args: List[str], timeout_s: float = 30.0) -> Tuple[int, str]:
    """Run drive_bridge_record to its end; return (exit status, stderr)."""
    result = fork_server.run([sys.executable, '-m', 'drive_bridge.ros.record.cli'] + args,
                             capture_output=True, text=True, timeout=timeout_s,
                             stdin=subprocess.DEVNULL)
    return result.returncode, result.stderr


@pytest.fixture(scope='module')
def line(tmp_path_factory):
    simulator = make_sim_server({20: 'mcd500', 1: 'fc51'},
                                settings={'mcd': {'start_time_s': 1.0, 'stop_time_s': 0.5},
                                          'fc': {'ramp_up_s': 1.0, 'ramp_down_s': 1.0}})
    with serving(simulator) as server, running_node(
            tmp_path_factory.mktemp('params') / 'line1.yaml',
            {'port': server.pty_path, 'parity': 'N', 'timeout': 0.3,
             'diagnostics_period': 0.5}, DEVICES, drives=['feeder'],
            ready=list(DEVICES), namespace=NAMESPACE) as client:
        yield client


def _recorder_subscribed(client, topics) -> bool:
    return all(any(info.node_name == 'drive_bridge_record'
                   for info in client.node.get_subscriptions_info_by_topic(topic))
               for topic in topics)


@pytest.fixture(scope='module')
def recording(line, tmp_path_factory) -> Recording:
    """Record --all of /line1 through a soft start and stop and an FC 51 ramp; end by Ctrl-C."""
    path = str(tmp_path_factory.mktemp('bags') / 'run')
    recorder = start_recorder(['--all', '--namespace', NAMESPACE, '-o', path])
    try:
        wait_for_output(recorder, 'drive_bridge_record: recording')
        assert line.spin_until(lambda: _recorder_subscribed(line, EXPECTED_TOPICS), 10.0)
        diagnostics = len(line.messages['/diagnostics'])  # one period more for matching
        assert line.spin_until(lambda: len(line.messages['/diagnostics']) > diagnostics)
        assert line.call('crusher', 'start').success
        assert line.wait_state('crusher', 'running')
        assert line.call('crusher', 'stop').success and line.wait_state('crusher', 'ready')
        reference = line.reference_publishers['feeder']  # the node and the recorder
        assert line.spin_until(lambda: reference.get_subscription_count() >= 2)
        line.publish_reference('feeder', REFERENCE_PCT)
        assert line.call('feeder', 'start').success
        assert line.spin_until(lambda: line.values('feeder', 'speed_feedback')[-1:] == [
            pytest.approx(REFERENCE_PCT, abs=0.01)])
        assert line.call('feeder', 'stop').success and line.wait_state('feeder', 'ready')
        diagnostics = len(line.messages['/diagnostics'])
        assert line.spin_until(lambda: len(line.messages['/diagnostics']) >= diagnostics + 2)
        recorder.send_signal(signal.SIGINT)
        returncode = recorder.wait(timeout=20)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
    return Recording(path, returncode, recorder.stderr.read())


@pytest.fixture(scope='module')
def messages(recording) -> Dict[str, Tuple[str, list]]:
    """Return topic -> (type, decoded messages) read with rosbags' AnyReader."""
    found: Dict[str, Tuple[str, list]] = {}
    with AnyReader([Path(recording.path)]) as reader:
        for connection in reader.connections:
            found.setdefault(connection.topic, (connection.msgtype, []))
        for connection, _, raw in reader.messages():
            found[connection.topic][1].append(reader.deserialize(raw, connection.msgtype))
    return found


def _metadata(path: str) -> dict:
    with open(os.path.join(path, 'metadata.yaml')) as stream:
        return yaml.safe_load(stream)['rosbag2_bagfile_information']


def test_ctrl_c_closes_the_bag_and_exits_0(recording):
    assert recording.returncode == 0, recording.stderr
    last = recording.stderr.strip().splitlines()[-1]
    assert last.startswith(f'drive_bridge_record: wrote {recording.path}: ')
    total = _metadata(recording.path)['message_count']
    assert f': {total} messages on {len(EXPECTED_TOPICS)} topics in ' in last


def test_metadata_is_what_jazzy_writes(recording, line):
    metadata = _metadata(recording.path)
    assert metadata['version'] == 9 and metadata['storage_identifier'] == 'mcap'
    assert metadata['compression_mode'] == '' and metadata['compression_format'] == ''
    [relative] = metadata['relative_file_paths']
    assert relative.endswith('.mcap') and os.path.isfile(os.path.join(recording.path, relative))
    topics = {entry['topic_metadata']['name']: entry
              for entry in metadata['topics_with_message_count']}
    assert set(topics) == EXPECTED_TOPICS
    assert sum(entry['message_count'] for entry in topics.values()) == \
        metadata['message_count'] == metadata['files'][0]['message_count']
    for name, entry in topics.items():
        topic = entry['topic_metadata']
        assert topic['serialization_format'] == 'cdr'
        [publisher] = line.node.get_publishers_info_by_topic(name)  # speed_reference: ours
        assert topic['type'] == publisher.topic_type
        assert topic['type_description_hash'] == str(publisher.topic_type_hash)
        [offer] = topic['offered_qos_profiles']  # as the graph reports the offer
        latched = name in LATCHED_TOPICS
        assert offer['durability'] == ('transient_local' if latched else 'volatile'), name
        assert offer['reliability'] == 'reliable' and offer['liveliness'] == 'automatic'
        assert offer['deadline'] == {'sec': 9223372036, 'nsec': 854775807}  # infinite


def test_rosbags_reads_types_qos_and_counts(recording, messages):
    counts = {entry['topic_metadata']['name']: entry['message_count']
              for entry in _metadata(recording.path)['topics_with_message_count']}
    with Reader(recording.path) as reader:
        for connection in reader.connections:
            offers = connection.ext.offered_qos_profiles
            latched = connection.topic in LATCHED_TOPICS
            assert all(offer.durability == (QosDurability.TRANSIENT_LOCAL if latched
                                            else QosDurability.VOLATILE) for offer in offers)
            assert all(offer.reliability == QosReliability.RELIABLE for offer in offers)
            assert connection.msgcount == counts[connection.topic]
            assert connection.msgtype == messages[connection.topic][0]
    assert {topic: len(decoded) for topic, (_, decoded) in messages.items()} == counts

    def data(topic):
        return [message.data for message in messages[f'{NAMESPACE}/{topic}'][1]]
    assert messages[f'{NAMESPACE}/crusher/state'][0] == 'std_msgs/msg/String'
    assert _in_order(data('crusher/state'), ['ready', 'starting', 'running', 'stopping',
                                             'ready'])
    assert _in_order(data('feeder/state'), ['ready', 'running', 'ready'])
    assert data('crusher/trip') == [''] and data('feeder/trip') == ['']
    assert max(data('crusher/motor_current')) > 50.0
    assert data('feeder/speed_reference') == [REFERENCE_PCT]
    assert max(data('feeder/speed_feedback')) == pytest.approx(REFERENCE_PCT, abs=0.01)
    statuses = {status.name for array in messages['/diagnostics'][1] for status in array.status}
    assert {'/line1/drive_bridge: crusher', '/line1/drive_bridge: feeder'} <= statuses


def _in_order(values, wanted) -> bool:
    iterator = iter(values)
    return all(any(value == item for value in iterator) for item in wanted)


def test_mcap_reader_reads_the_storage_file(recording):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    metadata = _metadata(recording.path)
    with open(os.path.join(recording.path, metadata['relative_file_paths'][0]), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert {schema.encoding for schema in summary.schemas.values()} == {'ros2msg'}
        assert {channel.message_encoding for channel in summary.channels.values()} == {'cdr'}
        channels = {channel.topic: channel for channel in summary.channels.values()}
        assert set(channels) == EXPECTED_TOPICS
        for topic in LATCHED_TOPICS:
            [offer] = yaml.safe_load(channels[topic].metadata['offered_qos_profiles'])
            assert offer['durability'] == 'transient_local'
        assert [record.name for record in reader.iter_metadata()] == ['rosbag2']
        decoded = sum(1 for _ in reader.iter_decoded_messages())  # from the schemas in the file
    assert decoded == metadata['message_count']


def test_the_bag_keeps_the_reference_configured_at_the_start(recording):
    custom = _metadata(recording.path)['custom_data']
    assert json.loads(custom[REFERENCE_AT_START]) == {
        f'{NAMESPACE}/feeder/speed_reference': CONFIGURED_PCT}


def test_plot_of_the_recording(recording, tmp_path, capsys):
    bag = read_recording(recording.path)
    series = bag.series
    assert sorted(series) == ['line1/crusher', 'line1/feeder']
    assert panels_of(series['line1/crusher']) == ['state', 'motor_current', 'motor_temperature']
    assert panels_of(series['line1/feeder']) == ['state', 'motor_current', 'motor_temperature',
                                                 'speed']
    assert series['line1/feeder']['speed_reference'][0] == (0.0, CONFIGURED_PCT)
    assert [value for _, value in series['line1/feeder']['speed_reference']] == \
        [CONFIGURED_PCT, REFERENCE_PCT]
    png = tmp_path / 'run.png'
    assert plot_main([recording.path, str(png), '--title', 'line 1']) == 0
    assert capsys.readouterr().out == f'drive_bridge_plot: wrote {png} (line1/crusher, ' \
        f'line1/feeder; recorded {bag.started()})\n'
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 10_000


def test_duration_ends_the_recording(line, tmp_path):
    path = str(tmp_path / 'latched')
    returncode, stderr = run_recorder(['crusher/state', '/line1/feeder/trip', '--namespace',
                                       NAMESPACE, '--duration', '1', '-o', path])
    assert returncode == 0, stderr
    summary = re.fullmatch(r'drive_bridge_record: wrote .*: \d+ messages on 2 topics in '
                           r'([0-9.]+) s', stderr.strip().splitlines()[-1])
    assert summary and 1.0 <= float(summary.group(1)) < 3.0, stderr
    topics = {entry['topic_metadata']['name']: entry['topic_metadata']
              for entry in _metadata(path)['topics_with_message_count']}
    assert set(topics) == {'/line1/crusher/state', '/line1/feeder/trip'}
    for topic in topics.values():
        assert [offer['durability'] for offer in topic['offered_qos_profiles']] == \
            ['transient_local']


def test_a_named_topic_without_publisher_is_recorded_after_the_wait(line, tmp_path):
    from std_msgs.msg import Float32
    subscription = line.node.create_subscription(Float32, '/line1/only_listened', print, 10)
    try:
        path = str(tmp_path / 'unpublished')
        # The wait is spent in full (no publisher comes); it must also cover the recorder's
        # discovery of this subscription: beside a CPU hog that took more than 1 s.
        returncode, stderr = run_recorder(['/line1/only_listened', '--wait', '3',
                                           '--duration', '0.5', '-o', path])
    finally:
        line.node.destroy_subscription(subscription)
    assert returncode == 0, stderr
    assert stderr.startswith('drive_bridge_record: /line1/only_listened has no publisher yet: '
                             'recording it as volatile\n')
    [entry] = _metadata(path)['topics_with_message_count']
    assert entry['message_count'] == 0
    assert entry['topic_metadata']['offered_qos_profiles'] == []


def test_recorder_class_in_process(line, tmp_path):
    recorder = BagRecorder(line.node, str(tmp_path / 'in_process'))
    recorder.add_topic('/line1/crusher/state', 'std_msgs/msg/String')
    recorder.add_topic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray')
    assert line.spin_until(lambda: recorder.counts['/diagnostics'] >= 2
                           and recorder.counts['/line1/crusher/state'] >= 1)  # latched
    recorder.close()
    metadata = _metadata(str(tmp_path / 'in_process'))
    counts = {entry['topic_metadata']['name']: entry['message_count']
              for entry in metadata['topics_with_message_count']}
    assert counts == recorder.counts and counts['/line1/crusher/state'] == 1


def test_a_reference_without_its_bridge_is_recorded_without_start_value(line, tmp_path):
    from std_msgs.msg import Float32
    publisher = line.node.create_publisher(Float32, '/line9/feeder/speed_reference', 10)
    try:
        path = str(tmp_path / 'no_bridge')
        returncode, stderr = run_recorder(['/line9/feeder/speed_reference', '--wait', '2',
                                           '--duration', '0.5', '-o', path])
    finally:
        line.node.destroy_publisher(publisher)
    assert returncode == 0, stderr
    assert 'drive_bridge_record: no answer from /line9/drive_bridge about '\
        'feeder.speed_reference: the bag has no reference at the start\n' in stderr
    assert not _metadata(path).get('custom_data')


def test_without_rosbags_it_is_one_line_and_exit_2(tmp_path):
    output = tmp_path / 'never'
    result = run_without(['rosbags'], 'drive_bridge_record', ['--all', '-o', str(output)])
    assert (result.returncode, result.stderr, result.stdout) == (
        2, "drive_bridge_record needs rosbags: pip install 'drive_bridge[recording]' "
        '(apt/rosdep: python3-rosbags-pip)\n', '')
    assert not output.exists()


@pytest.mark.parametrize('args, reason', [
    ([], 'name the topics to record, or --all (not both)'),
    (['--all', '/a'], 'name the topics to record, or --all (not both)'),
    (['bad topic'], "'bad topic' is not a topic name: "),
    (['/a', '--duration', '0'], '--duration must be a positive number of seconds, not 0.0'),
    (['/a', '--duration', 'nan'], '--duration must be a positive number of seconds, not nan'),
    (['/line1/nothing', '--wait', '0.5'], 'no topic /line1/nothing within 0.5 s (is the'),
    (['--all', '--namespace', '/line9', '--wait', '0.5'], 'no node /line9/drive_bridge within'),
])
def test_bad_input_is_one_line_and_exit_2(line, tmp_path, args, reason):
    output = tmp_path / 'never'
    returncode, stderr = run_recorder(args + ['-o', str(output)])
    assert returncode == 2
    assert len(stderr.strip().splitlines()) == 1, stderr
    assert stderr.startswith(f'drive_bridge_record: {reason}'), stderr
    assert not output.exists()


def test_an_existing_output_is_refused(tmp_path):
    returncode, stderr = run_recorder(['--all', '-o', str(tmp_path)])
    assert (returncode, stderr) == (2, f'drive_bridge_record: {tmp_path} exists: choose a new '
                                       'output directory\n')


# -- the layouts in docs/ ---------------------------------------------------------------------
def foxglove_fields(path: str) -> List[Tuple[str, str]]:
    """Return (topic, field path) of every message path and diagnostics topic in the layout."""
    with open(path) as stream:
        layout = json.load(stream)
    panels = layout['configById']
    assert _mosaic_leaves(layout['layout']) == set(panels)
    fields = []
    for config in panels.values():
        for entry in config.get('paths', []):
            topic, _, field = entry['value'].partition('.')
            fields.append((topic, field))
        if 'topicToRender' in config:
            fields.append((config['topicToRender'], ''))
    return fields


def _mosaic_leaves(node) -> set:
    if isinstance(node, str):
        return {node}
    return _mosaic_leaves(node['first']) | _mosaic_leaves(node['second'])


def plotjuggler_curves(path: str) -> List[str]:
    """Return the curve names of a PlotJuggler layout (checked as PlotJuggler loads it)."""
    root = ElementTree.parse(path).getroot()
    assert root.tag == 'root'
    [tabbed] = root.findall('tabbed_widget')
    assert tabbed.get('parent') == 'main_window'
    for splitter in root.iter('DockSplitter'):
        children = [child for child in splitter if child.tag in ('DockSplitter', 'DockArea')]
        assert int(splitter.get('count')) == len(children) == \
            len(splitter.get('sizes').split(';'))
    return [curve.get('name') for curve in root.iter('curve')]


def _field(message, path: List[str]):
    for name in path:
        message = getattr(message, name)
    return message


def test_foxglove_layout_names_recorded_topics_and_fields(messages):
    fields = foxglove_fields(os.path.join(ROOT, 'docs', 'foxglove_layout.json'))
    assert {topic for topic, _ in fields} >= {f'{NAMESPACE}/feeder/speed_reference',
                                              '/diagnostics'}
    for topic, field in fields:
        assert messages.get(topic, ('', []))[1], f'{topic}: not in the bag or no messages'
        type_name, decoded = messages[topic]
        if not field:
            assert type_name == 'diagnostic_msgs/msg/DiagnosticArray', topic
            continue
        value = _field(decoded[-1], field.split('.'))
        assert isinstance(value, (str, float, int)), f'{topic}.{field}'
    with open(os.path.join(ROOT, 'docs', 'foxglove_layout.json')) as stream:
        panels = json.load(stream)['configById']
    statuses = {(status.hardware_id, status.name)
                for array in messages['/diagnostics'][1] for status in array.status}
    for config in panels.values():
        if 'selectedHardwareId' in config:
            assert (config['selectedHardwareId'], config['selectedName']) in statuses


def test_plotjuggler_layout_names_recorded_series(messages):
    curves = plotjuggler_curves(os.path.join(ROOT, 'docs', 'plotjuggler_layout.xml'))
    assert len(curves) >= 12
    for curve in curves:
        topic = max((topic for topic in messages if curve.startswith(topic + '/')),
                    key=len, default=None)
        assert topic and messages[topic][1], f'{curve}: no topic of it in the bag'
        type_name, decoded = messages[topic]
        rest = curve[len(topic) + 1:]
        if type_name == 'diagnostic_msgs/msg/DiagnosticArray':  # PlotJuggler's own naming
            hardware_id, _, status_and_key = rest.partition('/')  # names may hold slashes
            name, _, key = status_and_key.rpartition('/')
            values = [float(status.level) if key == 'level' else
                      float({v.key: v.value for v in status.values}[key])
                      for array in decoded for status in array.status
                      if (status.hardware_id, status.name) == (hardware_id, name)]
            assert values and all(math.isfinite(value) for value in values), curve
        else:
            value = _field(decoded[-1], rest.split('/'))
            assert isinstance(value, (float, int)) and not isinstance(value, bool), curve
