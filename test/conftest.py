"""Shared test set-up: a ROS domain of each test process's own, loopback-only discovery."""

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


def pytest_unconfigure(config):
    lock = getattr(config, 'ros_domain_lock', None)
    if lock is not None:
        lock.release()


def pytest_report_header(config):
    lock = getattr(config, 'ros_domain_lock', None)
    return f'ROS_DOMAIN_ID={lock.domain_id}' if lock is not None else None


def pytest_collection_modifyitems(config, items):
    """
    Mark each test with its tier, from its directory: ``pytest -m unit`` runs test/unit.

    The full-length soaks (marked ``soak``) run only when ``-m`` names them
    (``pytest -m soak test``); every run runs their shorter versions.
    """
    for item in items:
        tier = item.path.parent.name
        if tier in TIERS:
            item.add_marker(getattr(pytest.mark, tier))
    if 'soak' not in (config.getoption('markexpr', default='') or ''):
        soaks = [item for item in items if item.get_closest_marker('soak') is not None]
        if soaks:
            config.hook.pytest_deselected(items=soaks)
            items[:] = [item for item in items if item.get_closest_marker('soak') is None]
