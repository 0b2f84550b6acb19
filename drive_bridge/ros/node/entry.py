"""
The node's entry point: block the exit signals before anything else runs.

Importing rclpy and the message packages starts threads (DDS, and numpy's thread pool
through ``sensor_msgs``) that take the signal mask of the thread that started them. A
thread that does not block SIGINT/SIGTERM could take a signal meant for the node's
``sigtimedwait`` and end the process in the middle of its stops. So this module, which
imports nothing heavy (:mod:`drive_bridge.ros.node.exit_signals` is standard library only),
blocks them first and then imports the process's main (:mod:`drive_bridge.ros.node.process`).
"""

import sys
from typing import List, Optional

from drive_bridge.ros.node.exit_signals import block_in_this_thread


def main(args: Optional[List[str]] = None) -> int:
    """Block the exit signals in this and every later thread, then run the node."""
    block_in_this_thread()
    from drive_bridge.ros.node import process  # noqa: I100 - after the mask, on purpose
    return process.main(args)


if __name__ == '__main__':
    sys.exit(main())
