"""drive_bridge_plot on bags written here with rosbags: states, panels, device selection."""

import importlib.util
import itertools
import os
import time
from typing import Dict, List, Optional, Tuple

from drive_bridge.bag_metadata import REFERENCE_AT_START
from drive_bridge.tools.plot_recording import main, plot, read_recording, STATES
from missing_module import run_without
import pytest

rosbag2 = pytest.importorskip('rosbags.rosbag2', reason='pip install rosbags')
typesys = pytest.importorskip('rosbags.typesys', reason='pip install rosbags')
pytest.importorskip('matplotlib', reason='pip install matplotlib')

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TYPES = {'state': 'std_msgs/msg/String', 'motor_current': 'std_msgs/msg/Float32',
         'motor_temperature': 'std_msgs/msg/Float32', 'speed_reference': 'std_msgs/msg/Float32',
         'speed_feedback': 'std_msgs/msg/Float32'}


START_NS = 10**18  # 2001-09-09 01:46:40 UTC


def write_bag(path, topics: Dict[str, List[Tuple[float, object]]],
              custom: Optional[Dict[str, str]] = None) -> str:
    """Write a bag with ``topic -> [(seconds, data)]``; the type follows the topic's last part."""
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    with rosbag2.Writer(path, version=9, storage_plugin=rosbag2.StoragePlugin.MCAP) as writer:
        for key, value in (custom or {}).items():
            writer.set_custom_data(key, value)
        for topic, samples in topics.items():
            type_name = TYPES[topic.rpartition('/')[2]]
            connection = writer.add_connection(topic, type_name, typestore=store)
            message_class = store.types[type_name]
            for seconds, data in samples:
                raw = store.serialize_cdr(message_class(data=data), type_name)
                writer.write(connection, START_NS + int(seconds * 1e9), raw)
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
    assert crusher == ['state', 'motor current\n[A]', 'motor temperature\n[%]']
    feeder = [axis.get_ylabel() for axis in axes['line1/feeder']]
    assert feeder == ['state', 'motor current\n[A]', 'speed\n[%]']
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


DRIVE = {'/line1/feeder/state': ramp(['ready', 'starting', 'running']),
         '/line1/feeder/motor_current': ramp([0.0, 1.2, 1.5]),
         '/line1/feeder/motor_temperature': ramp([0.0, 2.0, 3.0]),
         '/line1/feeder/speed_reference': [(1.0, 80.0)],
         '/line1/feeder/speed_feedback': ramp([0.0, 40.0, 80.0])}
STARTER = {'/line1/crusher/state': ramp(['ready', 'starting', 'running']),
           '/line1/crusher/motor_current': ramp([0.0, 300.0, 80.0]),
           '/line1/crusher/motor_temperature': ramp([10.0, 12.0, 13.0])}
PNG = b'\x89PNG\r\n\x1a\n'


@pytest.fixture
def central_european_time(monkeypatch):
    """Local time is CET/CEST (a POSIX rule: no time zone database needed)."""
    monkeypatch.setenv('TZ', 'CET-1CEST,M3.5.0,M10.5.0/3')
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()


def drawn(figure):
    """Draw a figure that plot() returned again, as savefig drew it; return the renderer."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    return canvas.get_renderer()


@pytest.mark.parametrize('devices', [['feeder'], ['crusher'], None])
def test_labels_and_titles_do_not_overlap(tmp_path, devices):
    bag = write_bag(tmp_path / 'line', {**DRIVE, **STARTER})
    figure = plot(read_recording(bag), str(tmp_path / 'line.png'), devices, 'line 1')
    renderer = drawn(figure)
    assert len(figure.subfigs) == (1 if devices else 2)
    for column in figure.subfigs:
        labels = [axis.yaxis.label for axis in column.axes]
        assert len(labels) >= 3 and all(label.get_text() for label in labels)
        boxes = [label.get_window_extent(renderer) for label in labels]
        for (one, box), (other, other_box) in itertools.combinations(zip(labels, boxes), 2):
            assert not box.overlaps(other_box), \
                f'{one.get_text()!r} overlaps {other.get_text()!r}'
    titles = figure.texts + [text for column in figure.subfigs for text in column.texts]
    boxes = [text.get_window_extent(renderer) for text in titles]
    for box, other_box in itertools.combinations(boxes, 2):
        assert not box.overlaps(other_box)


def test_the_title_says_when_the_recording_began(tmp_path, central_european_time):
    bag = write_bag(tmp_path / 'run', DRIVE)  # first message at START_NS
    recording = read_recording(bag)
    figure = plot(recording, str(tmp_path / 'titled.png'), title='line 1')
    assert figure.get_suptitle() == 'line 1\nrecorded 2001-09-09 03:46:40+02:00'
    figure = plot(recording, str(tmp_path / 'untitled.png'))
    assert figure.get_suptitle() == 'recorded 2001-09-09 03:46:40+02:00'


def test_the_reference_starts_with_the_one_configured_at_the_start(tmp_path):
    configured = {REFERENCE_AT_START: '{"/line1/feeder/speed_reference": 25.0}'}
    bag = write_bag(tmp_path / 'run', DRIVE, configured)
    figure = plot(read_recording(bag), str(tmp_path / 'run.png'))
    reference = columns(figure)['line1/feeder'][3].lines[0]
    assert reference.get_label() == 'reference'
    assert list(reference.get_xdata()) == [0.0, 1.0, 2.0]  # from the start to the end
    assert list(reference.get_ydata()) == [25.0, 80.0, 80.0]


def test_a_configured_reference_alone_draws_the_speed_panel(tmp_path):
    configured = {REFERENCE_AT_START: '{"/line1/feeder/speed_reference": 0.0}'}
    bag = write_bag(tmp_path / 'run', {'/line1/feeder/state': ramp(['ready', 'ready'])},
                    configured)
    figure = plot(read_recording(bag), str(tmp_path / 'run.png'))
    [_, speed] = columns(figure)['line1/feeder']
    assert list(speed.lines[0].get_ydata()) == [0.0, 0.0]


@pytest.mark.parametrize('value', [
    'not json', '[1, 2]', '{"/line1/feeder/speed_reference": "25"}',
    '{"/line1/feeder/speed_reference": NaN}', '{"/line1/feeder/speed_reference": true}',
    '{"/line1/feeder/state": 25.0}'])
def test_a_malformed_reference_at_the_start_is_left_out(tmp_path, value):
    bag = write_bag(tmp_path / 'run', DRIVE, {REFERENCE_AT_START: value})
    assert read_recording(bag).series['line1/feeder']['speed_reference'] == [(1.0, 80.0)]


def test_success_is_one_line_naming_the_file(tmp_path, capsys, central_european_time):
    bag = write_bag(tmp_path / 'run', {**DRIVE, **STARTER})
    output = tmp_path / 'run.png'
    assert main([bag, str(output)]) == 0
    assert capsys.readouterr() == (
        f'drive_bridge_plot: wrote {output} (line1/crusher, line1/feeder; recorded '
        '2001-09-09 03:46:40+02:00)\n', '')
    assert output.read_bytes()[:8] == PNG


@pytest.mark.parametrize('make_output, reason', [
    (lambda tmp: tmp / 'missing' / 'out.png', 'no directory {tmp}/missing'),
    (lambda tmp: tmp / 'file.txt' / 'out.png', '{tmp}/file.txt is not a directory'),
    (lambda tmp: tmp, 'it is a directory'),
    (lambda tmp: tmp / 'out.txt', 'unknown image type .txt (use .png, .svg or .pdf)'),
])
def test_a_bad_output_path_is_one_line_naming_it(tmp_path, capsys, make_output, reason):
    bag = write_bag(tmp_path / 'run', DRIVE)
    (tmp_path / 'file.txt').write_text('')
    output = str(make_output(tmp_path))
    assert main([bag, output]) == 2
    assert capsys.readouterr().err == \
        f'drive_bridge_plot: cannot write {output}: {reason.format(tmp=tmp_path)}\n'
    assert not (tmp_path / 'out.txt').exists()


def test_an_unwritable_output_is_one_line_naming_it(tmp_path, capsys):
    # sysfs refuses a new file even to root, whom the permission check lets through
    bag = write_bag(tmp_path / 'run', DRIVE)
    output = '/sys/drive_bridge_plot.png'
    assert main([bag, output]) == 2
    error = capsys.readouterr().err
    assert error.startswith(f'drive_bridge_plot: cannot write {output}: ')
    assert error.count('\n') == 1 and bag not in error and 'Traceback' not in error


@pytest.mark.parametrize('module, key', [('rosbags', 'python3-rosbags-pip'),
                                         ('matplotlib', 'python3-matplotlib')])
def test_a_missing_optional_module_is_one_line_and_exit_2(tmp_path, module, key):
    bag = write_bag(tmp_path / 'run', DRIVE)
    output = tmp_path / 'out.png'
    result = run_without([module], 'drive_bridge_plot', [bag, str(output)])
    assert (result.returncode, result.stderr, result.stdout) == (
        2, f"drive_bridge_plot needs {module}: pip install 'drive_bridge[recording]' "
        f'(apt/rosdep: {key})\n', '')
    assert not output.exists()


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
