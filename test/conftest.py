"""Shared test set-up: a distinct ROS domain per test process, loopback-only discovery."""

import os
import sys

import pytest

# Never multicast off this machine; check message field types; one domain per process.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_PYTHON_CHECK_FIELDS'] = '1'
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
_PROFILE = os.path.join(os.path.dirname(__file__), 'fastdds_test_profile.xml')
os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', _PROFILE)
sys.path.insert(0, os.path.dirname(__file__))  # test helpers (integration_helpers)

TIERS = ('unit', 'integration', 'ros')


def pytest_collection_modifyitems(config, items):
    """Mark each test with its tier, from its directory: ``pytest -m unit`` runs test/unit."""
    for item in items:
        tier = item.path.parent.name
        if tier in TIERS:
            item.add_marker(getattr(pytest.mark, tier))
