"""drive_bridge_plot on bags written here with rosbags: states, panels, device selection."""

import importlib.util
import os
from typing import Dict, List, Tuple

from drive_bridge.tools.plot_recording import main, plot, read_recording, STATES
import pytest

rosbag2 = pytest.importorskip('rosbags.rosbag2', reason='pip install rosbags')
typesys = pytest.importorskip('rosbags.typesys', reason='pip install rosbags')
pytest.importorskip('matplotlib', reason='pip install matplotlib')

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TYPES = {'state': 'std_msgs/msg/String', 'motor_current': 'std_msgs/msg/Float32',
         'motor_temperature': 'std_msgs/msg/Float32', 'speed_reference': 'std_msgs/msg/Float32',
         'speed_feedback': 'std_msgs/msg/Float32'}


def write_bag(path, topics: Dict[str, List[Tuple[float, object]]]) -> str:
    """Write a bag with ``topic -> [(seconds, data)]``; the type follows the topic's last part."""
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    with rosbag2.Writer(path, version=9, storage_plugin=rosbag2.StoragePlugin.MCAP) as writer:
        for topic, samples in topics.items():
            type_name = TYPES[topic.rpartition('/')[2]]
            connection = writer.add_connection(topic, type_name, typestore=store)
            message_class = store.types[type_name]
            for seconds, data in samples:
                raw = store.serialize_cdr(message_class(data=data), type_name)
                writer.write(connection, int(1e18 + seconds * 1e9), raw)
    return str(path)


def ramp(values) -> List[Tuple[float, object]]:
    return [(float(index), value) for index, value in enumerate(values)]


def columns(figure) -> Dict[str, list]:
    """Return device -> the axes of its column, from the figure that plot() drew."""
    return {subfigure.get_suptitle(): subfigure.axes for subfigure in figure.subfigs}


def test_every_state_of_the_contract_is_drawn_as_itself(tmp_path):
    bag = write_bag(tmp_path / 'states', {'/line1/crusher/state': ramp(STATES)})
    figure = plot(read_recording(bag), str(tmp_path / 'states.png'))
    [state_axis] = columns(figure)['line1/crusher']
    assert [label.get_text() for label in state_axis.get_yticklabels()] == list(STATES)
    levels = list(state_axis.lines[0].get_ydata())
    assert levels == list(range(len(STATES))) + [len(STATES) - 1]  # held to the end
    assert {'restart_delay', 'program_mode', 'jog_forward', 'jog_reverse'} <= set(STATES)


def test_a_state_outside_the_contract_is_drawn_as_unknown(tmp_path):
    bag = write_bag(tmp_path / 'odd', {'/m/state': ramp(['ready', 'weird', 'running'])})
    figure = plot(read_recording(bag), str(tmp_path / 'odd.png'))
    levels = list(columns(figure)['m'][0].lines[0].get_ydata())
    assert levels[:3] == [STATES.index('ready'), STATES.index('unknown'),
                          STATES.index('running')]


def test_panels_follow_the_topics_in_the_bag(tmp_path):
    bag = write_bag(tmp_path / 'line', {
        '/line1/crusher/state': ramp(['ready', 'starting', 'running']),
        '/line1/crusher/motor_current': ramp([0.0, 300.0, 80.0]),
        '/line1/crusher/motor_temperature': ramp([10.0, 12.0, 13.0]),
        '/line1/feeder/state': ramp(['ready', 'running']),
        '/line1/feeder/motor_current': ramp([0.0, 1.2]),
        '/line1/feeder/speed_reference': [(0.5, 60.0)],
        '/line1/feeder/speed_feedback': ramp([0.0, 30.0, 60.0]),
        '/line1/pump/state': ramp(['offline'])})
    figure = plot(read_recording(bag), str(tmp_path / 'line.png'))
    axes = columns(figure)
    crusher = [axis.get_ylabel() for axis in axes['line1/crusher']]
    assert crusher == ['state', 'motor current [A]', 'motor temperature [%]']
    feeder = [axis.get_ylabel() for axis in axes['line1/feeder']]
    assert feeder == ['state', 'motor current [A]', 'speed [%]']
    speed = axes['line1/feeder'][2]
    assert [line.get_label() for line in speed.lines] == ['reference', 'feedback']
    assert list(speed.lines[0].get_ydata()) == [60.0, 60.0]  # held to the end of the bag
    assert [axis.get_ylabel() for axis in axes['line1/pump']] == ['state']
    for column in axes.values():  # no empty placeholder panels: the panels fill the column
        assert not any(axis.texts for axis in column)
        top = max(axis.get_position().y1 for axis in column)
        bottom = min(axis.get_position().y0 for axis in column)
        assert top - bottom > 0.75


def test_device_by_name_or_last_part(tmp_path, capsys):
    bag = write_bag(tmp_path / 'two', {'/line1/crusher/state': ramp(['ready']),
                                       '/line2/crusher/state': ramp(['ready']),
                                       '/line1/feeder/state': ramp(['ready'])})
    assert main([bag, str(tmp_path / 'a.png'), '--device', 'feeder']) == 0
    assert main([bag, str(tmp_path / 'b.png'), '--device', 'line2/crusher']) == 0
    assert main([bag, str(tmp_path / 'c.png'), '--device', 'crusher']) == 2
    assert capsys.readouterr().err == (
        f"drive_bridge_plot: {bag}: more than one device named 'crusher': devices are "
        'line1/crusher, line1/feeder, line2/crusher\n')


def test_an_unknown_device_is_one_line_listing_the_devices(tmp_path, capsys):
    bag = write_bag(tmp_path / 'run', {'/a/state': ramp(['ready']),
                                       '/b/state': ramp(['running'])})
    assert main([bag, str(tmp_path / 'out.png'), '--device', 'c']) == 2
    assert capsys.readouterr().err == \
        f"drive_bridge_plot: {bag}: no device 'c': devices are a, b\n"
    assert not (tmp_path / 'out.png').exists()


@pytest.mark.parametrize('make, reason', [
    (lambda tmp: tmp / 'missing', 'no such file or directory'),
    (lambda tmp: tmp, 'not a rosbag2 bag: no metadata.yaml in '),
])
def test_a_path_that_is_not_a_bag_is_one_line(tmp_path, capsys, make, reason):
    path = str(make(tmp_path))
    assert main([path, str(tmp_path / 'out.png')]) == 2
    assert capsys.readouterr().err.startswith(f'drive_bridge_plot: {path}: {reason}')


def test_a_file_inside_the_bag_names_the_bag(tmp_path):
    bag = write_bag(tmp_path / 'run', {'/a/state': ramp(['ready'])})
    assert main([os.path.join(bag, 'metadata.yaml'), str(tmp_path / 'out.png')]) == 0


def _record_plots():
    spec = importlib.util.spec_from_file_location(
        'record_plots', os.path.join(ROOT, 'demo', 'record_plots.py'))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_record_plots_leaves_docs_alone_unless_asked(tmp_path):
    record_plots = _record_plots()
    docs = os.path.join(ROOT, 'docs')
    default = record_plots.parse_args([])
    assert not default.plot_dir.startswith(docs) and not default.bag.startswith(docs)
    chosen = record_plots.parse_args(['--output', str(tmp_path)])
    assert chosen.plot_dir == str(tmp_path) and chosen.bag.startswith(str(tmp_path))
    update = record_plots.parse_args(['--update-docs'])
    assert update.plot_dir == docs and not update.bag.startswith(docs)
