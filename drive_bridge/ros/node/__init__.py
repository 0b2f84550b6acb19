"""
The node, ``drive_bridge_node``: the lifecycle node and its parts.

entry.py is what the command runs (the exit signals blocked before anything starts a
thread), process.py the process around the node, bridge_node.py the lifecycle shell
that builds the parts; joints/ the ros2_control joints. This file imports nothing, so
that importing entry.py still starts no thread.
"""
