"""Names the node gives things, without rclpy (tools and tests use them too)."""

COMMANDS_NODE_SUFFIX = '_commands'  # the node of the high-rate command topics


def status_name(node_fqn: str, device: str) -> str:
    """
    Return the status name of a device.

    ``drive_bridge: feeder`` in the root namespace, ``/line1/drive_bridge: feeder`` in a
    namespace (as diagnostic_updater's ``use_fqn`` names it).
    """
    namespace, _, node = node_fqn.rpartition('/')
    return f'{node}: {device}' if not namespace else f'{node_fqn}: {device}'
