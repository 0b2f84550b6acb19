"""When a device is due after a poll (schedule_next): its rate holds however late polls begin."""

from drive_bridge.bus.device import DeviceHealth
from hypothesis import given, HealthCheck, settings, strategies as st

PERIOD_S = 0.05  # 20 Hz

lateness_s = st.lists(st.one_of(st.just(0.0), st.floats(0.0, 0.2), st.floats(0.0, 3.0)),
                      min_size=1, max_size=60)


def begin_times(lateness: list, poll_s: float = 0.004) -> list:
    """Begin one poll after another, each ``lateness`` after it may begin (a busy machine)."""
    health = DeviceHealth(now_s=0.0)
    begun = []
    for late_s in lateness:
        earliest_s = max(health.next_due_s, begun[-1] + poll_s if begun else 0.0)
        now_s = earliest_s + late_s
        health.schedule_next(PERIOD_S, now_s)
        begun.append(now_s)
    return begun


@settings(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(lateness_s, st.floats(0.0, 2.0))
def test_polls_begun_in_any_window_are_at_most_its_periods_plus_two(lateness, window_s):
    """
    Begin at most W / P + 2 polls in any window W, however late they begin.

    Due times are a period apart at least, so a window holds at most W / P + 1 of them, and
    at most one poll due before it that began late (test_joints_node counts on this).
    """
    begun = begin_times(lateness)
    for start_s in begun:
        inside = [t for t in begun if start_s <= t <= start_s + window_s]
        assert len(inside) <= int(window_s / PERIOD_S + 1e-9) + 2, (window_s, inside)


def test_after_a_stall_one_poll_catches_up_then_the_rate_holds():
    """
    Catch up with one poll after a stall, not with a burst.

    A poll begun three periods late makes the device due at once (never in the past): one
    more poll follows it right away, then the period again; the polls the stall missed are
    not made up.
    """
    begun = begin_times([0.0, 0.0, 0.15, 0.0, 0.0, 0.0])
    gaps = [round(b - a, 3) for a, b in zip(begun, begun[1:])]
    assert gaps == [0.05, 0.2, 0.004, 0.046, 0.05]
