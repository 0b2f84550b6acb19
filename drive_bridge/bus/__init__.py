"""The bus: one thread owns one bus (see :mod:`drive_bridge.bus.master`)."""
