"""Shared test set-up: a ROS domain of each test process's own, loopback-only discovery."""

import gc
import os
import sys

import pytest

# Never multicast off this machine; check message field types.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_PYTHON_CHECK_FIELDS'] = '1'
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
_PROFILE = os.path.join(os.path.dirname(__file__), 'fastdds_test_profile.xml')
os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', _PROFILE)
sys.path.insert(0, os.path.dirname(__file__))  # test helpers (integration_helpers)

TIERS = ('unit', 'integration', 'ros')
# The longest tests first (--durations, 2-core machine), so that pytest-xdist's workers do not
# end with one of them while the others idle. Only the order changes: a test or module left
# out runs after these, in collection order. With --dist loadgroup, xdist hands out the
# groups (xdist_group) first, the most tests first, and then the other tests in this order:
# the entries below for grouped modules order them only in runs without groups.
LONGEST_FIRST = (
    'test/ros/test_soak_node.py',  # 37 s
    'test/ros/test_safety_signals.py::test_sigterm_exits_cleanly_under_load',  # 31 s
    'test/ros/test_safety_parameters.py::test_refused_atomic_set_leaves_the_poll_rate',  # 17 s
    'test/ros/test_quickstart.py',  # 16 s
    'test/ros/test_safety_cases.py::test_babbling_line',  # 2 x 14 s
    'test/ros/test_reconnect_node.py',  # 14 s, module node
    'test/ros/test_ctl.py',  # 94 s in 26 tests, module node
    'test/ros/test_joints_node.py',  # 51 s in 12 tests, module node
    'test/ros/test_safety_cases.py',  # 110 s in 16 tests
    'test/ros/test_adversarial_safety.py',  # 210 s in 65 tests, 30 of them on shared nodes
    'test/integration/test_fault_injection.py::test_ap_ascii_faults',  # 52 s
    'test/integration/test_soak.py',  # 70 s in 9 tests: 32 s, 21 s, ...
    'test/integration/test_fc_protocol_sim.py::test_random_faults',  # 22 s
    'test/integration/test_reconnect.py',  # realtime: 22, 11, 11 s
    'test/integration/test_cli.py::test_scan_finds_each_device',  # 19 s
    'test/integration/test_fc_protocol_transport.py::test_random_wire_bytes',  # 17 s
    'test/integration/test_safety_bus.py',  # the babbling lines, one xdist group: 45 s
    'test/integration/test_docs_examples.py',  # 20 s
    'test/integration/test_bus.py::test_start_stop',  # 9 s
    'test/integration/test_cli.py',  # 60 s in 30 tests
)


def pytest_configure(config):
    """
    Give this test process a ROS domain of its own (test/ros_domain.py), held until it ends.

    A pytest-xdist worker always takes a free id; a serial run takes the exported
    ``ROS_DOMAIN_ID`` if there is one, else a free id. The controller of an xdist run runs no
    test and takes none. Each test process also checks that every test that makes a pymodbus
    transport is marked ``pymodbus`` (test/pymodbus_use.py).
    """
    import pymodbus_use  # test helpers, on the path from sys.path above
    import ros_domain

    worker = hasattr(config, 'workerinput')
    if not worker and config.getoption('dist', default='no') != 'no':
        return
    exported = os.environ.get('ROS_DOMAIN_ID', '')
    try:
        if exported and not worker:
            lock = ros_domain.take_exported(int(exported))
        else:
            lock = ros_domain.take_free()
    except ros_domain.DomainTaken as error:
        raise pytest.UsageError(str(error)) from None
    config.ros_domain_lock = lock
    os.environ['ROS_DOMAIN_ID'] = str(lock.domain_id)
    pymodbus_use.register(config)


def pytest_runtest_setup(item):
    """
    Fail a test of an ``xdist_group`` whose mark has no effect.

    With ``--dist loadgroup`` a worker appends each test's group to its id, and the tests of a
    group then run on one worker (the babbling lines one after another; a module's node
    started once). pytest 9.2 ignores that id (pytest-xdist issue 1386): the groups were
    silently spread over the workers.
    """
    config = item.config
    if not hasattr(config, 'workerinput') or not config.getvalue('loadgroup'):
        return
    # The suffix as pytest-xdist 3.8 makes it (xdist/remote.py): every group mark, by its
    # first argument or name=, sorted and joined.
    groups = sorted({str(mark.args[0] if mark.args else mark.kwargs.get('name', 'default'))
                     for mark in item.iter_markers('xdist_group')})
    if groups and not item.nodeid.endswith('@' + '_'.join(groups)):
        pytest.fail(f'xdist_group has no effect with pytest {pytest.__version__} (pytest-xdist '
                    'issue 1386): this test is not in its group; use requirements-test.txt',
                    pytrace=False)


def pytest_unconfigure(config):
    lock = getattr(config, 'ros_domain_lock', None)
    if lock is not None:
        lock.release()


def pytest_collection_finish(session):
    """
    Move what start-up and collection made out of the collector's sight (``gc.freeze``).

    A simulator that answers in the test's own process waits out every full collection, and
    a full collection walks every object the process holds: over a thousand collected tests,
    their modules and pymodbus's. Frozen, those are never walked again, and a pause is the
    size of what the running test made.
    """
    gc.collect()
    gc.freeze()


def pytest_report_header(config):
    lock = getattr(config, 'ros_domain_lock', None)
    return f'ROS_DOMAIN_ID={lock.domain_id}' if lock is not None else None


def pytest_collection_modifyitems(config, items):
    """
    Mark each test with its tier, from its directory: ``pytest -m unit`` runs test/unit.

    The full-length soaks (marked ``soak``) run only when ``-m`` names them
    (``pytest -m soak test``); every run runs their shorter versions. The tests of
    ``LONGEST_FIRST`` run first, in its order.
    """
    def rank(item) -> int:
        for index, prefix in enumerate(LONGEST_FIRST):
            if item.nodeid.startswith(prefix) or \
                    f'test/{item.nodeid}'.startswith(prefix):
                return index
        return len(LONGEST_FIRST)

    items.sort(key=rank)
    for item in items:
        tier = item.path.parent.name
        if tier in TIERS:
            item.add_marker(getattr(pytest.mark, tier))
    if 'soak' not in (config.getoption('markexpr', default='') or ''):
        soaks = [item for item in items if item.get_closest_marker('soak') is not None]
        if soaks:
            config.hook.pytest_deselected(items=soaks)
            items[:] = [item for item in items if item.get_closest_marker('soak') is None]
