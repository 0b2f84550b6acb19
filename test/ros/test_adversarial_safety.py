"""
Adversarial safety tests through the node: races, outages and monitor-only on every path.

Written by an independent tester against the invariants of the developers' guide ("Safety
first") and the ROS contract, beside the safety cases (test_safety_*.py), which they do not
repeat: a start and a stop queued in one gap, start/stop calls from several clients at once,
``allow_control`` switched off with a start queued or a stream of commands going, the
lifecycle ``shutdown`` and two Ctrl-C with a start in flight, a device that stops answering
and answers again, and a monitor-only node driven through every input it has. The motor is
read from the simulated device (what it received, what its model does), never from the
bridge.
"""

import random
import signal
import subprocess
import sys
import time
from typing import Dict, List, Tuple

from drive_bridge.sim.faults import FaultPlan
import fork_server
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import lean_node
from safety_helpers import (
    DriveProbe, frames_to, HoldNext, is_run_word, MCD_START, MCD_STOP, recorded, ReplyHold,
    wait_for, write_frames)
from safety_ros import (
    call_later, clean_exit, Lifecycle, make_rig, parameter_value, READY_S,
    Session, start_behind_a_held_poll)
from sensor_msgs.msg import JointState
from shared_rigs import on_rig
from std_srvs.srv import Trigger

SCALE = 20.0  # rad/s of a joint at 100 %
STORM_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def more_frames(rig, count: int, timeout_s: float = 20.0) -> bool:
    """Wait until the device got ``count`` more requests (polls go on meanwhile)."""
    unit = rig.probe.unit
    target = frames_to(rig.server, unit) + count
    return wait_for(lambda: frames_to(rig.server, unit) >= target, timeout_s)


def set_parameter_later(client, name: str, value):
    """Send a SetParameters request for one parameter; return its future."""
    assert client.parameters.wait_for_service(timeout_sec=15.0)
    request = SetParameters.Request(parameters=[
        ParameterMsg(name=name, value=parameter_value(value))])
    return client.parameters.call_async(request)


def answered_order(client, futures: Dict[str, object], timeout_s: float = 20.0) -> List[str]:
    """Spin until every future is done; return their names in the order their answers came."""
    order: List[str] = []
    for name, future in futures.items():
        future.add_done_callback(lambda _, name=name: order.append(name))
    assert client.spin_until(lambda: len(order) == len(futures), timeout_s), \
        f'unanswered: {[name for name in futures if name not in order]}'
    return order


def settled_moving(probe, timeout_s: float = 5.0) -> bool:
    """Return whether the motor turns once its ramp is over (stopped within ``timeout_s``)."""
    return not wait_for(lambda: not probe.moving(), timeout_s)


def joint_commands_publisher(client):
    """Return a publisher of ``~/joint_commands`` once the node's subscription matched it."""
    publisher = client.node.create_publisher(JointState, '/drive_bridge/joint_commands', 10)
    assert client.spin_until(lambda: publisher.get_subscription_count() > 0, 15.0)
    return publisher


def zero_first_stream(client, rig):
    """
    Stream ``rig``'s joint command at 100 Hz, zero for 0.3 s first (arms the automatic start).

    Returns the velocity to send (a one-item list to change) and the stream's timer.
    """
    publisher = joint_commands_publisher(client)
    velocity = [0.0]
    timer = client.node.create_timer(0.01, lambda: publisher.publish(JointState(
        name=[rig.name], velocity=[velocity[0]])))
    client.spin_until(lambda: False, 0.3)
    return velocity, timer


def started_then_in_hand_on(client, rig):
    """Start the starter through the node, then put it in Hand On: it refuses the network."""
    assert client.wait_state(rig.name, 'ready', READY_S)
    assert client.call(rig.name, 'start').success
    assert client.wait_state(rig.name, 'running', 10.0)
    with rig.server.lock:
        rig.probe.model.hand_on = True


# -- a start and a stop in one gap ----------------------------------------------------------
@pytest.mark.parametrize('family, stop_kind', [
    on_rig(family, family, stop_kind) for family, stop_kind in (
        ('mcd', 'stop'), ('fc', 'stop'), ('lvsg', 'stop'), ('mcd', 'quick_stop'),
        ('fc', 'quick_stop'), ('fc', 'coast_stop'), ('lvsg', 'quick_stop'))])
def test_stop_queued_behind_a_start_in_the_same_gap_wins(family, stop_kind, rigs):
    """
    A start, then a stop (``stop_kind``), both waiting while a poll holds the bus: still.

    The user asked to stop last. Whatever order the bridge executes them in, the motor's end
    must be the last command answered as succeeded, and that must be the stop: a start that
    a later stop superseded is no longer in force.
    """
    with rigs.session(family) as session:
        client, rig = session.client, session.rig
        hold = HoldNext(rig.probe.unit)
        rig.server.reply_hook = hold
        start = start_behind_a_held_poll(client, rig, hold)
        stop = call_later(client, rig.name, stop_kind)
        client.spin_until(lambda: False, 0.2)
        hold.release()
        order = answered_order(client, {'start': start, 'stop': stop})
        answers = {'start': start.result(), 'stop': stop.result()}
        print(f'{family} {stop_kind}: answered {order}: '
              f'{[(name, answers[name].success, answers[name].message) for name in order]}')
        moving = settled_moving(rig.probe)
        succeeded = [name for name in order if answers[name].success]
        assert succeeded, 'neither the start nor the stop succeeded'
        assert moving == (succeeded[-1] == 'start'), \
            f'the motor {"turns" if moving else "is still"}, the last success was ' \
            f'{succeeded[-1]}'
        assert not moving, 'the start asked first ran after the stop asked last'
        assert rig.probe.start_edges() <= 1


@pytest.mark.parametrize('target', ['starter', 'conv', 'mixer'])
@pytest.mark.xdist_group('rig_mixed')
def test_start_and_stop_queued_while_another_device_is_polled(target, rigs):
    """
    A four-device line: a poll of the fan holds the bus; a start then a stop for ``target``.

    The stop was asked last: the target ends still, with at most one start received; the
    other devices never got a start.
    """
    with rigs.mixed() as session:
        client, rig = session.client, session.rig
        hold = HoldNext(rig.probes['fan'].unit)
        rig.server.reply_hook = hold
        for name in rig.devices:
            assert client.wait_state(name, 'ready', READY_S), name
        hold.arm()
        assert wait_for(hold.seen.is_set, 10.0)  # the fan's poll waits for its reply
        start = call_later(client, target, 'start')
        client.spin_until(lambda: False, 0.1)
        stop = call_later(client, target, 'stop')
        client.spin_until(lambda: False, 0.1)
        hold.release()
        order = answered_order(client, {'start': start, 'stop': stop})
        answers = {'start': start.result(), 'stop': stop.result()}
        print(f'{target}: answered {order}: '
              f'{[(name, answers[name].success, answers[name].message) for name in order]}')
        probe = rig.probes[target]
        assert not settled_moving(probe), 'the start asked first ran after the stop asked last'
        assert probe.start_edges() <= 1
        for name, other in rig.probes.items():
            if name != target:
                assert other.start_edges() == 0, name


@pytest.mark.xdist_group('rig_mcd')
def test_start_stop_storm_from_three_clients_ends_as_the_last_success(rigs):
    """
    Three clients call start and stop at random, overlapping: the starter ends as asked.

    Bursts of one call per client, up to 100 ms apart. Judged from the starter: it received
    exactly the commands answered as succeeded (a failed one is never sent), and its final
    state is that of the last succeeded answer when that answer came clearly (50 ms, a start
    50 ms and the stop ramp) after the last one of the other kind.
    """
    chance = random.Random(7)
    with rigs.session('mcd') as session:
        client, rig = session.client, session.rig
        assert client.wait_state(rig.name, 'ready', READY_S)
        nodes = [lean_node(f'test_storm_{index}_{id(rig)}') for index in range(3)]
        executor = SingleThreadedExecutor()
        answers: List[Tuple[float, str, Trigger.Response]] = []
        futures = []
        try:
            services = []
            for node in nodes:
                executor.add_node(node)
                # Deep histories: every client's reply reader gets the replies to all three
                # clients; depth 10 (the services default) would drop some in a storm.
                pair = {command: node.create_client(Trigger, f'/{rig.name}/{command}',
                                                    qos_profile=STORM_QOS)
                        for command in ('start', 'stop')}
                for service in pair.values():
                    assert service.wait_for_service(timeout_sec=15.0)
                services.append(pair)
            # A client made just now can lose its first response while the node has not yet
            # discovered its reply reader (see ros_helpers.RosClient): there is no event for
            # that discovery, so the clients settle for a second before the storm.
            settle_until = time.monotonic() + 1.0
            while time.monotonic() < settle_until:
                executor.spin_once(timeout_sec=0.05)
            for burst in range(6):
                for pair in services:
                    command = chance.choice(('start', 'stop'))
                    future = pair[command].call_async(Trigger.Request())
                    future.add_done_callback(
                        lambda done, command=command: answers.append(
                            (time.monotonic(), command, done.result())))
                    futures.append(future)
                pause_until = time.monotonic() + chance.uniform(0.0, 0.1)
                while time.monotonic() < pause_until:  # the stimulus's own timing
                    executor.spin_once(timeout_sec=0.005)
            deadline = time.monotonic() + 30.0
            # Until every answer was also recorded: rclpy runs a future's done callbacks as
            # tasks of the executor, after the future itself is done (a storm's last answer
            # was once done but not yet recorded when the loop ended).
            while (not all(f.done() for f in futures) or len(answers) < len(futures)) and \
                    time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            assert all(f.done() for f in futures), \
                'calls left unanswered (burst, client): ' \
                f'{[divmod(i, 3) for i, f in enumerate(futures) if not f.done()]}'
        finally:
            executor.shutdown()
            for node in nodes:
                node.destroy_node()
        succeeded = [(at, command) for at, command, response in answers if response.success]
        print(f'{len(answers)} calls, answers: '
              f'{[(round(at - answers[0][0], 3), c, r.success) for at, c, r in answers]}')
        print(f'the starter received {rig.probe.commands()}')
        commands = rig.probe.commands()
        for command, code in (('start', MCD_START), ('stop', MCD_STOP)):
            succeeded_count = sum(1 for _, kind in succeeded if kind == command)
            assert commands.count(code) == succeeded_count, \
                f'the starter got {commands.count(code)} {command}s, {succeeded_count} ' \
                'answered as succeeded: a failed one was sent, or a success was not'
        assert succeeded
        last_at, last = succeeded[-1]
        others = [at for at, command in succeeded if command != last]
        moving = settled_moving(rig.probe)
        # The starter takes a start only when ready: one that reaches it during its soft stop
        # is acknowledged and has no effect (the simulated MCD 500 ends its stop ramp first),
        # so a last start is judged only when it came more than the stop ramp after the stop.
        ramp_s = rig.probe.model.config.stop_time_s if last == 'start' else 0.0
        if not others or last_at - others[-1] > ramp_s + 0.05:
            assert moving == (last == 'start'), \
                f'the starter {"turns" if moving else "is still"}; last success: {last}'
        else:
            print(f'last {last} and the other kind {last_at - others[-1]:.3f} s apart: '
                  'their order is not judged')


# -- allow_control switched off ---------------------------------------------------------------
@pytest.mark.parametrize('family', [on_rig(family, family) for family in ('mcd', 'fc', 'lvsg')])
def test_monitor_only_set_while_a_start_waits_for_the_bus(family, rigs):
    """
    A start waits behind a held poll; allow_control false comes meanwhile.

    Either the change is refused (a start is asked for), or it is accepted and the start
    queued before it must never reach the device: monitor-only writes nothing.
    """
    with rigs.session(family) as session:
        client, rig = session.client, session.rig
        hold = HoldNext(rig.probe.unit)
        rig.server.reply_hook = hold
        assert client.wait_state(rig.name, 'ready', READY_S)
        hold.arm()
        assert wait_for(hold.seen.is_set, 10.0)
        start = call_later(client, rig.name, 'start')
        client.spin_until(lambda: False, 0.2)
        change = set_parameter_later(client, f'{rig.name}.allow_control', False)
        changed = client.spin_until(change.done, 1.0)
        accepted_at = recorded(rig.server)
        hold.release()
        answered_order(client, {'start': start, 'change': change})
        result = change.result().results[0]
        response = start.result()
        print(f'{family}: allow_control false answered {"at once" if changed else "late"}: '
              f'{result.successful} {result.reason!r}; start: {response.success} '
              f'{response.message!r}')
        assert more_frames(rig, 20)
        if result.successful:
            late = write_frames(rig.server, rig.probe.unit, since=accepted_at)
            assert not late, f'written after allow_control false was accepted: ' \
                f'{[frame.hex() for frame in late]}'
            assert rig.probe.start_edges() == 0 and not rig.probe.moving()
            assert not response.success
        else:
            assert response.success or rig.probe.start_edges() == 0


def test_monitor_only_during_a_joint_command_stream_that_turns_nonzero(tmp_path):
    """
    auto_start joint commands at ~200/s switch from zero to nonzero as allow_control goes off.

    Either monitor-only is refused (the command started the drive first), or from its
    acceptance on nothing at all is written and the drive does not turn.
    """
    rig = make_rig('fc', velocity_scale=SCALE, command_mode='auto_start')
    with Session(rig, tmp_path / 'stream_monitor.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        publisher = joint_commands_publisher(client)
        velocity = [0.0]
        sent = [0]
        timer = client.node.create_timer(0.005, lambda: (publisher.publish(JointState(
            name=[rig.name], velocity=[velocity[0]])), sent.__setitem__(0, sent[0] + 1)))
        assert client.spin_until(lambda: sent[0] > 50, 10.0)
        velocity[0] = 5.0  # the next messages would start the drive
        change = set_parameter_later(client, f'{rig.name}.allow_control', False)
        assert client.spin_until(change.done, 10.0)
        accepted_at = recorded(rig.server)
        result = change.result().results[0]
        client.spin_until(lambda: False, 1.5)  # the stream goes on
        client.node.destroy_timer(timer)
        print(f'allow_control false: {result.successful} {result.reason!r}; {sent[0]} sent; '
              f'starts at the drive: {rig.probe.start_edges()}')
        if result.successful:
            # The simulator may record a frame sent before the change only after its answer
            # came here: judge from three requests on, as the runtime monitor-only case does.
            late = write_frames(rig.server, rig.probe.unit, since=accepted_at + 3)
            assert not late, f'written after allow_control false: {[f.hex() for f in late]}'
            assert not settled_moving(rig.probe)
        else:
            assert rig.probe.start_edges() == 1


# -- endings with a start in flight -----------------------------------------------------------
def start_on_the_wire(session, rig, hold):
    """Arm ``hold`` and call start; return the call once its request reached the device."""
    client = session.client
    assert client.wait_state(rig.name, 'ready', READY_S)
    hold.arm()
    start = call_later(client, rig.name, 'start')
    assert client.spin_until(hold.seen.is_set, 15.0), 'the start never reached the device'
    return start


@pytest.mark.parametrize('lost', [False, True], ids=['late', 'lost'])
@pytest.mark.parametrize('family', ['mcd', 'fc', 'lvsg'])
def test_lifecycle_shutdown_with_a_start_in_flight_stops_the_motor(family, lost, tmp_path):
    """The lifecycle 'shutdown' transition while a start is on the wire: the motor ends still."""
    rig = make_rig(family)
    hold = ReplyHold(rig.probe, drop=lost, extra_s=0.1)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'shutdown.yaml') as session:
        client = session.client
        start = start_on_the_wire(session, rig, hold)
        lifecycle = Lifecycle(client)
        change = lifecycle.begin('shutdown')
        hold.release()
        assert client.spin_until(change.done, 20.0), 'shutdown did not answer'
        print(f'{family}: shutdown {change.result().success}; start answered '
              f'{start.done() and start.result().message!r}')
        assert change.result().success
        assert lifecycle.state() == 'finalized'
        assert wait_for(rig.probe.stopped, 5.0), 'the lifecycle shutdown left the motor running'
        runs = rig.probe.run_writes()
        client.spin_until(lambda: False, 1.0)  # finalized: nothing more may be written
        assert rig.probe.run_writes() == runs
        assert rig.probe.start_edges() == 1
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    assert rig.probe.stopped()


@pytest.mark.parametrize('family', ['mcd', 'fc'])
def test_a_start_call_in_flight_at_the_lifecycle_shutdown_is_answered(family, tmp_path):
    """
    The contract: every call is answered once acknowledged or failed; also at shutdown.

    A start is on the wire (its reply 0.1 s late) when the lifecycle shutdown comes: its
    caller must get an answer (success or failure), not wait forever.
    """
    rig = make_rig(family)
    hold = ReplyHold(rig.probe, extra_s=0.1)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'unanswered.yaml') as session:
        client = session.client
        start = start_on_the_wire(session, rig, hold)
        change = Lifecycle(client).begin('shutdown')
        hold.release()
        assert client.spin_until(change.done, 20.0) and change.result().success
        answered = client.spin_until(start.done, 10.0)
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    assert 'InvalidHandle' not in output, output
    assert answered, 'the start call in flight at the lifecycle shutdown was never answered'


@pytest.mark.parametrize('family', ['mcd', 'fc', 'lvsg'])
def test_two_quick_ctrl_c_with_a_lost_start_in_flight_stop_the_motor(family, tmp_path):
    """Two SIGINTs 30 ms apart while a start's reply is being lost: stopped, exit 0, 1 start."""
    rig = make_rig(family)
    hold = ReplyHold(rig.probe, drop=True)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'ctrl_c.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        hold.arm()
        call_later(client, rig.name, 'start')
        assert client.spin_until(hold.seen.is_set, 15.0), 'the start never reached the device'
        code, output = session.signal(signal.SIGINT, signal.SIGINT, between_s=0.03,
                                      after_send=hold.release)
    print(f'{family}: exit {code} after {session.exit_s:.2f} s')
    assert clean_exit(code, output), output
    assert rig.probe.start_edges() == 1, 'the start whose reply was lost was repeated'
    assert wait_for(rig.probe.stopped, 5.0), 'the motor was left running'


@pytest.mark.parametrize('round_', range(4))
@pytest.mark.parametrize('family', ['mcd', 'fc'])
def test_exit_signal_right_after_a_start_call_on_a_slow_bus_ends_stopped(family, round_,
                                                                         tmp_path):
    """
    A start call, then SIGTERM or SIGINT 0-50 ms later, every reply 0.1 s late: ends still.

    The start may be in the node, queued for the bus or on the wire when the signal comes;
    whichever, the motor ends stopped (or never started) and got at most one start.
    """
    chance = random.Random(round_)
    number = (signal.SIGTERM, signal.SIGINT)[round_ % 2]
    rig = make_rig(family)
    with Session(rig, tmp_path / 'quick_signal.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        rig.server.faults.set_plan(FaultPlan(rate=1.0, kinds=('slow',), slow_s=0.1))
        start = call_later(client, rig.name, 'start')
        client.spin_until(start.done, chance.uniform(0.0, 0.05))
        code, output = session.signal(number)
    print(f'{family} {signal.Signals(number).name}: exit {code} after {session.exit_s:.2f} s;'
          f' starts at the device: {rig.probe.start_edges()}')
    assert clean_exit(code, output), output
    assert rig.probe.start_edges() <= 1
    assert wait_for(rig.probe.stopped, 5.0), 'the motor was left running'


def test_a_refused_stop_at_deactivate_is_remembered_through_activate(tmp_path):
    """Deactivate's stop refused (Hand On), then activate: the node's death still stops it."""
    rig = make_rig('mcd')
    server, probe = rig.server, rig.probe
    with Session(rig, tmp_path / 'reactivate.yaml') as session:
        client = session.client
        started_then_in_hand_on(client, rig)
        lifecycle = Lifecycle(client)
        assert lifecycle.transition('deactivate')
        with server.lock:
            probe.model.hand_on = False
        assert lifecycle.transition('activate')
        assert client.wait_state(rig.name, 'running', 15.0)
        assert probe.commands() == [MCD_START]
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    assert wait_for(lambda: not probe.moving(), 5.0), 'the motor runs on after SIGTERM'
    assert probe.commands() == [MCD_START, MCD_STOP]


@pytest.mark.parametrize('family', ['mcd', 'fc'])
def test_two_lifecycle_transitions_at_once_with_a_start_in_flight(family, tmp_path):
    """Deactivate and shutdown asked together while a start is on the wire: ends still."""
    rig = make_rig(family)
    hold = ReplyHold(rig.probe, extra_s=0.1)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'two_transitions.yaml') as session:
        client = session.client
        start = start_on_the_wire(session, rig, hold)
        lifecycle = Lifecycle(client)
        deactivate = lifecycle.begin('deactivate')
        shutdown = lifecycle.begin('shutdown')
        hold.release()
        order = answered_order(client, {'deactivate': deactivate, 'shutdown': shutdown}, 30.0)
        print(f'{family}: answered {order}: deactivate {deactivate.result().success}, '
              f'shutdown {shutdown.result().success}; start answered {start.done()} (the '
              f'defect above); state {lifecycle.state()}')
        assert session.process.poll() is None, 'the node died'
        assert wait_for(rig.probe.stopped, 5.0), 'the motor was left running'
        runs = rig.probe.run_writes()
        client.spin_until(lambda: False, 1.0)  # polls may have ended: finalized
        assert rig.probe.run_writes() == runs
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    assert rig.probe.start_edges() == 1 and rig.probe.stopped()


@pytest.mark.parametrize('ending', ['cleanup', 'cleanup_configure_activate', 'shutdown'])
def test_a_refused_stop_at_cleanup_or_shutdown_does_not_forget_the_motor(ending, tmp_path):
    """
    A started starter refuses network commands (Hand On) through deactivate and cleanup.

    Both stops fail (``shutdown``: the lifecycle shutdown from inactive instead of cleanup).
    The starter then takes network commands again: the motor still runs because of this
    node, so the node's death (SIGTERM) must stop it, also after the node was configured and
    activated again (``cleanup_configure_activate``). A node that forgets the run leaves a
    motor that ROS started and can no longer stop.
    """
    rig = make_rig('mcd')
    server, probe = rig.server, rig.probe
    with Session(rig, tmp_path / 'cleanup.yaml') as session:
        client = session.client
        started_then_in_hand_on(client, rig)
        lifecycle = Lifecycle(client)
        assert lifecycle.transition('deactivate')
        answered = lifecycle.transition(ending.split('_')[0])
        print(f'{ending}: answered {answered}; state {lifecycle.state()}')
        with server.lock:
            probe.model.hand_on = False  # network control again
        if ending == 'cleanup_configure_activate' and lifecycle.state() == 'unconfigured':
            assert lifecycle.transition('configure')
            assert lifecycle.transition('activate')
            assert client.wait_state(rig.name, 'running', 15.0)
        assert probe.moving() and probe.commands() == [MCD_START]
        code, output = session.signal(signal.SIGTERM)
    print(f'the starter received {probe.commands()}')
    assert clean_exit(code, output), output
    assert wait_for(lambda: not probe.moving(), 5.0), \
        'the motor started by the node runs on after its death: the node forgot it'
    assert probe.commands()[-1] == MCD_STOP


@pytest.mark.parametrize('topic', ['speed_reference', 'joint_commands'])
def test_deadman_stops_the_drive_on_a_slow_bus_when_commands_stop(topic, tmp_path):
    """
    reference_timeout 0.5 s, every reply 0.1 s late.

    Commands at 20 Hz keep the drive running; when they stop, a stop word reaches the drive
    within the timeout and one slow poll cycle (bound: timeout + 1 s), and it is never
    restarted by the keepalive.
    """
    rig = make_rig('fc', velocity_scale=SCALE, reference_timeout=0.5)
    with Session(rig, tmp_path / 'deadman.yaml') as session:
        client = session.client
        probe = rig.probe
        assert client.wait_state(rig.name, 'ready', READY_S)
        joints = joint_commands_publisher(client)
        last_sent = [0.0]

        def send() -> None:
            if topic == 'speed_reference':
                client.publish_reference(rig.name, 30.0)
            else:
                joints.publish(JointState(name=[rig.name], velocity=[6.0]))
            last_sent[0] = time.monotonic()

        timer = client.node.create_timer(0.05, send)
        assert client.spin_until(lambda: last_sent[0] > 0.0, 5.0)
        assert client.call(rig.name, 'start').success
        assert client.spin_until(probe.moving, 10.0)
        rig.server.faults.set_plan(FaultPlan(rate=1.0, kinds=('slow',), slow_s=0.1))
        client.spin_until(lambda: False, 1.0)  # running on the slow bus, commands flowing
        assert not probe.last_write_stops(), 'stopped while commands were flowing'
        client.node.destroy_timer(timer)
        stopped_at = last_sent[0]
        assert client.spin_until(probe.last_write_stops, 5.0), 'the deadman never stopped it'
        took_s = time.monotonic() - stopped_at
        print(f'{topic}: a stop word {took_s:.2f} s after the last command')
        assert took_s < 1.5
        assert wait_for(probe.stopped, 5.0)
        runs = probe.run_writes()
        assert more_frames(rig, 20)
        assert probe.run_writes() == runs and probe.start_edges() == 1


# -- an outage: the device stops answering, then answers again -------------------------------
OUTAGE_BUS = {'timeout': 0.2, 'retries': 0, 'offline_after': 2, 'backoff_max': 0.5}


@pytest.mark.parametrize('family', [
    on_rig(f'outage_{family}', family) for family in ('fc', 'vlt', 'lvsg')])
def test_cyclic_run_is_not_resumed_after_an_outage(family, rigs):
    """
    A running drive (or gateway) stops answering, then answers: it gets stop images only.

    A start asked for during the outage is answered as failed and never reaches the device
    afterwards.
    """
    with rigs.session(family, **OUTAGE_BUS) as session:
        client, rig = session.client, session.rig
        server, probe = rig.server, rig.probe
        assert client.wait_state(rig.name, 'ready', READY_S)
        assert client.call(rig.name, 'start').success
        assert wait_for(probe.moving, 10.0)
        with server.lock:
            server.silent_units.add(probe.unit)  # the device keeps its state, says nothing
        assert client.wait_state(rig.name, 'offline', 10.0)
        during = client.call(rig.name, 'start', timeout_s=15.0)
        print(f'start during the outage: {during.success} {during.message!r}')
        assert not during.success
        with server.lock:
            server.silent_units.discard(probe.unit)
            back_at = len(run_flags(probe))
        assert client.spin_until(lambda: client.state(rig.name) not in ('offline', ''), 15.0)
        assert more_frames(rig, 30)
        flags = run_flags(probe)[back_at:]
        print(f'{family}: {len(flags)} control writes after the outage, {sum(flags)} run')
        assert flags, 'no control image written after the outage'
        assert not any(flags), 'run images after the outage: the run was resumed unasked'
        assert wait_for(probe.stopped, 10.0), 'the run went on after the outage'
        assert probe.start_edges() == 1


def run_flags(probe) -> List[bool]:
    """Return, per control image the device received, whether it asks to run."""
    if isinstance(probe, DriveProbe):
        return [is_run_word(word) for word in probe.words()]
    return [image.fwd_run for image in probe.images()]


@pytest.mark.xdist_group('rig_outage_mcd')
def test_starter_stopped_locally_during_an_outage_is_not_restarted(rigs):
    """An MCD starter runs, goes silent, is stopped at its keypad, answers: no start again."""
    with rigs.session('mcd', **OUTAGE_BUS) as session:
        client, rig = session.client, session.rig
        server, probe = rig.server, rig.probe
        assert client.wait_state(rig.name, 'ready', READY_S)
        assert client.call(rig.name, 'start').success
        assert client.wait_state(rig.name, 'running', 10.0)
        with server.lock:
            server.silent_units.add(probe.unit)
        assert client.wait_state(rig.name, 'offline', 10.0)
        during = client.call(rig.name, 'start', timeout_s=15.0)
        assert not during.success, during.message
        with server.lock:  # the operator stops it at the starter
            probe.model.write_register(1, MCD_STOP, server.clock())
            server.silent_units.discard(probe.unit)
        assert client.wait_state(rig.name, 'ready', 15.0)
        assert more_frames(rig, 30)
        assert probe.commands() == [MCD_START, MCD_STOP], probe.commands()
        assert not probe.moving()


def mark(server, probe) -> Tuple[int, int]:
    """Return the control words the drive got so far and the requests it got (a mark)."""
    return len(probe.words()), frames_to(server, probe.unit)


def run_flags_since(client, server, probe, since: Tuple[int, int],
                    requests: int = 40) -> List[bool]:
    """Spin until ``requests`` more reached the drive since ``since``; return run flags."""
    words_at, frames_at = since
    assert client.spin_until(lambda: frames_to(server, probe.unit) > frames_at + requests,
                             20.0)
    return [is_run_word(word) for word in probe.words()[words_at:]]


def zero_and_back_starts(client, probe, velocity: List[float], timer) -> None:
    """Send zero, then 5 rad/s again (a new request): wait until the drive turns."""
    velocity[0] = 0.0
    client.spin_until(lambda: False, 0.3)
    velocity[0] = 5.0
    assert client.spin_until(probe.moving, 15.0)
    client.node.destroy_timer(timer)


def test_auto_start_stream_does_not_restart_a_drive_after_an_outage(tmp_path):
    """
    auto_start joint commands keep asking 5 rad/s through an outage: no restart after it.

    The outage ended the run (the drive gets the stop image when it answers again); as
    after a deactivate or a trip, the automatic start waits for a zero command and a new
    nonzero one, so the drive stays still until then.
    """
    rig = make_rig('fc', velocity_scale=SCALE, command_mode='auto_start')
    server, probe = rig.server, rig.probe
    with Session(rig, tmp_path / 'outage_auto.yaml', **OUTAGE_BUS) as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        velocity, timer = zero_first_stream(client, rig)
        velocity[0] = 5.0
        assert client.spin_until(probe.moving, 15.0), 'the nonzero command did not start it'
        with server.lock:
            server.silent_units.add(probe.unit)
        assert client.wait_state(rig.name, 'offline', 10.0)
        with server.lock:
            server.silent_units.discard(probe.unit)
            back = mark(server, probe)
        assert client.spin_until(lambda: client.state(rig.name) not in ('offline', ''), 15.0)
        flags = run_flags_since(client, server, probe, back)
        print(f'{len(flags)} control words after the outage, {sum(flags)} run; starts: '
              f'{probe.start_edges()}')
        assert not any(flags), 'the stream restarted the drive after the outage'
        assert probe.start_edges() == 1
        assert client.spin_until(probe.stopped, 10.0)
        zero_and_back_starts(client, probe, velocity, timer)
        assert probe.start_edges() == 2


def test_auto_start_stream_does_not_start_a_drive_when_control_returns(tmp_path):
    """
    auto_start, armed; allow_control false at runtime; the stream turns nonzero, refused.

    When control comes back the nonzero command is one that was already there: it starts
    nothing (found by an adversarial probe: the drive started 19 ms after control
    returned). Zero and back is a new request, and starts it.
    """
    rig = make_rig('fc', velocity_scale=SCALE, command_mode='auto_start')
    server, probe = rig.server, rig.probe
    with Session(rig, tmp_path / 'control_back_auto.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        velocity, timer = zero_first_stream(client, rig)
        assert client.set_parameter(f'{rig.name}.allow_control', False).successful
        velocity[0] = 5.0  # refused while monitor-only (the stream goes on while spinning)
        polled = frames_to(server, probe.unit) + 10
        assert client.spin_until(lambda: frames_to(server, probe.unit) > polled, 20.0)
        assert client.set_parameter(f'{rig.name}.allow_control', True).successful
        flags = run_flags_since(client, server, probe, mark(server, probe))
        print(f'{len(flags)} control words after control came back, {sum(flags)} run; '
              f'starts: {probe.start_edges()}')
        assert not any(flags) and probe.start_edges() == 0, \
            'a command that was there before control came back started the drive'
        assert not probe.moving()
        zero_and_back_starts(client, probe, velocity, timer)
        assert probe.start_edges() == 1


def test_auto_start_whose_reply_was_lost_is_not_repeated_by_the_stream(tmp_path):
    """
    auto_start: the start a nonzero joint command sends loses its reply; the stream goes on.

    The start may have run, so it is never sent again while the command stays nonzero; the
    drive ends stopped (a cyclic device's unconfirmed run gets the stop image).
    """
    rig = make_rig('fc', velocity_scale=SCALE, command_mode='auto_start')
    probe = rig.probe
    hold = ReplyHold(probe, drop=True, wait_release=False)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'auto_lost.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        velocity, timer = zero_first_stream(client, rig)
        hold.arm()
        velocity[0] = 5.0
        assert client.spin_until(hold.seen.is_set, 10.0), 'the stream sent no start'
        assert client.spin_until(probe.last_write_stops, 10.0), 'no stop image after it'
        assert more_frames(rig, 40)
        client.node.destroy_timer(timer)
        print(f'starts {probe.start_edges()}, run writes {probe.run_writes()}')
        assert probe.start_edges() == 1, 'the stream repeated a start whose reply was lost'
        assert probe.run_writes() == 1
        assert wait_for(probe.stopped, 10.0)


def mcd_start_frames(server, unit: int) -> int:
    """Return how many recorded writes to ``unit`` carry an MCD start (answered or not)."""
    count = 0
    for frame in write_frames(server, unit):
        if frame[1] == 0x06 and frame[2:6] == bytes([0, 1, 0, MCD_START]):
            count += 1
        elif frame[1] == 0x10 and frame[2:4] == bytes([0, 1]) and \
                frame[7:9] == bytes([0, MCD_START]):
            count += 1
    return count


@pytest.mark.parametrize('round_', range(3))
@pytest.mark.parametrize('family, when', [
    *(on_rig(f'outage_{family}', family, 'offline') for family in ('mcd', 'fc')),
    *((family, 'just_silent') for family in ('mcd', 'fc'))])
def test_start_asked_during_an_outage_as_the_device_comes_back(
        family, when, round_, rigs, tmp_path):
    """
    A start asked for in an outage; the device answers again 0-0.6 s later.

    ``offline``: the node knows the device is offline; ``just_silent``: the device has just
    gone silent, the node does not know yet (the start goes out and gets no reply; the
    silent device does not execute it). A start answered as failed never reaches the device
    later, and none is sent twice.

    ``just_silent`` runs on a node of its own: on a shared node its timing changed (a start
    of round 1 on the FC 51 reached the device after its silence, and its acknowledgement was
    refused as one that could be owed to an earlier write: "may or may not have been
    executed"), which is not the case this test describes.
    """
    chance = random.Random(10 + round_)
    if when == 'offline':
        node = rigs.session(family, **OUTAGE_BUS)
    else:
        node = rigs.fresh(make_rig(family), tmp_path / 'comeback.yaml', **OUTAGE_BUS)
    with node as session:
        client, rig = session.client, session.rig
        server, probe = rig.server, rig.probe
        assert client.wait_state(rig.name, 'ready', READY_S)
        with server.lock:
            server.silent_units.add(probe.unit)
        if when == 'offline':
            assert client.wait_state(rig.name, 'offline', 10.0)
        start = call_later(client, rig.name, 'start')
        client.spin_until(start.done, chance.uniform(0.0, 0.6))
        with server.lock:
            server.silent_units.discard(probe.unit)
        assert client.spin_until(start.done, 20.0), 'the start was never answered'
        response = start.result()
        assert client.spin_until(lambda: client.state(rig.name) not in ('offline', ''), 15.0)
        assert more_frames(rig, 30)
        print(f'{family} {when}: start {response.success} {response.message!r}; starts '
              f'executed by the device: {probe.start_edges()}')
        if family == 'mcd':
            assert mcd_start_frames(server, probe.unit) <= 1, 'a start was sent twice'
        if response.success:
            assert probe.start_edges() == 1
        else:
            assert probe.start_edges() == 0, 'a start answered as failed reached the device'
            assert probe.run_writes() == 0 and not probe.moving()


def test_a_start_refused_as_monitor_only_is_not_sent_when_control_returns(tmp_path):
    """Monitor-only, start refused, allow_control back to true: still no run image written."""
    rig = make_rig('fc')
    with Session(rig, tmp_path / 'control_back.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        assert client.set_parameter(f'{rig.name}.allow_control', False).successful
        refused = client.call(rig.name, 'start')
        assert not refused.success, refused.message
        client.publish_reference(rig.name, 40.0)
        assert client.set_parameter(f'{rig.name}.allow_control', True).successful
        assert more_frames(rig, 30)
        assert rig.probe.run_writes() == 0, 'the refused start was sent when control returned'
        assert not rig.probe.moving()
        assert client.call(rig.name, 'start').success  # control is back: a new start runs
        assert wait_for(rig.probe.moving, 10.0)
        assert rig.probe.start_edges() == 1


# -- monitor-only: every input ---------------------------------------------------------------
def test_monitor_only_drive_gets_nothing_from_any_input(tmp_path):
    """
    allow_control false: services, topics, parameters, lifecycle, a trip and SIGTERM.

    A drive with a configured comms timeout (a set-up write) and a joint (the node refuses
    auto_start with monitor-only): not one request that writes reaches it, from start-up to
    exit.
    """
    rig = make_rig('fc', allow_control=False, speed_reference=0.0, velocity_scale=SCALE,
                   comms_timeout=15.5, comms_timeout_function=2, reference_timeout=0.5)
    server, probe = rig.server, rig.probe
    with Session(rig, tmp_path / 'monitor_all.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        for command in ('start', 'stop', 'quick_stop', 'coast_stop', 'reset'):
            response = client.call(rig.name, command)
            print(f'{command}: {response.success} {response.message!r}')
            assert not response.success or command in ('stop', 'quick_stop', 'coast_stop'), \
                command
        joints = joint_commands_publisher(client)
        for index in range(20):
            joints.publish(JointState(name=[rig.name], velocity=[5.0]))
            client.publish_reference(rig.name, 30.0)
            client.spin_until(lambda: False, 0.02)
        for name, value in (('speed_reference', 60.0), ('reference_timeout', 0.0),
                            ('allow_control', False)):
            result = client.set_parameter(f'{rig.name}.{name}', value)
            print(f'{name}={value}: {result.successful} {result.reason!r}')
        trip_refused_reset_and_lifecycle(session, rig, 5)
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    written = write_frames(server, probe.unit)
    assert not written, f'a monitor-only drive got writes: {[f.hex() for f in written]}'
    assert probe.words() == [] and not probe.moving()


def trip_refused_reset_and_lifecycle(session, rig, trip_code: int) -> None:
    """Trip the device by itself, check a reset call is refused; deactivate and activate."""
    client, server, probe = session.client, rig.server, rig.probe
    with server.lock:
        probe.model.trip(trip_code, server.clock())
    assert client.wait_state(rig.name, 'tripped', 10.0)
    assert not client.call(rig.name, 'reset').success
    lifecycle = Lifecycle(client)
    assert lifecycle.transition('deactivate')
    assert lifecycle.transition('activate')
    assert more_frames(rig, 20)


def ctl(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess:
    """Run drive_bridge_ctl to its end, as a user does, for the node /drive_bridge."""
    return fork_server.run([sys.executable, '-m', 'drive_bridge.ros.ctl.cli', *args],
                           capture_output=True, text=True, timeout=timeout_s,
                           stdin=subprocess.DEVNULL)


def test_monitor_only_drive_gets_nothing_from_the_cli(tmp_path):
    """allow_control false: drive_bridge_ctl calls, references, a stream, params, lifecycle."""
    rig = make_rig('fc', allow_control=False, speed_reference=0.0)
    server, probe = rig.server, rig.probe
    with Session(rig, tmp_path / 'monitor_cli.yaml') as session:
        assert session.client.wait_state(rig.name, 'ready', READY_S)
        outcomes = [ctl('call', f'{rig.name}/{command}')
                    for command in ('start', 'stop', 'coast_stop', 'reset')]
        outcomes.append(ctl('reference', rig.name, '30'))
        outcomes.append(ctl('param', 'set', f'{rig.name}.speed_reference', '40'))
        stream = fork_server.ForkedPopen(
            [sys.executable, '-m', 'drive_bridge.ros.ctl.cli', 'reference', rig.name, '30',
             '--rate', '50'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            preexec_fn=fork_server.default_signals)
        assert more_frames(rig, 20)  # the stream goes on meanwhile
        stream.send_signal(signal.SIGINT)
        stream.communicate(timeout=30)
        outcomes.append(ctl('lifecycle', 'set', 'deactivate'))
        outcomes.append(ctl('lifecycle', 'set', 'activate'))
        for outcome in outcomes:
            print(f'{outcome.args[3:]}: exit {outcome.returncode}: '
                  f'{(outcome.stdout + outcome.stderr).strip()!r}')
        assert session.client.wait_state(rig.name, 'ready', 15.0)
        assert more_frames(rig, 10)
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    written = write_frames(server, probe.unit)
    assert not written, f'the CLI got writes to a monitor-only drive: ' \
        f'{[f.hex() for f in written]}'
    assert probe.words() == [] and not probe.moving()


@pytest.mark.parametrize('family', ['mcd', 'lvsg'])
def test_monitor_only_starter_gets_nothing_from_any_input(family, tmp_path):
    """allow_control false on a starter: every service, deactivate/activate, a trip, SIGTERM."""
    rig = make_rig(family, allow_control=False)
    server, probe = rig.server, rig.probe
    with Session(rig, tmp_path / 'monitor_starter.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        for command in ('start', 'stop', 'quick_stop', 'reset'):
            response = client.call(rig.name, command)
            print(f'{command}: {response.success} {response.message!r}')
        trip_refused_reset_and_lifecycle(session, rig, 3)
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    written = write_frames(server, probe.unit)
    assert not written, f'a monitor-only starter got writes: {[f.hex() for f in written]}'
    assert probe.start_edges() == 0
