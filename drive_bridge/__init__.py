"""drive_bridge: ROS 2 driver for Danfoss soft starters and frequency drives on RS-485."""

__version__ = '0.4.0'  # package.xml's version; test/unit/test_packaging.py checks
