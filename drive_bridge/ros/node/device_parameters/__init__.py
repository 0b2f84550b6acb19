"""
Each device's parameters as ROS parameters: a node per device, ``<device>_parameters``.

The standard tools drive them (``ros2 param list/get/set/describe/dump/load``,
rqt_reconfigure): see docs/device_parameters.md. :class:`~.nodes.DeviceParameterNodes` is
what the bus session makes and destroys; the naming and what may be written are pure, in
:mod:`drive_bridge.devices.parameter_names` and :mod:`drive_bridge.devices.remote_parameters`.
"""
