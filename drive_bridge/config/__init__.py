"""
Configuration: the settings model, the node's parameter names, and the parameters file.

- :mod:`~drive_bridge.config.model`: what a bus and a device configuration are, their
  settings (types, defaults, ranges, text), and their validation into typed objects;
- :mod:`~drive_bridge.config.node_parameters`: the names the node declares and refuses, and
  a node block split into bus and device values;
- :mod:`~drive_bridge.config.params_file`: a ROS 2 parameters file read as rcl reads it, and
  written; it knows YAML, not the settings.
"""
