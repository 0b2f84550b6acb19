"""
Safety cases 5 and 6 through the node: monitor-only at runtime, refused atomic parameter sets.

What was written is read from the simulated line (the recorded request frames) and the
device's own record, never from the bridge.
"""

import time

import pytest
from safety_helpers import frames_to, MCD_START, MCD_STOP, recorded, ReplyHold, wait_for, \
    write_frames
from safety_ros import (
    call_later, call_ok, get_parameters, make_rig, READY_S, Session, set_atomically)
from shared_rigs import on_rig


def more_frames(rig, count: int, timeout_s: float = 20.0) -> bool:
    """Wait until the device got ``count`` more requests (polls go on meanwhile)."""
    unit = rig.probe.unit
    target = frames_to(rig.server, unit) + count
    return wait_for(lambda: frames_to(rig.server, unit) >= target, timeout_s)


# -- case 5: runtime allow_control false on a running motor ---------------------------------
@pytest.mark.parametrize('family', [on_rig(family, family) for family in ('fc', 'mcd', 'lvsg')])
def test_monitor_only_refused_while_running_then_nothing_written(family, rigs):
    """Case 5: allow_control false refused while a run is held; after a stop, no writes."""
    with rigs.session(family) as session:
        client, rig = session.client, session.rig
        name = rig.name
        assert client.wait_state(name, 'ready', READY_S)
        assert client.call(name, 'start').success
        assert client.wait_state(name, 'running', 10.0)
        result = client.set_parameter(f'{name}.allow_control', False)
        assert not result.successful
        assert f'stop {name} first' in result.reason, result.reason
        print(f'refused: {result.reason}')
        assert get_parameters(client, [f'{name}.allow_control']) == {
            f'{name}.allow_control': True}
        runs = rig.probe.run_writes()
        assert more_frames(rig, 20)
        assert rig.probe.moving(), 'the run ended when monitor-only was refused'
        if family != 'mcd':  # the keepalive still carries the run
            assert rig.probe.run_writes() > runs
        assert call_ok(client, name, 'stop').success
        assert wait_for(rig.probe.stopped, 10.0)
        result = client.set_parameter(f'{name}.allow_control', False)
        assert result.successful, result.reason
        # The simulator runs in this process and may record a frame the node sent before
        # the change only after the answer came here: judge from three requests on.
        assert more_frames(rig, 3)
        accepted_at = recorded(rig.server)
        for percent in (10.0, 20.0, 30.0):  # references are not written either
            if rig.drives:
                client.publish_reference(name, percent)
            assert more_frames(rig, 10)
        assert more_frames(rig, 10)
        refused = client.call(name, 'start')
        assert not refused.success and 'monitor only' in refused.message
        assert more_frames(rig, 10)
        late = write_frames(rig.server, rig.probe.unit, since=accepted_at)
        assert not late, f'written after allow_control false: {[f.hex() for f in late]}'
        assert rig.probe.start_edges() == 1


def test_monitor_only_refused_while_a_start_may_have_run(tmp_path):
    """Case 5: a start in flight, then one without reply: monitor-only refused both times."""
    rig = make_rig('mcd')
    hold = ReplyHold(rig.probe, drop=False, extra_s=0.0)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'monitor.yaml') as session:
        client = session.client
        name = rig.name
        assert client.wait_state(name, 'ready', READY_S)
        hold.arm()
        start = call_later(client, name, 'start')
        assert client.spin_until(hold.seen.is_set, 15.0)
        in_flight = client.set_parameter(f'{name}.allow_control', False)
        hold.release()
        assert not in_flight.successful, 'monitor-only accepted with a start on the wire'
        assert client.spin_until(start.done, 15.0)
        assert call_ok(client, name, 'stop').success
        assert wait_for(lambda: not rig.probe.moving(), 10.0)
        hold.drop, hold.wait_release = True, False
        hold.arm()
        assert not client.call(name, 'start').success  # executed, reply lost
        lost = client.set_parameter(f'{name}.allow_control', False)
        assert not lost.successful and f'stop {name} first' in lost.reason, lost.reason
        assert call_ok(client, name, 'stop').success
        commands = rig.probe.commands()
        assert commands.count(MCD_START) == 2 and commands[-1] == MCD_STOP, commands


# -- case 6: a refused atomic parameter set ------------------------------------------------
BAD_COMPANIONS = [('motor.poll_rate', 'x'), ('motor.poll_rate', 500.0),
                  ('motor.address', 30), ('motor.current_scale', 0.5),
                  ('motor.no_such_setting', 1.0), ('motor.stop_on_shutdown', 'yes')]


@pytest.fixture(scope='class')
def monitor_only(tmp_path_factory):
    """Yield a node with one monitor-only MCD 500 (motor), for the tests of one class."""
    rig = make_rig('mcd', allow_control=False)
    with Session(rig, tmp_path_factory.mktemp('atomic') / 'atomic.yaml') as session:
        assert session.client.wait_state(rig.name, 'ready', READY_S)
        yield session


class TestRefusedAtomicSet:
    """One monitor-only node (class scope: it must be gone before the next node starts)."""

    @pytest.mark.parametrize('bad', BAD_COMPANIONS, ids=lambda bad: f'{bad[0]}={bad[1]!r}')
    def test_refused_atomic_set_does_not_enable_control(self, monitor_only, bad):
        """Case 6: [allow_control=true, a bad value] refused as a whole: still monitor only."""
        session = monitor_only
        client, rig = session.client, session.rig
        result = set_atomically(client, [('motor.allow_control', True), bad])
        assert not result.successful
        print(f'refused: {result.reason}')
        assert get_parameters(client, ['motor.allow_control']) == {
            'motor.allow_control': False}
        response = client.call('motor', 'start')
        assert not response.success and 'monitor only' in response.message, response.message
        assert more_frames(rig, 5)
        assert write_frames(rig.server, rig.probe.unit) == []
        assert rig.probe.commands() == []


def polls_take_s(rig, count: int = 4) -> float:
    """Return the seconds the device takes to get ``count`` more polls (one request each)."""
    started = time.monotonic()
    assert more_frames(rig, count, timeout_s=30.0)
    return time.monotonic() - started


def test_refused_atomic_set_leaves_the_poll_rate(tmp_path):
    """Case 6: [poll_rate=20, allow_control='x'] refused as a whole: still 1 poll a second."""
    rig = make_rig('mcd', poll_rate=1.0)
    with Session(rig, tmp_path / 'rate.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        for bad in (('motor.allow_control', 'x'), ('motor.reference_timeout', 1.0),
                    ('motor.poll_rate', 'fast')):
            result = set_atomically(client, [('motor.poll_rate', 20.0), bad])
            assert not result.successful, bad
            assert get_parameters(client, ['motor.poll_rate']) == {'motor.poll_rate': 1.0}
            slow_s = polls_take_s(rig)
            print(f'{bad}: refused ({result.reason}); 4 polls took {slow_s:.2f} s')
            assert slow_s > 2.0, f'the refused poll_rate took effect on the bus ({bad})'
        assert set_atomically(client, [('motor.poll_rate', 20.0)]).successful
        fast_s = polls_take_s(rig, 40)  # the measure tells the rates apart: 40 s at 1 Hz
        print(f'poll_rate 20 accepted: 40 polls took {fast_s:.2f} s')
        assert fast_s < 10.0
