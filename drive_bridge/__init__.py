"""drive_bridge: ROS 2 driver for Danfoss soft starters and frequency drives on RS-485."""

__version__ = '0.1.0'
