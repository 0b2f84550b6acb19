"""The keepalive rule: the longest gap between two polls of a drive, and what is refused."""

from drive_bridge.bus.keepalive import keepalive_gap, LineTimes, PollLoad, round_up
from drive_bridge.config import model as config
from drive_bridge.config.node_parameters import split_parameters
from drive_bridge.config.params_file import load_params_file
from drive_bridge.errors import ConfigError
import pytest

# Round numbers: an answered transaction 0.1 s, a failed one 0.5 s.
TIMES = LineTimes(answered_s=0.1, failed_s=0.5, retries=2, offline_after=3)
DRIVE = PollLoad('drive', 0.2, transactions=1, writes=1)


def test_a_drive_alone_waits_one_period_when_its_polls_fit():
    times = LineTimes(0.01, 0.5, retries=0, offline_after=3)
    gap = keepalive_gap('drive', [DRIVE], times)
    assert gap.gap_s == pytest.approx(0.2)
    assert gap.explain() == 'its poll period 0.20 s'


def test_its_own_reads_each_answered_at_the_last_retry_stretch_its_poll():
    # 1 transaction answered after min(retries 2, offline_after 3 - 1) = 2 lost attempts
    gap = keepalive_gap('drive', [DRIVE], TIMES)
    assert gap.gap_s == pytest.approx(0.1 + 2 * 0.5)
    assert gap.parts[0][0] == 'its own poll, each read answered at the last retry'
    # offline_after 2 leaves room for one lost attempt only: more and it goes offline
    one = LineTimes(0.1, 0.5, retries=2, offline_after=2)
    assert keepalive_gap('drive', [DRIVE], one).gap_s == pytest.approx(0.6)
    many = PollLoad('drive', 0.2, transactions=3, writes=1)  # each transaction retried
    assert keepalive_gap('drive', [many], TIMES).gap_s == pytest.approx(3 * 1.1)


def test_a_neighbour_counts_once_after_the_drive_falls_due_and_once_under_way():
    # However fast it polls: once the drive is due, a device that begins a poll is made due
    # no sooner than that moment, so the drive comes before its next one.
    times = LineTimes(0.01, 0.5, retries=0, offline_after=1)
    fast = PollLoad('fast', 0.05, transactions=2)
    gap = keepalive_gap('drive', [DRIVE, fast], times)
    parts = dict(gap.parts)
    # its longest poll: silent, one failed read (offline after 1); online: 2 x 0.01
    assert parts['a poll of fast'] == pytest.approx(0.5)
    assert parts['a poll under way as it falls due'] == pytest.approx(0.5)
    assert gap.gap_s == pytest.approx(0.2 + 0.5 + 0.5)


def test_a_flaky_neighbour_that_never_goes_offline_costs_its_retries_on_every_transaction():
    # The review's counter-example: a device losing two attempts of three stays online (an
    # answer ends the row of failures) and takes 2 x 0.5 + 0.1 s a transaction.
    neighbour = PollLoad('neighbour', 0.2, transactions=3, writes=1)
    gap = keepalive_gap('drive', [DRIVE, neighbour], TIMES)
    parts = dict(gap.parts)
    assert parts['a poll of neighbour'] == pytest.approx(3 * 1.1)
    assert gap.gap_s == pytest.approx(0.2 + 3.3 + 3.3)


def test_a_silent_neighbour_fails_its_writes_and_a_read_with_its_retries_no_more():
    starter = PollLoad('starter', 0.2, transactions=1)
    gap = keepalive_gap('drive', [DRIVE, starter], TIMES)
    # a read and 2 retries fail: 1.5 s (online, answered at the last retry: 1.1 s)
    assert dict(gap.parts)['a poll of starter'] == pytest.approx(1.5)
    gateway = PollLoad('gateway', 0.2, transactions=1, writes=2)
    capped = LineTimes(0.1, 0.5, retries=5, offline_after=1)
    # 2 writes and 1 read fail, then it is offline (offline_after 1 + its 2 writes)
    assert dict(keepalive_gap('drive', [DRIVE, gateway], capped).parts)[
        'a poll of gateway'] == pytest.approx(1.5)


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
    assert text.startswith('feeder.comms_timeout 1 s is below 7.28 s, the longest the bus may '
                           'go without writing to feeder (address 1) while the line works: '
                           'its own poll, each read answered at the last retry 5.64 s + a '
                           'poll of crusher 1.27 s + devices coming online 0.37 s (an '
                           'answered transaction 0.092 s, a failed one 0.424 s): set '
                           'comms_timeout to at least 8.3 s (a margin of 1 s)')


def test_the_issue_case_of_a_tenth_of_a_second_is_refused_too():
    with pytest.raises(ConfigError, match=r'feeder.comms_timeout 0.1 s is below'):
        config.build_config(BUS, feeder(comms_timeout=0.1))


def test_at_the_gap_it_configures_and_zero_leaves_the_drive_alone():
    built = config.build_config(BUS, feeder(comms_timeout=7.3))
    gaps = config.keepalive_gaps(built)
    assert set(gaps) == {'feeder'} and gaps['feeder'].gap_s == pytest.approx(7.28, abs=0.005)
    config.build_config(BUS, feeder(comms_timeout=0.0))  # not written: nothing to check


def test_a_faster_line_or_fewer_retries_lowers_the_minimum():
    fast = dict(BUS, baudrate=115200, timeout=0.1, retries=0)
    gap = config.keepalive_gaps(config.build_config(fast, feeder(comms_timeout=2.0)))['feeder']
    assert gap.gap_s < 1.2 and gap.parts[0][0] == 'its own poll'  # no retries


def test_a_runtime_poll_rate_is_refused_where_the_timeout_would_no_longer_cover_the_gap():
    built = config.build_config(BUS, feeder(comms_timeout=7.3))
    # still covered: its own poll (5.64 s) outlasts a period of 2 s; a neighbour's rate does
    # not count (it polls at most once more, however fast)
    config.check_poll_rate_changes(built, {'feeder': 0.5, 'crusher': 100.0})
    with pytest.raises(ConfigError) as error:
        config.check_poll_rate_changes(built, {'feeder': 0.1})  # a 10 s period
    assert str(error.value).startswith('poll_rate not changed: feeder.comms_timeout 7.3 s is '
                                       'below 12.91 s')
    assert [device.poll_rate for device in built.devices] == [5.0, 10.0]  # unchanged


def test_every_drive_in_the_example_configs_has_the_margin():
    import glob
    import os
    root = os.path.join(os.path.dirname(__file__), '..', '..', 'config')
    checked = 0
    for path in sorted(glob.glob(os.path.join(root, '**', '*.yaml'), recursive=True)):
        for block in load_params_file(path).values():
            if 'devices' not in block:
                continue
            bus, devices = split_parameters(block)
            built = config.build_config(bus, devices)
            for name, gap in config.keepalive_gaps(built).items():
                assert built.device(name).option('comms_timeout') >= gap.advised_s, \
                    (path, name, gap.advised_s)
                checked += 1
    assert checked >= 7
