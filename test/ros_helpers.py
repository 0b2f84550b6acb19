"""Run the node in a subprocess and drive it through real rclpy clients."""

from contextlib import contextmanager
import os
import signal
import subprocess
import sys
import tempfile
import time
from typing import Dict, Iterator, List, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from drive_bridge.config.params_file import write_params_file
from fork_server import default_signals, ForkedPopen
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Float32, String, UInt16, UInt32
from std_srvs.srv import Trigger

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# The client's topics without rclpy's default QoS event handlers (incompatible QoS and type
# warnings): two a subscription, each one more entity that every spin walks (a client of two
# devices spent about 40 % of its CPU on them).
NO_SUBSCRIPTION_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)
NO_PUBLISHER_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)


def write_params(path, bus: Dict, devices: Dict[str, Dict]) -> str:
    """Write a params file for the node and return its path."""
    return write_params_file(str(path), bus, devices)


def start_node(params_file: str, namespace: str = '', restore_signals: bool = False,
               remaps: Sequence[str] = (), fresh: bool = False) -> subprocess.Popen:
    """
    Start drive_bridge_node in a subprocess with the test environment.

    ``restore_signals``: SIGINT and SIGTERM at their defaults in the child (a child of a
    non-interactive shell's background job inherits SIGINT ignored). ``remaps``: more
    ``-r FROM:=TO`` rules. The node is forked from the test process's fork server
    (:mod:`fork_server`), or exec'd as ``python -m`` where ``fresh``.
    """
    command = [sys.executable, '-m', 'drive_bridge.ros.node.entry', '--ros-args',
               '--params-file', params_file]
    if namespace:
        command += ['-r', f'__ns:={namespace}']
    for rule in remaps:
        command += ['-r', rule]
    log = tempfile.NamedTemporaryFile('w+', prefix='drive_bridge_node_', suffix='.log')
    process = ForkedPopen(command, env=dict(os.environ), stdout=log, stderr=log, text=True,
                          preexec_fn=default_signals if restore_signals else None,
                          fork=not fresh)
    process.log = log  # a file, not a pipe: a full pipe would block the node's logging
    return process


def node_output(process: subprocess.Popen) -> str:
    """
    Return what the node printed so far.

    Read through an open file of its own: the node writes through a duplicate of
    ``process.log``'s descriptor, which shares its file offset, so a ``seek(0)`` on
    ``process.log`` made the node's next line overwrite the start of the log (seen: a line
    the test looked for lost its first characters).
    """
    with open(process.log.name) as log:
        return log.read()


def stop_node(process: subprocess.Popen, timeout_s: float = 10.0):
    """SIGTERM the node and return (exit code, stderr)."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
    try:
        process.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
    return process.returncode, node_output(process)


@contextmanager
def serving(server) -> Iterator[object]:
    """Serve a simulator on a pty for the duration of the block."""
    server.open_pty()
    server.start()
    try:
        yield server
    finally:
        server.stop()


@contextmanager
def running_node(params_path, bus: Dict, devices: Dict[str, Dict], drives: Sequence[str] = (),
                 ready: Sequence[str] = (), namespace: str = '',
                 remaps: Sequence[str] = ()) -> Iterator['RosClient']:
    """Run the node on ``bus`` with ``devices``; yield a client once ``ready`` are ready."""
    process = start_node(write_params(params_path, bus, devices), namespace, remaps=remaps)
    client = RosClient(list(devices), namespace=namespace, drives=list(drives))
    try:
        for name in ready:
            assert client.wait_state(name, 'ready', 15.0), stop_node(process)
        client.process = process
        yield client
    finally:
        client.close()
        print(stop_node(process)[1])


def spin_until(node: 'rclpy.node.Node', predicate, timeout_s: float) -> bool:
    """Spin ``node`` until ``predicate`` holds or ``timeout_s`` passed; return the predicate."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        rclpy.spin_once(node, timeout_sec=0.05)
    return bool(predicate())


def lean_node(name: str) -> 'rclpy.node.Node':
    """
    Return a test node without the services no test calls on it.

    No parameter services, no type description service, no /rosout publisher: seven services
    and a publisher fewer for the node under test and the client to discover, and for each
    spin to wait on.
    """
    return rclpy.create_node(name, start_parameter_services=False, enable_rosout=False,
                             parameter_overrides=[Parameter('start_type_description_service',
                                                            value=False)])


class RosClient:
    """An rclpy node that records a device's topics and calls its services."""

    def __init__(self, names: List[str], namespace: str = '', drives: List[str] = ()):
        self.node = lean_node(f'test_client_{os.getpid()}')
        self.prefix = namespace.rstrip('/') + '/' if namespace else ''
        self.messages: Dict[str, list] = {}
        for name in names:
            for topic, kind, qos in (('state', String, LATCHED), ('trip', String, LATCHED),
                                     ('motor_current', Float32, 10),
                                     ('motor_temperature', Float32, 10),
                                     ('trip_code', UInt16, 10), ('status_word', UInt16, 10)):
                self._record(f'{self.prefix}{name}/{topic}', kind, qos)
        for name in drives:
            for topic, kind in (('speed_feedback', Float32), ('alarm_word', UInt32),
                                ('warning_word', UInt32)):
                self._record(f'{self.prefix}{name}/{topic}', kind, 10)
        self.reference_publishers = {
            name: self.node.create_publisher(Float32, f'{self.prefix}{name}/speed_reference', 10,
                                             event_callbacks=NO_PUBLISHER_EVENTS)
            for name in drives}
        self._record('/diagnostics', DiagnosticArray, 10)
        # Clients are made once, up front: a client created just before a call can lose its
        # first response while the server has not yet discovered the client's reply reader.
        self.clients = {(name, command): self.node.create_client(
            Trigger, f'{self.prefix}{name}/{command}')
            for name in names for command in ('start', 'stop', 'quick_stop', 'reset')}
        self.clients.update({(name, 'coast_stop'): self.node.create_client(
            Trigger, f'{self.prefix}{name}/coast_stop') for name in drives})
        self.parameters = self.node.create_client(
            SetParameters, f'{self.prefix or "/"}drive_bridge/set_parameters')

    def _record(self, topic, kind, qos):
        self.messages[topic] = []
        self.node.create_subscription(kind, topic, self.messages[topic].append, qos,
                                      event_callbacks=NO_SUBSCRIPTION_EVENTS)

    def values(self, name: str, topic: str) -> list:
        return [m.data for m in self.messages[f'{self.prefix}{name}/{topic}']]

    def spin_until(self, predicate, timeout_s: float = 10.0) -> bool:
        return spin_until(self.node, predicate, timeout_s)

    def state(self, name: str) -> str:
        states = self.values(name, 'state')
        return states[-1] if states else ''

    def wait_state(self, name: str, state: str, timeout_s: float = 10.0) -> bool:
        return self.spin_until(lambda: self.state(name) == state, timeout_s)

    def call(self, name: str, command: str, timeout_s: float = 10.0) -> Trigger.Response:
        client = self.clients[(name, command)]
        assert client.wait_for_service(timeout_sec=timeout_s), f'no {name}/{command}'
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(self.node, future, timeout_sec=timeout_s)
        assert future.done(), f'{name}/{command} did not answer'
        return future.result()

    def set_parameter(self, name: str, value) -> 'SetParameters.Response':
        """Set one parameter of the node (bool, float, int or str) and return the result."""
        kinds = {bool: ('PARAMETER_BOOL', 'bool_value'),
                 float: ('PARAMETER_DOUBLE', 'double_value'),
                 int: ('PARAMETER_INTEGER', 'integer_value'),
                 str: ('PARAMETER_STRING', 'string_value')}
        kind, field = kinds[type(value)]
        parameter = ParameterMsg(name=name, value=ParameterValue(
            type=getattr(ParameterType, kind), **{field: value}))
        assert self.parameters.wait_for_service(timeout_sec=5)
        future = self.parameters.call_async(SetParameters.Request(parameters=[parameter]))
        rclpy.spin_until_future_complete(self.node, future, timeout_sec=5)
        assert future.done(), f'setting {name} did not answer'
        return future.result().results[0]

    def publish_reference(self, name: str, percent: float) -> None:
        self.reference_publishers[name].publish(Float32(data=float(percent)))

    def wait_fresh_diagnostics(self) -> bool:
        """Wait for a /diagnostics message begun after this call (the second one from now)."""
        count = len(self.messages['/diagnostics'])
        return self.spin_until(lambda: len(self.messages['/diagnostics']) > count + 1)

    def diagnostics(self, name: str):
        """Return the latest status of device ``name`` (namespaced nodes: full name)."""
        wanted = f'{self.prefix}drive_bridge: {name}' if self.prefix else \
            f'drive_bridge: {name}'
        for array in reversed(self.messages['/diagnostics']):
            for status in array.status:
                if status.name == wanted:
                    return status
        return None

    def close(self):
        self.node.destroy_node()
