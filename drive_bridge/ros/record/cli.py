"""
``drive_bridge_record``: record the bridge's topics into a rosbag2 bag (MCAP storage).

For machines without rosbag2 (ROS 2 from PyPI); on an apt install ``ros2 bag record`` writes
the same kind of bag. Name topics, or ``--all`` for every topic the ``drive_bridge`` node in
``--namespace`` publishes or subscribes to (``/rosout`` and ``/parameter_events`` left out;
topics that appear later are added within a second). Relative topic names are taken in
``--namespace``. Recording starts once the subscriptions are connected to the publishers (at
most ``--wait`` seconds), and ends after ``--duration`` seconds or at Ctrl-C / SIGTERM; either
way the bag is closed cleanly and the exit status is 0, as with ``ros2 bag record``.
For each recorded ``<device>/speed_reference`` the bag's metadata keeps the bridge's
``<device>.speed_reference`` parameter as recording began (the reference configured then;
the topic carries only later changes), for ``drive_bridge_plot``.
Exit status: 0 recorded, 1 the bag could not be written, 2 bad input or ``rosbags`` missing
(one line on stderr).
"""

import argparse
import math
import os
import signal
import sys
import time
from typing import Dict, List, Optional, Tuple, TYPE_CHECKING

from drive_bridge.bag_metadata import encode_references, REFERENCE_AT_START
from drive_bridge.console import OneLineParser, plain_text
from drive_bridge.errors import RecordingError
from drive_bridge.extras import MissingDependency, require
from drive_bridge.ros.naming import COMMANDS_NODE_SUFFIX
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
import rclpy
from rclpy.exceptions import InvalidTopicNameException
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from rclpy.validate_full_topic_name import validate_full_topic_name

if TYPE_CHECKING:  # rosbags is optional: main() checks it before the recorder is imported
    from drive_bridge.ros.record.recorder import BagRecorder

PROG = 'drive_bridge_record'
BRIDGE_NODE = 'drive_bridge'
SKIPPED = ('/rosout', '/parameter_events')
RESCAN_PERIOD_S = 1.0
REFERENCE_TOPIC = 'speed_reference'
PARAMETER_RETRY_S = 1.0
DISCOVERY_SETTLE_S = 0.5  # the bridge's topics unchanged this long: all found
DISCOVERY_SETTLE_ALONE_S = 2.0  # the same without its commands node


class BadInput(Exception):
    """An argument or the ROS graph does not allow a recording (exit status 2)."""


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser (its arguments are checked by :func:`parse_args`)."""
    parser = OneLineParser(
        prog=PROG, description=plain_text(__doc__.split('\n\n')[1].strip()))
    parser.add_argument('topics', nargs='*', help='topics to record (relative: in --namespace)')
    parser.add_argument('-a', '--all', action='store_true',
                        help='every topic of the drive_bridge node in --namespace')
    parser.add_argument('-o', '--output', help='bag directory to create '
                        '(default: rosbag2_YYYY_MM_DD-HH_MM_SS, as ros2 bag record names it)')
    parser.add_argument('--namespace', default='/', help="the bridge node's namespace "
                        '(as given with -r __ns:=...; default /)')
    parser.add_argument('--duration', type=float, help='seconds to record (default: until '
                        'Ctrl-C)')
    parser.add_argument('--wait', type=float, default=10.0,
                        help='seconds to wait for the topics to appear (default 10)')
    return parser


def parse_args(argv: List[str]) -> argparse.Namespace:
    """Parse and check the command line; raise BadInput with one line."""
    args = build_parser().parse_args(argv)
    if bool(args.topics) == args.all:
        raise BadInput('name the topics to record, or --all (not both)')
    for name, value in (('--duration', args.duration), ('--wait', args.wait)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise BadInput(f'{name} must be a positive number of seconds, not {value}')
    args.namespace = '/' + args.namespace.strip('/')
    args.topics = [full_topic_name(topic, args.namespace) for topic in args.topics]
    args.output = args.output or time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
    if os.path.exists(args.output):
        raise BadInput(f'{args.output} exists: choose a new output directory')
    return args


def full_topic_name(topic: str, namespace: str) -> str:
    """Return ``topic`` taken in ``namespace``; raise BadInput if it is not a topic name."""
    name = topic if topic.startswith('/') else f'{namespace.rstrip("/")}/{topic}'
    try:
        validate_full_topic_name(name)
    except InvalidTopicNameException as error:
        reason = str(error).splitlines()[0].split(': ', 1)[-1].rstrip(':')
        raise BadInput(f'{topic!r} is not a topic name: {reason}') from None
    return name


def bridge_topics(node: Node, namespace: str) -> Dict[str, str]:
    """Return topic -> type of the drive_bridge node in ``namespace`` ({} if not found)."""
    return bridge_graph(node, namespace)[0]


def bridge_graph(node: Node, namespace: str) -> Tuple[Dict[str, str], bool]:
    """
    Return the drive_bridge node's topics in ``namespace`` and whether its commands node is.

    Its command subscriptions (``speed_reference``, ``~/joint_commands``) are those of its
    commands node, ``drive_bridge_commands`` beside it
    (:mod:`drive_bridge.ros.node.command_inputs`), made when the bridge is configured.
    """
    topics: Dict[str, str] = {}
    commands_node = BRIDGE_NODE + COMMANDS_NODE_SUFFIX
    with_commands_node = True
    for query, name in ((node.get_publisher_names_and_types_by_node, BRIDGE_NODE),
                        (node.get_subscriber_names_and_types_by_node, BRIDGE_NODE),
                        (node.get_subscriber_names_and_types_by_node, commands_node)):
        try:
            found = query(name, namespace)
        except NodeNameNonExistentError:
            if name == commands_node:
                with_commands_node = False  # not made yet (the node not configured)
                continue
            return {}, False
        topics.update((topic, types[0]) for topic, types in found
                      if topic not in SKIPPED and types)
    return topics, with_commands_node


def published_topics(node: Node, wanted: List[str]) -> Dict[str, str]:
    """Return topic -> type of the ``wanted`` topics that have a publisher now."""
    found = {}
    for topic in wanted:
        publishers = node.get_publishers_info_by_topic(topic)
        if publishers:
            found[topic] = publishers[0].topic_type
    return found


def discover(node: Node, args: argparse.Namespace) -> Dict[str, str]:
    """
    Wait up to ``--wait`` for the topics and their publishers; raise BadInput if none.

    A named topic is subscribed once its publishers are known, so that the recorder asks for
    transient local where they offer it; one that only has subscribers when the wait ends is
    recorded without.
    """
    deadline = time.monotonic() + args.wait
    settled = _Settled()
    while True:
        now = time.monotonic()
        if args.all:
            found, with_commands_node = bridge_graph(node, args.namespace)
            quiet = settled.after(found, with_commands_node, now)
            if found and (quiet or now > deadline):
                return found
        else:
            found = published_topics(node, args.topics)
            if len(found) == len(args.topics):
                return found
        if now > deadline:
            break
        rclpy.spin_once(node, timeout_sec=0.1)
    hint = '(is the bridge running, in this ROS_DOMAIN_ID and namespace?)'
    if args.all:
        where = f'{args.namespace.rstrip("/")}/{BRIDGE_NODE}'
        raise BadInput(f'no node {where} within {args.wait:g} s {hint}')
    known = dict(node.get_topic_names_and_types())
    missing = [topic for topic in args.topics if topic not in found and not known.get(topic)]
    if missing:
        raise BadInput(f'no topic {", ".join(missing)} within {args.wait:g} s {hint}')
    for topic in args.topics:
        if topic not in found:
            print(f'{PROG}: {topic} has no publisher yet: recording it as volatile',
                  file=sys.stderr)
            found[topic] = known[topic][0]
    return found


class _Settled:
    """
    Whether the bridge's topics stopped coming in.

    DDS discovers a node's topics one by one, and those of the commands node beside it
    (``speed_reference``) on their own: a recording begun at the first topic found missed
    the speed reference at the start (found a second later, by the rescan). Settled: the
    topics unchanged for ``DISCOVERY_SETTLE_S`` with the commands node discovered, or for
    ``DISCOVERY_SETTLE_ALONE_S`` without it (a bridge not configured has none).
    """

    def __init__(self):
        self.topics: Dict[str, str] = {}
        self.since_s = 0.0

    def after(self, topics: Dict[str, str], with_commands_node: bool, now_s: float) -> bool:
        """Take what is found at ``now_s`` (monotonic); return whether it has settled."""
        if topics != self.topics:
            self.topics, self.since_s = dict(topics), now_s
        quiet_s = DISCOVERY_SETTLE_S if with_commands_node else DISCOVERY_SETTLE_ALONE_S
        return now_s - self.since_s >= quiet_s


class _Stop:
    """Set by SIGINT and SIGTERM: the recording ends and the bag is closed."""

    def __init__(self):
        self.requested = False
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, self._handle)

    def _handle(self, number, frame) -> None:
        self.requested = True


def recordable(topics: Dict[str, str], skip_unknown: bool) -> Dict[str, str]:
    """Return the topics whose type rosbags knows; skip (--all) or refuse the others."""
    from drive_bridge.ros.record.recorder import is_recordable  # needs rosbags: main() checked it
    unknown = {topic: name for topic, name in topics.items() if not is_recordable(name)}
    if unknown and not skip_unknown:
        topic, name = sorted(unknown.items())[0]
        raise BadInput(f'{topic}: type {name} is not a ROS 2 Jazzy type that rosbags knows')
    for topic, name in sorted(unknown.items()):
        print(f'{PROG}: skipping {topic}: type {name} is unknown to rosbags', file=sys.stderr)
    return {topic: name for topic, name in topics.items() if topic not in unknown}


def configured_references(node: Node, topics: List[str], deadline_s: float,
                          stop: _Stop) -> Dict[str, float]:
    """
    Return reference topic -> its bridge's ``<device>.speed_reference`` parameter now [%].

    The bridge of ``<namespace>/<device>/speed_reference`` is ``<namespace>/drive_bridge``
    (device names hold no slash); it is asked through its parameter service, spinning
    ``node`` (so the recording goes on), until ``deadline_s`` (monotonic) at the latest.
    Parameters left unanswered are named in one line on stderr and left out, as are those
    the bridge does not have.
    """
    wanted: Dict[str, Dict[str, str]] = {}  # bridge node -> parameter -> topic
    for topic in topics:
        namespace, device, name = (['', ''] + topic.rsplit('/', 2))[-3:]
        if name == REFERENCE_TOPIC and device:
            wanted.setdefault(f'{namespace}/{BRIDGE_NODE}', {})[f'{device}.{name}'] = topic
    found: Dict[str, float] = {}
    for bridge, parameters in sorted(wanted.items()):
        values, unanswered = _double_parameters(node, bridge, list(parameters), deadline_s,
                                                stop)
        found.update((parameters[name], value) for name, value in values.items())
        if unanswered:
            print(f'{PROG}: no answer from {bridge} about {", ".join(unanswered)}: the bag '
                  'has no reference at the start', file=sys.stderr, flush=True)
    return found


def _double_parameters(node: Node, bridge: str, names: List[str], deadline_s: float,
                       stop: _Stop) -> Tuple[Dict[str, float], List[str]]:
    """
    Return the double parameters ``names`` of node ``bridge``, and the names unanswered.

    One request per name (a name the node lacks empties a whole answer), repeated each
    ``PARAMETER_RETRY_S`` until answered (reading is harmless): the answer to a client that
    the server has not discovered yet is lost.
    """
    client = node.create_client(GetParameters, f'{bridge}/get_parameters')
    pending: Dict[str, Optional[Future]] = dict.fromkeys(names)
    found: Dict[str, float] = {}
    sent_s = -math.inf
    try:
        while pending and time.monotonic() < deadline_s and not stop.requested:
            for name, future in list(pending.items()):
                if future is not None and future.done():
                    values = future.result().values
                    if values and values[0].type == ParameterType.PARAMETER_DOUBLE:
                        found[name] = values[0].double_value
                    del pending[name]
            if pending and client.service_is_ready() and \
                    time.monotonic() - sent_s >= PARAMETER_RETRY_S:
                for name, future in pending.items():
                    if future is not None:
                        client.remove_pending_request(future)
                    pending[name] = client.call_async(GetParameters.Request(names=[name]))
                sent_s = time.monotonic()
            rclpy.spin_once(node, timeout_sec=0.05)
        return found, list(pending)
    finally:
        node.destroy_client(client)


def record(node: Node, args: argparse.Namespace, stop: _Stop) -> 'BagRecorder':
    """Record until the duration ends or a stop is requested; return the closed recorder."""
    from drive_bridge.ros.record.recorder import BagRecorder  # needs rosbags: main() checked it
    topics = recordable(discover(node, args), skip_unknown=args.all)
    recorder = BagRecorder(node, args.output)
    try:
        for topic, type_name in sorted(topics.items()):
            recorder.add_topic(topic, type_name)
        deadline = time.monotonic() + args.wait
        while not recorder.matched() and time.monotonic() < deadline and not stop.requested:
            rclpy.spin_once(node, timeout_sec=0.05)
        references = configured_references(node, sorted(topics),
                                           time.monotonic() + args.wait, stop)
        if references:
            recorder.set_custom_data(REFERENCE_AT_START, encode_references(references))
        recorder.restart_clock()  # the duration counts from here
        print(f'{PROG}: recording {len(topics)} topics to {args.output}', flush=True)
        rescan = time.monotonic() + RESCAN_PERIOD_S
        while not stop.requested:
            if args.duration is not None and recorder.elapsed_s() >= args.duration:
                break
            if args.all and time.monotonic() >= rescan:
                rescan = time.monotonic() + RESCAN_PERIOD_S
                found = recordable(bridge_topics(node, args.namespace), skip_unknown=True)
                for topic, type_name in found.items():
                    recorder.add_topic(topic, type_name)
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        recorder.close()
    return recorder


def main(argv: Optional[List[str]] = None) -> int:
    """Run the command; see the module docstring for the exit status."""
    argv = sys.argv if argv is None else [PROG] + list(argv)
    try:
        args = parse_args(remove_ros_args(argv)[1:])
        require(PROG, 'rosbags')
    except BadInput as error:
        print(f'{PROG}: {error}', file=sys.stderr, flush=True)
        return 2
    except MissingDependency as error:
        print(error, file=sys.stderr, flush=True)
        return 2
    from drive_bridge.ros.record.recorder import count_summary  # needs rosbags: checked above
    stop = _Stop()
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('drive_bridge_record', start_parameter_services=False)
    try:
        recorder = record(node, args, stop)
    except (BadInput, RecordingError) as error:
        print(f'{PROG}: {error}', file=sys.stderr, flush=True)
        return 2
    except OSError as error:
        print(f'{PROG}: cannot write {args.output}: {error}', file=sys.stderr, flush=True)
        return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    print(f'{PROG}: wrote {args.output}: '
          f'{count_summary(recorder.counts, recorder.elapsed_s())}', file=sys.stderr, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
