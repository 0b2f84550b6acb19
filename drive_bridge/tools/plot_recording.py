"""
Plot a recording (a rosbag2 bag from ``ros2 bag record`` or ``drive_bridge_record``) as a PNG.

One column per device (a ``<device>/state`` topic) and one panel per quantity the bag has
for it: the state (each of the contract's twelve states on its own row), motor current [A],
motor temperature [% of thermal capacity], and speed reference against speed feedback [%].
A starter has no speed topics, so its panels share the whole column. The title says when
the recording began (time 0, the bag's first message, in local time). The reference line
starts at time 0 with the reference configured when the recording began, where the bag
holds it (``drive_bridge_record`` stores the bridge's ``<device>.speed_reference`` parameter
in the bag's metadata). Reads the bag with ``rosbags`` and draws with ``matplotlib``; no ROS
installation needed.
Run: ``drive_bridge_plot BAG plot.png [--device NAME] [--title TEXT]`` (BAG: the bag
directory, or a file in it). Exit status: 0 written (one line names the file), 2 bad input:
a bad bag, device name or output path, or a missing ``rosbags`` or ``matplotlib`` (one line
on stderr).
"""

import argparse
from collections import defaultdict
from dataclasses import dataclass
import datetime
import os
import sys
from typing import Dict, List, Optional, Tuple

from drive_bridge.bag_metadata import decode_references
from drive_bridge.console import OneLineParser, plain_text
from drive_bridge.extras import MissingDependency, require

PROG = 'drive_bridge_plot'
# The contract's states, bottom row to top row: not running, standing by, moving.
STATES = ('offline', 'unknown', 'not_ready', 'tripped', 'program_mode', 'restart_delay',
          'ready', 'jog_reverse', 'jog_forward', 'stopping', 'starting', 'running')
FIELDS = ('state', 'motor_current', 'motor_temperature', 'speed_reference', 'speed_feedback')
# panel -> (fields drawn in it, y label); the state panel comes first in every column. The
# labels are two short lines: a panel is lower than one long line (they overlapped).
PANELS = (('motor_current', ('motor_current',), 'motor current\n[A]'),
          ('motor_temperature', ('motor_temperature',), 'motor temperature\n[%]'),
          ('speed', ('speed_reference', 'speed_feedback'), 'speed\n[%]'))
STYLE = {'motor_current': ('tab:red', 'current'),
         'motor_temperature': ('tab:orange', 'temperature'),
         'speed_reference': ('tab:gray', 'reference'),
         'speed_feedback': ('tab:green', 'feedback')}
COLUMN_SIZE_IN = (6.5, 8.0)
DPI = 90
Samples = List[Tuple[float, object]]
Series = Dict[str, Dict[str, Samples]]  # device -> field -> (seconds from the start, value)


class NotARecording(Exception):
    """The file is not a bag, or it lacks what was asked for."""


class BadOutput(Exception):
    """The plot cannot be written where asked (the text says why, without the path)."""


@dataclass
class Recording:
    """What a bag holds for the plot: the samples, and when the bag began."""

    series: Series
    start_ns: int  # the bag's start time (its first message), ns since the epoch

    def started(self) -> str:
        """Return the start as local date and time with its UTC offset."""
        moment = datetime.datetime.fromtimestamp(self.start_ns / 1e9).astimezone()
        return moment.isoformat(sep=' ', timespec='seconds')


def bag_directory(path: str) -> str:
    """Return the bag directory of ``path`` (the directory itself or a file inside it)."""
    if not os.path.exists(path):
        raise NotARecording('no such file or directory')
    directory = (os.path.dirname(path) or '.') if os.path.isfile(path) else path
    if not os.path.isfile(os.path.join(directory, 'metadata.yaml')):
        raise NotARecording(f'not a rosbag2 bag: no metadata.yaml in {directory}')
    return directory


def read_recording(path: str) -> Recording:
    """Return the samples of every ``<device>/<field>`` topic in the bag, and its start."""
    from pathlib import Path

    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.rosbag2 import ReaderError
    series: Series = defaultdict(lambda: defaultdict(list))
    directory = bag_directory(path)
    try:
        with AnyReader([Path(directory)]) as reader:
            wanted = [connection for connection in reader.connections
                      if _device_field(connection.topic)[1] in FIELDS]
            for connection, time_ns, raw in reader.messages(connections=wanted):
                device, field = _device_field(connection.topic)
                value = reader.deserialize(raw, connection.msgtype).data
                series[device][field].append(((time_ns - reader.start_time) / 1e9, value))
            start_ns = reader.start_time
        custom = custom_data(directory)
    except (AnyReaderError, ReaderError, ValueError) as error:
        raise NotARecording(f'not a rosbag2 bag: {error}') from None
    except OSError as error:
        raise NotARecording(f'cannot read the bag: {error.strerror or error}') from None
    for topic, percent in decode_references(custom).items():
        device, _ = _device_field(topic)
        series[device]['speed_reference'].insert(0, (0.0, percent))
    return Recording(series, start_ns)


def custom_data(directory: str) -> Dict[str, str]:
    """Return the custom data in a bag's metadata.yaml (rosbags has no public reader of it)."""
    import yaml
    with open(os.path.join(directory, 'metadata.yaml')) as stream:
        metadata = yaml.safe_load(stream)['rosbag2_bagfile_information']
    return metadata.get('custom_data') or {}


def _device_field(topic: str) -> Tuple[str, str]:
    device, _, field = topic.strip('/').rpartition('/')
    return (device, field) if device else ('', '')


def devices_of(series: Series) -> List[str]:
    """Return the devices (a ``<device>/state`` topic with messages) in name order."""
    return sorted(name for name, fields in series.items() if fields.get('state'))


def select_devices(series: Series, wanted: Optional[List[str]]) -> List[str]:
    """Return the devices to draw: all, or ``wanted`` (full name or last part, unambiguous)."""
    names = devices_of(series)
    if not names:
        raise NotARecording('the bag has no <device>/state topic with messages')
    if not wanted:
        return names
    chosen = []
    for request in wanted:
        matches = [name for name in names
                   if name == request.strip('/') or name.rpartition('/')[2] == request]
        if len(matches) != 1:
            reason = 'no device' if not matches else 'more than one device named'
            raise NotARecording(f'{reason} {request!r}: devices are {", ".join(names)}')
        chosen.append(matches[0])
    return chosen


def panels_of(fields: Dict[str, Samples]) -> List[str]:
    """Return the panels of one device: state, then each quantity the bag has samples of."""
    return ['state'] + [panel for panel, panel_fields, _ in PANELS
                        if any(fields.get(field) for field in panel_fields)]


def state_level(state: object) -> int:
    """Return the row of a state; a text outside the contract is drawn as ``unknown``."""
    return STATES.index(state) if state in STATES else STATES.index('unknown')


def check_output(path: str) -> None:
    """Raise BadOutput unless a plot can be written to ``path`` (checked before drawing)."""
    from matplotlib.backend_bases import FigureCanvasBase
    directory = os.path.dirname(path) or '.'
    extension = os.path.splitext(path)[1].lstrip('.').lower()
    formats = FigureCanvasBase.get_supported_filetypes()
    if not os.path.isdir(directory):
        raise BadOutput(f'no directory {directory}' if not os.path.exists(directory)
                        else f'{directory} is not a directory')
    if os.path.isdir(path):
        raise BadOutput('it is a directory')
    if not os.access(path if os.path.exists(path) else directory, os.W_OK):
        raise BadOutput('permission denied')
    if extension and extension not in formats:
        raise BadOutput(f'unknown image type .{extension} (use .png, .svg or .pdf)')


def plot(recording: Recording, output: str, devices: Optional[List[str]] = None,
         title: str = ''):
    """Draw ``devices`` (default: all) into the PNG ``output``; return the matplotlib figure."""
    from matplotlib.figure import Figure
    series = recording.series
    names = select_devices(series, devices)
    width_in, height_in = COLUMN_SIZE_IN
    figure = Figure(figsize=(width_in * len(names), height_in), dpi=DPI, layout='constrained')
    columns = figure.subfigures(1, len(names), squeeze=False)[0]
    end_s = max(samples[-1][0] for fields in series.values()
                for samples in fields.values() if samples)
    for column, name in zip(columns, names):
        _draw_device(column, name, series[name], end_s)
    figure.suptitle('\n'.join(filter(None, [title, f'recorded {recording.started()}'])))
    try:
        figure.savefig(output)
    except OSError as error:  # e.g. a file system that refuses even root
        reason = error.strerror or str(error)
        raise BadOutput(reason[:1].lower() + reason[1:]) from None
    return figure


def _draw_device(subfigure, name: str, fields: Dict[str, Samples], end_s: float) -> None:
    panels = panels_of(fields)
    axes = subfigure.subplots(len(panels), 1, sharex=True, squeeze=False,
                              height_ratios=[2.2] + [1.0] * (len(panels) - 1))[:, 0]
    subfigure.suptitle(name)
    _draw_states(axes[0], fields['state'], end_s)
    for axis, panel in zip(axes[1:], panels[1:]):
        _, panel_fields, label = next(entry for entry in PANELS if entry[0] == panel)
        for field in panel_fields:
            _draw_values(axis, field, fields.get(field, []), end_s)
        axis.set_ylabel(label)
        axis.grid(True, alpha=0.3)
        if len(panel_fields) > 1:
            axis.legend(loc='best', fontsize='small')
    axes[-1].set_xlabel('time [s]')
    subfigure.align_ylabels(axes)


def _draw_states(axis, states: Samples, end_s: float) -> None:
    times = [time for time, _ in states] + [max(end_s, states[-1][0])]
    levels = [state_level(state) for _, state in states]
    axis.step(times, levels + levels[-1:], where='post', color='tab:blue')
    axis.set_yticks(range(len(STATES)), STATES)
    axis.set_ylim(-0.5, len(STATES) - 0.5)
    axis.set_ylabel('state')
    axis.grid(True, axis='y', alpha=0.3)


def _draw_values(axis, field: str, samples: Samples, end_s: float) -> None:
    if not samples:
        return
    colour, label = STYLE[field]
    times = [time for time, _ in samples]
    values = [value for _, value in samples]
    if field == 'speed_reference':  # a set point holds until the next one
        axis.step(times + [end_s], values + values[-1:], where='post', color=colour,
                  linestyle='--', label=label)
    else:
        axis.plot(times, values, color=colour, label=label)


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser."""
    parser = OneLineParser(prog=PROG, description=plain_text(
        __doc__.split('\n\n')[1].split('. ')[0]) + '.')
    parser.add_argument('recording', help='bag directory (or a file in it)')
    parser.add_argument('output', help='PNG file to write')
    parser.add_argument('--device', action='append',
                        help='only this device (repeatable; e.g. crusher or line1/crusher)')
    parser.add_argument('--title', default='', help='title above the plot')
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    """Plot a recording; exit 2 with one line on a bad bag, device name or output path."""
    args = build_parser().parse_args(argv)
    try:
        require(PROG, 'rosbags', 'matplotlib')
        check_output(args.output)
        recording = read_recording(args.recording)
        plot(recording, args.output, args.device, args.title)
    except MissingDependency as error:
        print(error, file=sys.stderr)
        return 2
    except BadOutput as error:
        print(f'{PROG}: cannot write {args.output}: {error}', file=sys.stderr)
        return 2
    except NotARecording as error:
        print(f'{PROG}: {args.recording}: {error}', file=sys.stderr)
        return 2
    names = select_devices(recording.series, args.device)
    print(f'{PROG}: wrote {args.output} ({", ".join(names)}; recorded {recording.started()})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
