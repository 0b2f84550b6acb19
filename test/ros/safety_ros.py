"""rclpy helpers of the safety tests: lifecycle, atomic parameters, calls left in flight."""

from dataclasses import dataclass, field
import random
import signal
import subprocess
import time
from typing import Any, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.sim.lvsg_gateway import make_lvsg_gateway
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParametersAtomically
from ros_helpers import node_output, RosClient, start_node, write_params
from safety_helpers import DriveProbe, LvsgProbe, McdProbe, MotorProbe, wait_for
from std_srvs.srv import Trigger

NODE = '/drive_bridge'
# The node's start-up (imports, discovery, first poll) on a loaded 2-core machine: seconds
# here, but 20 s was seen with a load average of 15.
READY_S = 60.0


@dataclass
class Rig:
    """One simulated device on a pty, its node configuration and its motor probe."""

    family: str
    server: Any
    probe: MotorProbe
    device: Dict[str, Any]
    name: str = 'motor'
    bus: Dict[str, Any] = field(default_factory=dict)

    @property
    def devices(self) -> Dict[str, Dict[str, Any]]:
        return {self.name: self.device}

    @property
    def drives(self) -> Tuple[str, ...]:
        return (self.name,) if self.family in ('fc', 'vlt') else ()

    def bus_settings(self, **extra: Any) -> Dict[str, Any]:
        return {'port': self.server.pty_path, 'parity': 'N', 'timeout': 1.0,
                'diagnostics_period': 0.2, 'backoff_max': 1.0, **self.bus, **extra}

    def stop(self) -> None:
        self.server.stop()


def make_rig(family: str, **device: Any) -> Rig:
    """
    Return a served rig of ``family`` with short ramps.

    Families: mcd, fc, vlt, lvsg (extended module), lvsg_basic.

    ``device`` overrides the node's device settings.
    """
    bus: Dict[str, Any] = {}
    if family == 'mcd':
        server = make_sim_server({20: 'mcd500'},
                                 settings={'mcd': {'start_time_s': 0.5, 'stop_time_s': 0.3}})
        settings = {'family': 'mcd', 'model': 'mcd500', 'address': 20}
        probe_of = (lambda: McdProbe(server, 20))
    elif family in ('fc', 'vlt'):
        model = 'fc51' if family == 'fc' else 'vlt6000'
        server = make_sim_server({1: model}, settings={family: {
            'ramp_up_s': 0.5, 'ramp_down_s': 0.3, 'quick_stop_ramp_s': 0.2}})
        settings = {'family': family, 'model': model, 'address': 1, 'speed_reference': 50.0}
        probe_of = (lambda: DriveProbe(server, 1))
    elif family in ('lvsg', 'lvsg_basic'):
        module = 'basic' if family == 'lvsg_basic' else 'extended'
        server = make_lvsg_gateway({0: ('mcd202', 100, module)}, start_time_s=0.5,
                                   stop_time_s=0.3)
        settings = {'family': 'lvsg', 'address': 1, 'gateway_input_register': 0,
                    'gateway_output_register': 100, 'lvsg_module': module}
        probe_of = (lambda: LvsgProbe(server, 1))
    else:
        raise ValueError(family)
    server.record_frames = True
    server.open_pty()
    server.start()
    return Rig(family, server, probe_of(), {**settings, 'poll_rate': 10.0, **device}, bus=bus)


class BusRig:
    """Several devices on one simulated line: their node configuration and motor probes."""

    def __init__(self, server, devices: Dict[str, Dict[str, Any]],
                 probes: Dict[str, MotorProbe], drives: Tuple[str, ...] = (), **bus: Any):
        self.server = server
        self.devices = devices
        self.probes = probes
        self.drives = drives
        self.bus = bus

    def bus_settings(self, **extra: Any) -> Dict[str, Any]:
        return {'port': self.server.pty_path, 'parity': 'N', 'timeout': 1.0,
                'diagnostics_period': 0.2, 'backoff_max': 1.0, **self.bus, **extra}

    def stop(self) -> None:
        self.server.stop()


def make_mixed_rig(**bus: Any) -> BusRig:
    """
    Return a served line with four devices: starter, conv, fan and mixer.

    An MCD 500 (starter, 20), an FC 51 (conv, 1), a VLT 6000 (fan, 2) and an MCD 202 behind
    a Profibus gateway (mixer, 5).
    """
    server = make_sim_server({20: 'mcd500', 1: 'fc51', 2: 'vlt6000'}, settings={
        'mcd': {'start_time_s': 0.5, 'stop_time_s': 0.3},
        'fc': {'ramp_up_s': 0.5, 'ramp_down_s': 0.3},
        'vlt': {'ramp_up_s': 0.5, 'ramp_down_s': 0.3}})
    gateway = make_lvsg_gateway({0: ('mcd202', 100, 'extended')}, start_time_s=0.5,
                                stop_time_s=0.3)
    server.devices[5] = gateway.devices[1]
    server.record_frames = True
    server.open_pty()
    server.start()
    devices = {
        'starter': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0},
        'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
                 'speed_reference': 50.0},
        'fan': {'family': 'vlt', 'model': 'vlt6000', 'address': 2, 'poll_rate': 10.0,
                'speed_reference': 50.0},
        'mixer': {'family': 'lvsg', 'address': 5, 'poll_rate': 10.0,
                  'gateway_input_register': 0, 'gateway_output_register': 100},
    }
    probes = {'starter': McdProbe(server, 20), 'conv': DriveProbe(server, 1),
              'fan': DriveProbe(server, 2), 'mixer': LvsgProbe(server, 5)}
    return BusRig(server, devices, probes, ('conv', 'fan'), **bus)


def parameter_value(value: Any) -> ParameterValue:
    """Return a ParameterValue of a bool, int, float or str."""
    kinds = {bool: ('PARAMETER_BOOL', 'bool_value'),
             int: ('PARAMETER_INTEGER', 'integer_value'),
             float: ('PARAMETER_DOUBLE', 'double_value'),
             str: ('PARAMETER_STRING', 'string_value')}
    kind, field = kinds[type(value)]
    return ParameterValue(type=getattr(ParameterType, kind), **{field: value})


def plain_value(value: ParameterValue) -> Any:
    """Return the Python value of a ParameterValue (None if not set)."""
    return {ParameterType.PARAMETER_BOOL: value.bool_value,
            ParameterType.PARAMETER_INTEGER: value.integer_value,
            ParameterType.PARAMETER_DOUBLE: value.double_value,
            ParameterType.PARAMETER_STRING: value.string_value}.get(value.type)


def call_service(client: RosClient, service, request, timeout_s: float = 15.0):
    """Call ``service`` (an rclpy client) and return its response."""
    assert service.wait_for_service(timeout_sec=timeout_s), f'no {service.srv_name}'
    future = service.call_async(request)
    assert client.spin_until(future.done, timeout_s), f'{service.srv_name} did not answer'
    return future.result()


def set_atomically(client: RosClient, values: List[Tuple[str, Any]]):
    """Set parameters of the node with SetParametersAtomically; return the result."""
    service = client.node.create_client(SetParametersAtomically,
                                        f'{NODE}/set_parameters_atomically')
    try:
        request = SetParametersAtomically.Request(parameters=[
            ParameterMsg(name=name, value=parameter_value(value)) for name, value in values])
        return call_service(client, service, request).result
    finally:
        client.node.destroy_client(service)


def get_parameters(client: RosClient, names: List[str]) -> Dict[str, Any]:
    """Return the node's values of ``names``."""
    service = client.node.create_client(GetParameters, f'{NODE}/get_parameters')
    try:
        response = call_service(client, service, GetParameters.Request(names=names))
        return {name: plain_value(value) for name, value in zip(names, response.values)}
    finally:
        client.node.destroy_client(service)


class Lifecycle:
    """ChangeState and GetState of the node (transitions by label: ros2/rclpy#1209)."""

    def __init__(self, client: RosClient):
        self.client = client
        self.change = client.node.create_client(ChangeState, f'{NODE}/change_state')
        self.get = client.node.create_client(GetState, f'{NODE}/get_state')

    def state(self) -> str:
        return call_service(self.client, self.get, GetState.Request()).current_state.label

    def begin(self, label: str):
        """Ask for a transition; return the future of its answer."""
        assert self.change.wait_for_service(timeout_sec=15.0)
        return self.change.call_async(ChangeState.Request(transition=Transition(label=label)))

    def transition(self, label: str, timeout_s: float = 20.0) -> bool:
        future = self.begin(label)
        assert self.client.spin_until(future.done, timeout_s), f'{label} did not answer'
        return future.result().success


def call_ok(client: RosClient, name: str, command: str, attempts: int = 3):
    """
    Call a stop-like command until acknowledged; return the last response.

    On a loaded machine a late reply to an earlier poll can arrive during the command's
    transaction and be taken for its answer (then "no acknowledgement"): call it again.
    Only for commands that may be repeated (stops, resets).
    """
    response = None
    for _ in range(attempts):
        response = client.call(name, command, timeout_s=30.0)
        if response.success or 'no acknowledgement' not in response.message:
            return response
        print(f'{name}/{command} again after: {response.message}')
    return response


def call_later(client: RosClient, name: str, command: str):
    """Send a Trigger call and return its future without waiting for the answer."""
    service = client.clients[(name, command)]
    assert service.wait_for_service(timeout_sec=15.0), f'no {name}/{command}'
    return service.call_async(Trigger.Request())


def start_behind_a_held_poll(client: RosClient, rig, hold):
    """
    Call start while ``hold`` (a HoldNext) keeps a poll of ``rig`` waiting for its reply.

    Returns the call's future once the call has reached the node and waits for the bus.
    """
    assert client.wait_state(rig.name, 'ready', READY_S)
    hold.arm()
    assert wait_for(hold.seen.is_set, 10.0)  # a poll waits for its reply
    start = call_later(client, rig.name, 'start')
    client.spin_until(lambda: False, 0.2)  # the call reaches the node, the bus is busy
    return start


def status_values(status: Optional[DiagnosticStatus]) -> Dict[str, str]:
    """Return the key/values of a DiagnosticStatus (empty for None)."""
    return {kv.key: kv.value for kv in status.values} if status is not None else {}


def diagnostics_seen(client: RosClient, name: str, predicate, timeout_s: float = 10.0,
                     since: int = 0) -> Optional[DiagnosticStatus]:
    """Spin until a /diagnostics status of ``name`` (from message ``since``) fits ``predicate``."""
    wanted = f'drive_bridge: {name}'
    found: List[DiagnosticStatus] = []

    def check() -> bool:
        for array in client.messages['/diagnostics'][since:]:
            for status in array.status:
                if status.name == wanted and predicate(status):
                    found.append(status)
                    return True
        return False

    client.spin_until(check, timeout_s)
    return found[0] if found else None


def level_is(level) -> Any:
    return lambda status: status.level == level


class Session:
    """The node on a rig and a client; on exit the client closes and the node gets SIGTERM."""

    def __init__(self, rig, path, restore_signals: bool = True, fresh: bool = False,
                 **bus: Any):
        self.rig = rig
        self.process = start_node(write_params(path, rig.bus_settings(**bus), rig.devices),
                                  restore_signals=restore_signals, fresh=fresh)
        self.client = RosClient(list(rig.devices), drives=list(rig.drives))
        self.closed = False
        self.code: Optional[int] = None
        self.output = ''
        self.exit_s = 0.0

    def close_client(self) -> None:
        if not self.closed:
            self.closed = True
            self.client.close()

    def signal(self, *numbers: int, between_s: float = 0.1, after_send=None,
               timeout_s: float = 20.0) -> Tuple[int, str]:
        """
        Close the client, send the signals ``between_s`` apart, wait for the exit.

        ``after_send`` runs right after the first signal. Returns (exit code, log).
        """
        self.close_client()
        for index, number in enumerate(numbers):
            if index:
                time.sleep(between_s)  # the stimulus's own timing, not a wait for an outcome
            self.process.send_signal(number)
            if index == 0 and after_send is not None:
                after_send()
        self.code, self.output, self.exit_s = wait_exit(self.process, timeout_s)
        return self.code, self.output

    def __enter__(self) -> 'Session':
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.close_client()
            if self.process.poll() is None:
                self.signal(signal.SIGTERM)
            else:
                self.code, self.output, _ = wait_exit(self.process, 1.0)
            print(self.output)
        finally:
            kill_quietly(self.process)
            self.rig.stop()


def wait_exit(process: subprocess.Popen, timeout_s: float = 20.0) -> Tuple[int, str, float]:
    """Wait for the node to exit (kill it after ``timeout_s``); return (code, log, seconds)."""
    started = time.monotonic()
    try:
        process.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGKILL)
        process.wait()
    return process.returncode, node_output(process), time.monotonic() - started


def clean_exit(code: int, output: str) -> bool:
    """Return whether the node exited 0 without a traceback."""
    return code == 0 and 'Traceback' not in output


def kill_quietly(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.kill()
        process.wait()


def sigterm_round(params: str, rig, chance: random.Random, index: int) -> str:
    """
    Run the node and SIGTERM it at a random moment; return '' or what went wrong.

    Every third round right after the node's first message (it may still be activating),
    every third with a start call in flight, the others once the device is ready; then a
    random pause of up to 0.5 s.
    """
    # exec'd: a SIGTERM soon after the start lands as it does on a node a user started
    process = start_node(params, restore_signals=True, fresh=True)
    client = RosClient(list(rig.devices), drives=list(rig.drives))
    problem = ''
    try:
        if index % 3:
            ready = client.wait_state(rig.name, 'ready', READY_S)
        else:
            ready = client.spin_until(lambda: client.values(rig.name, 'state'), READY_S)
        if not ready:
            problem = 'the node never published a state; '
        elif index % 3 == 2:
            call_later(client, rig.name, 'start')
        client.spin_until(lambda: False, chance.uniform(0.0, 0.5))
    finally:
        client.close()
    process.send_signal(signal.SIGTERM)
    code, output, took_s = wait_exit(process, 30.0)
    if problem or not clean_exit(code, output):
        return f'round {index}: {problem}exit {code} after {took_s:.2f} s:\n{output}'
    return ''
