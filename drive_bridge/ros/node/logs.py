"""
The package's Python log records (``logging.getLogger('drive_bridge...')``) in the node's log.

Below ROS nothing imports rclpy, so what the transports have to say outside of a transaction
(a pty opened without parity) goes to Python's ``logging``; this handler puts those lines
into the node's own log, with their severity, as the node's other lines are.
"""

import logging

PACKAGE_LOGGER = 'drive_bridge'


class NodeLogHandler(logging.Handler):
    """Pass each record to an rclpy logger at its severity (INFO and above)."""

    def __init__(self, ros_logger):
        super().__init__(logging.INFO)
        self._ros_logger = ros_logger

    def emit(self, record: logging.LogRecord) -> None:
        """Log the record's message on the node's logger; never raise."""
        try:
            text = record.getMessage()
            if record.levelno >= logging.ERROR:
                self._ros_logger.error(text)
            elif record.levelno >= logging.WARNING:
                self._ros_logger.warning(text)
            else:
                self._ros_logger.info(text)
        except Exception:  # noqa: B902 - logging must not kill the thread that logs
            self.handleError(record)


def attach(ros_logger) -> NodeLogHandler:
    """Send the package's INFO and higher records to ``ros_logger``; return the handler."""
    handler = NodeLogHandler(ros_logger)
    logger = logging.getLogger(PACKAGE_LOGGER)
    logger.addHandler(handler)
    if logger.getEffectiveLevel() > logging.INFO:
        logger.setLevel(logging.INFO)
    return handler


def detach(handler: NodeLogHandler) -> None:
    """Stop sending records to the handler's logger."""
    logging.getLogger(PACKAGE_LOGGER).removeHandler(handler)
