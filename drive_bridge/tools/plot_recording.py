"""
Plot a recording (MCAP from ``ros2 bag record`` or the bridge's recorder) as a PNG.

One column per device found in the file (a ``<device>/state`` topic), three panels each:
state over time, motor current in amperes, speed feedback in percent (drives only). Needs
``mcap``, ``mcap-ros2-support`` and ``matplotlib``; no ROS installation.
Run: ``drive_bridge_plot recording.mcap plot.png [--device NAME] [--title TEXT]``
"""

import argparse
from collections import defaultdict
import sys
from typing import Dict, List, Optional, Tuple

STATES = ('offline', 'unknown', 'not_ready', 'tripped', 'ready', 'stopping', 'starting',
          'running')
Series = Dict[str, Dict[str, List[Tuple[float, object]]]]  # device -> field -> samples


def read_recording(path: str) -> Series:
    """Return device -> topic field (state, motor_current, speed_feedback) -> samples."""
    series: Series = defaultdict(lambda: defaultdict(list))
    start_ns: Optional[int] = None
    for _, channel, message, decoded in decoded_messages(path):
        device, _, field = channel.topic.strip('/').rpartition('/')
        if field not in ('state', 'motor_current', 'speed_feedback') or not device:
            continue
        start_ns = message.log_time if start_ns is None else start_ns
        series[device][field].append(((message.log_time - start_ns) / 1e9, decoded.data))
    return series


def decoded_messages(path: str):
    """Yield (schema, channel, message, decoded message) of an MCAP file with ROS 2 CDR."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        yield from reader.iter_decoded_messages()


def plot(series: Series, output: str, devices: Optional[List[str]] = None,
         title: str = '') -> None:
    """Draw the panels of ``devices`` (all with a state topic by default) into ``output``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    names = devices or sorted(name for name in series if series[name].get('state'))
    if not names:
        raise ValueError('the recording has no <device>/state topic')
    figure, axes = plt.subplots(3, len(names), sharex='col', squeeze=False,
                                figsize=(6.5 * len(names), 6.5))
    for column, name in enumerate(names):
        _draw_device(axes[:, column], name, series[name])
    if title:
        figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(output, dpi=90)
    plt.close(figure)


def _draw_device(axes, name: str, fields) -> None:
    state_axis, current_axis, speed_axis = axes
    states = fields.get('state', [])
    if states:
        times = [time for time, _ in states] + [_last_time(fields)]
        levels = [STATES.index(value) if value in STATES else 0 for _, value in states]
        state_axis.step(times, levels + levels[-1:], where='post', color='tab:blue')
    state_axis.set_yticks(range(len(STATES)), STATES)
    state_axis.set_title(f'{name}')
    state_axis.set_ylabel('state')
    for axis, field, label, colour in ((current_axis, 'motor_current', 'motor current [A]',
                                        'tab:red'),
                                       (speed_axis, 'speed_feedback', 'speed feedback [%]',
                                        'tab:green')):
        samples = fields.get(field, [])
        if samples:
            axis.plot([time for time, _ in samples], [value for _, value in samples],
                      color=colour)
        else:
            axis.text(0.5, 0.5, f'no {field} topic', ha='center', va='center',
                      transform=axis.transAxes)
        axis.set_ylabel(label)
        axis.grid(True, alpha=0.3)
    speed_axis.set_xlabel('time [s]')


def _last_time(fields) -> float:
    return max((samples[-1][0] for samples in fields.values() if samples), default=0.0)


def main(argv: Optional[List[str]] = None) -> int:
    """Plot a recording; exit 2 with one line on a bad file."""
    parser = argparse.ArgumentParser(prog='drive_bridge_plot', description=__doc__.split(
        '\n\n')[0].strip())
    parser.add_argument('recording', help='MCAP file')
    parser.add_argument('output', help='PNG file to write')
    parser.add_argument('--device', action='append', help='only this device (repeatable)')
    parser.add_argument('--title', default='')
    args = parser.parse_args(argv)
    from mcap.exceptions import McapError
    try:
        series = read_recording(args.recording)
        plot(series, args.output, args.device, args.title)
    except (OSError, ValueError, KeyError, McapError) as error:
        print(f'drive_bridge_plot: {args.recording}: {error}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
