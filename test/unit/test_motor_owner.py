"""The motor-state owner, event by event: the safety model's transition table."""

from drive_bridge.bus.motor import Motion, MotorOwner, SETTLE_S
from drive_bridge.devices.contracts import DeviceReading
from drive_bridge.errors import CommandRefused
from drive_bridge.protocol.commands import Command
import pytest

START, STOP, QUICK, COAST, RESET = (Command.START, Command.STOP, Command.QUICK_STOP,
                                    Command.COAST_STOP, Command.RESET)


def owner(cyclic=True, **kwargs):
    return MotorOwner('conv', cyclic=cyclic, **kwargs)


def started(cyclic=True):
    motor = owner(cyclic)
    motor.sending(START)
    motor.acknowledged(START)
    return motor


def reading(state):
    return DeviceReading(state=state, status_word=0)


def test_nothing_is_carried_before_a_command_and_the_run_image_only_after_an_ack():
    motor = owner()
    assert motor.steady is None and motor.motion is Motion.IDLE and not motor.holds_run
    motor.sending(START)
    assert motor.steady is None  # on the wire: not yet in force
    assert motor.motion is Motion.MAY_RUN and motor.holds_run
    motor.acknowledged(START)
    assert motor.steady is START and motor.motion is Motion.RUNNING


@pytest.mark.parametrize('cyclic', [True, False])
def test_a_start_without_reply_may_run_and_is_never_repeated(cyclic):
    motor = owner(cyclic)
    motor.sending(START)
    motor.unanswered(START, Motion.IDLE, now_s=0.0)
    assert motor.motion is Motion.MAY_RUN and motor.holds_run
    assert motor.steady is (STOP if cyclic else None)  # a cyclic device gets the stop image
    assert 'may be running' in motor.describe()


def test_a_refused_start_leaves_things_as_they_were():
    motor = owner()
    motor.sending(STOP)
    motor.acknowledged(STOP)
    motor.sending(START)
    motor.refused(START, Motion.IDLE)
    assert motor.motion is Motion.IDLE and motor.steady is STOP and not motor.holds_run


@pytest.mark.parametrize('stop', [STOP, QUICK, COAST])
def test_a_stop_takes_over_the_image_when_it_is_sent_whatever_its_answer(stop):
    motor = started()
    motor.sending(stop)
    assert motor.steady is stop  # from now on, even if the reply is lost
    motor.unanswered(stop, Motion.RUNNING, now_s=0.0)
    assert motor.steady is stop and motor.motion is Motion.MAY_RUN
    motor.sending(stop)
    motor.acknowledged(stop)
    assert motor.motion is Motion.IDLE and not motor.holds_run


def test_an_mcd_start_then_stop_holds_nothing_afterwards():
    motor = started(cyclic=False)
    assert motor.holds_run and motor.steady is None  # nothing cyclic on an MCD
    motor.sending(STOP)
    motor.acknowledged(STOP)
    assert not motor.holds_run
    motor.set_allow_control(False)  # possible again once stopped


def test_a_reset_leaves_a_stop_image_and_never_restarts():
    motor = started()
    motor.sending(RESET)
    assert motor.steady is STOP
    motor.unanswered(RESET, Motion.RUNNING, now_s=0.0)
    assert motor.steady is STOP and motor.motion is Motion.MAY_RUN
    quick = owner()
    quick.sending(QUICK)
    quick.acknowledged(QUICK)
    quick.sending(RESET)
    assert quick.steady is QUICK  # a stop in force stays what it was


def test_a_trip_ends_the_run():
    motor = started()
    notice = motor.on_reading(reading('tripped'), polled_at_s=0.0)
    assert motor.steady is STOP and motor.motion is Motion.IDLE
    assert 'the run command is ended' in notice


def test_offline_replaces_the_run_image_by_a_stop_and_says_so_when_back():
    motor = started()
    motor.on_offline(now_s=0.0)
    assert motor.steady is STOP and motor.motion is Motion.MAY_RUN
    assert 'the run is not resumed' in motor.on_online(now_s=1.0)
    assert motor.on_online(now_s=2.0) is None  # said once
    idle = owner()
    idle.on_offline(now_s=0.0)
    assert idle.steady is None and idle.on_online(now_s=1.0) is None  # nothing held: nothing


def test_may_run_is_settled_by_a_stopped_state_read_late_enough():
    motor = owner(cyclic=False)
    motor.sending(START)
    motor.unanswered(START, Motion.IDLE, now_s=10.0)
    motor.on_reading(reading('ready'), polled_at_s=10.0 + SETTLE_S / 2)
    assert motor.motion is Motion.MAY_RUN  # too early: a start may not show yet
    motor.on_reading(reading('running'), polled_at_s=10.0 + SETTLE_S * 2)
    assert motor.motion is Motion.MAY_RUN
    motor.on_reading(reading('ready'), polled_at_s=10.0 + SETTLE_S * 2)
    assert motor.motion is Motion.IDLE


def test_monitor_only_is_refused_while_a_run_is_held_and_then_writes_nothing():
    motor = started()
    with pytest.raises(CommandRefused, match='stop conv first'):
        motor.set_allow_control(False)
    assert motor.allow_control
    motor.sending(STOP)
    motor.acknowledged(STOP)
    motor.set_allow_control(False)
    assert motor.steady is None and not motor.writes_allowed


def test_admission_stops_always_while_a_run_is_held_else_control_and_commands_enabled():
    motor = started()
    motor.admit(STOP, commands_enabled=False)  # inactive node: a stop still goes
    with pytest.raises(CommandRefused, match='commands are disabled'):
        motor.admit(START, commands_enabled=False)
    idle = owner(allow_control=False)
    with pytest.raises(CommandRefused, match='monitor only'):
        idle.admit(STOP, commands_enabled=True)


def test_release_stops_carrying_the_image():
    motor = started()
    motor.release('stop_on_shutdown is false', now_s=0.0)
    assert motor.steady is None and motor.motion is Motion.MAY_RUN and motor.holds_run
