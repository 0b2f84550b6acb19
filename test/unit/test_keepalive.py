"""The keepalive rule: the longest gap between two polls of a drive, and what is refused."""

from drive_bridge import config
from drive_bridge.bus.keepalive import keepalive_gap, LineTimes, PollLoad, round_up
from drive_bridge.errors import ConfigError
import pytest

# Round numbers: an answered transaction 0.1 s, a failed one 0.5 s.
TIMES = LineTimes(answered_s=0.1, failed_s=0.5, retries=2, offline_after=3,
                  backoff_initial_s=1.0)
DRIVE = PollLoad('drive', 0.2, transactions=1, writes=1)


def test_a_drive_alone_waits_one_period_when_its_polls_fit():
    times = LineTimes(0.01, 0.5, retries=0, offline_after=3)
    gap = keepalive_gap('drive', [DRIVE], times)
    assert gap.gap_s == pytest.approx(0.2)
    assert gap.explain() == 'its poll period 0.20 s'


def test_its_own_lost_reads_stretch_its_poll():
    # 1 answered + min(retries 2, offline_after 3 - 1) = 2 lost reads: 0.1 + 1.0
    gap = keepalive_gap('drive', [DRIVE], TIMES)
    assert gap.gap_s == pytest.approx(1.1)
    assert gap.parts[0][0] == 'its own poll with 2 lost reads'
    # offline_after 2 leaves room for one lost read only: more and it goes offline
    one = LineTimes(0.1, 0.5, retries=2, offline_after=2)
    assert keepalive_gap('drive', [DRIVE], one).gap_s == pytest.approx(0.6)


def test_a_neighbour_polls_as_often_as_its_rate_allows_within_the_period():
    times = LineTimes(0.01, 0.5, retries=0, offline_after=1, backoff_initial_s=1.0)
    fast = PollLoad('fast', 0.05, transactions=2)  # 4 periods in the drive's: 4 + 1 polls
    gap = keepalive_gap('drive', [DRIVE, fast], times)
    parts = dict(gap.parts)
    assert parts['fast: 5 polls'] == pytest.approx(5 * 2 * 0.01)
    # silent: offline after 1 failed transaction, or its probes (the one due at the start and
    # one more within 0.2 s: a backoff of 1 s apart), not both
    assert parts['2 failed if fast is silent'] == pytest.approx(1.0)
    assert gap.gap_s == pytest.approx(0.2 + 0.1 + 1.0)


def test_an_offline_neighbour_costs_its_failures_before_offline_and_never_more_polls():
    starter = PollLoad('starter', 0.2, transactions=1)
    gap = keepalive_gap('drive', [DRIVE, starter], TIMES)
    parts = dict(gap.parts)
    # 2 polls in the period; each fails a read and its 2 retries, but it goes offline after
    # 3 failed transactions: 3, whatever the polls could have held
    assert parts['3 failed if starter is silent'] == pytest.approx(1.5)
    assert gap.gap_s == pytest.approx(1.1 + 2 * 0.1 + 1.5)


def test_a_neighbour_with_writes_fails_them_too_and_probes_with_them():
    lvsg = PollLoad('gateway', 0.2, transactions=3, writes=1)
    gap = keepalive_gap('drive', [DRIVE, lvsg], TIMES)
    assert dict(gap.parts)['4 failed if gateway is silent'] == pytest.approx(2.0)
    # a backoff shorter than the period: the burst and the probes after it both fit
    quick = LineTimes(0.1, 0.5, retries=0, offline_after=1, backoff_initial_s=0.5)
    slow_drive = PollLoad('drive', 2.0, transactions=1, writes=1)
    lvsg = PollLoad('gateway', 0.5, transactions=3, writes=1)
    parts = dict(keepalive_gap('drive', [slow_drive, lvsg], quick).parts)
    # going offline: 1 + 1 write; probes: min(5 polls, 2.0 / 0.5 + 1) = 5, 2 each; but each
    # of the 5 polls fails at most its write and a read: 10
    assert parts['10 failed if gateway is silent'] == pytest.approx(5.0)


def test_devices_coming_online_add_their_identity_reads_and_setup_writes():
    drive = PollLoad('drive', 0.2, transactions=1, writes=1, online=4)
    other = PollLoad('other', 1.0, online=2)
    times = LineTimes(0.01, 0.5, retries=0, offline_after=1)
    parts = dict(keepalive_gap('drive', [drive, other], times).parts)
    assert parts['devices coming online'] == pytest.approx(6 * 0.01)


def test_the_advice_adds_the_margin_rounded_up():
    gap = keepalive_gap('drive', [DRIVE], TIMES)
    assert gap.advised_s == 2.1
    assert round_up(1.91) == 2.0 and round_up(2.0) == 2.0
    assert round_up(0.1 + 0.2) == 0.3  # float noise is no tenth more


# -- through the configuration ---------------------------------------------------------------
BUS = {'timeout': 0.3, 'retries': 2, 'baudrate': 9600, 'devices': ['crusher', 'feeder']}
DEVICES = {'crusher': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 5.0},
           'feeder': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
                      'comms_timeout': 1.0, 'comms_timeout_function': 2}}


def feeder(**values):
    return dict(DEVICES, feeder=dict(DEVICES['feeder'], **values))


def test_configure_refuses_a_comms_timeout_below_the_gap_in_one_line_saying_why():
    with pytest.raises(ConfigError) as error:
        config.build_config(BUS, DEVICES)
    text = str(error.value)
    assert '\n' not in text
    assert text.startswith('feeder.comms_timeout 1 s is below 3.23 s, the longest the bus may '
                           'go without writing to feeder (address 1) while the line works: '
                           'its own poll with 2 lost reads 1.40 s + crusher: 2 polls 0.18 s '
                           '+ 3 failed if crusher is silent 1.27 s + devices coming online '
                           '0.37 s (an answered transaction 0.092 s, a failed one 0.424 s): '
                           'set comms_timeout to at least 4.3 s (a margin of 1 s)')


def test_the_issue_case_of_a_tenth_of_a_second_is_refused_too():
    with pytest.raises(ConfigError, match=r'feeder.comms_timeout 0.1 s is below'):
        config.build_config(BUS, feeder(comms_timeout=0.1))


def test_at_the_gap_it_configures_and_zero_leaves_the_drive_alone():
    built = config.build_config(BUS, feeder(comms_timeout=3.3))
    gaps = config.keepalive_gaps(built)
    assert set(gaps) == {'feeder'} and gaps['feeder'].gap_s == pytest.approx(3.23, abs=0.005)
    config.build_config(BUS, feeder(comms_timeout=0.0))  # not written: nothing to check


def test_a_faster_line_or_fewer_retries_lowers_the_minimum():
    fast = dict(BUS, baudrate=115200, timeout=0.1, retries=0)
    gap = config.keepalive_gaps(config.build_config(fast, feeder(comms_timeout=2.0)))['feeder']
    assert gap.gap_s < 1.2 and gap.parts[0][0] == 'its own poll'


def test_a_runtime_poll_rate_is_refused_where_the_timeout_would_no_longer_cover_the_gap():
    built = config.build_config(BUS, feeder(comms_timeout=3.3))
    config.check_poll_rate_changes(built, {'feeder': 20.0, 'crusher': 2.0})  # still covered
    with pytest.raises(ConfigError) as error:
        config.check_poll_rate_changes(built, {'feeder': 0.5})
    assert str(error.value).startswith('poll_rate not changed: feeder.comms_timeout 3.3 s is '
                                       'below ')
    with pytest.raises(ConfigError, match='poll_rate not changed'):
        config.check_poll_rate_changes(built, {'crusher': 100.0})  # a neighbour's share too
    assert [device.poll_rate for device in built.devices] == [5.0, 10.0]  # unchanged


def test_every_drive_in_the_example_configs_has_the_margin():
    import glob
    import os
    root = os.path.join(os.path.dirname(__file__), '..', '..', 'config')
    checked = 0
    for path in sorted(glob.glob(os.path.join(root, '**', '*.yaml'), recursive=True)):
        for block in config.load_params_file(path).values():
            if 'devices' not in block:
                continue
            bus, devices = config.split_parameters(block)
            built = config.build_config(bus, devices)
            for name, gap in config.keepalive_gaps(built).items():
                assert built.device(name).option('comms_timeout') >= gap.advised_s, \
                    (path, name, gap.advised_s)
                checked += 1
    assert checked >= 7
