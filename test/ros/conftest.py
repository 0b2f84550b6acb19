"""The ROS tier: one rclpy context per test process, in this process's own domain."""

import os

import pytest
import rclpy


@pytest.fixture(scope='session', autouse=True)
def ros_context():
    rclpy.init(domain_id=int(os.environ['ROS_DOMAIN_ID']))
    yield
    rclpy.try_shutdown()
