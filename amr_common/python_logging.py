"""Python logging for the plain-Python algorithm modules: throttled, and bridged to ROS.

Algorithm modules (no rclpy) log with `logging.getLogger(__name__)`. Bad input that repeats with
every message (a broken scan at 5-20 Hz) must not print one line per message:

    _LOG = ThrottledLogger(logging.getLogger(__name__))
    _LOG.warning("geometry", "ignoring unusable scan geometry %s", geometry)  # once per 5 s

Inside a ROS node, `forward_to_ros_logger("amr_control", node.get_logger())` hands the package's
records to the node's logger (rosout, the node's log file, its name on the console) instead of
Python's bare stderr fallback. No rclpy import here: the ROS logger is any object with
debug/info/warning/error/fatal methods.
"""
from __future__ import annotations

import logging
import time
from typing import Any, Callable


class ThrottledLogger:
    """Emits each kind of message (a key) at most once per `period_s` seconds.

    A repeated message says how many of its kind were suppressed since it last appeared.
    """

    def __init__(self, logger: logging.Logger, period_s: float = 5.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        """Wrap `logger`; `clock` returns seconds (monotonic by default)."""
        self.logger = logger
        self.period_s = float(period_s)
        self._clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def warning(self, key: str, message: str, *args: Any) -> bool:
        """Log a warning of kind `key` unless one was logged less than period_s ago.

        Returns True if it was logged.
        """
        return self._log(logging.WARNING, key, message, args)

    def error(self, key: str, message: str, *args: Any) -> bool:
        """As warning(), at error level."""
        return self._log(logging.ERROR, key, message, args)

    def _log(self, level: int, key: str, message: str, args: tuple) -> bool:
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return False
        self._last[key] = now
        suppressed = self._suppressed.pop(key, 0)
        if suppressed:
            message += f" ({suppressed} more like this in the last {now - last:.0f} s)"
        self.logger.log(level, message, *args)
        return True


class RosLoggerHandler(logging.Handler):
    """A logging.Handler writing each record to a ROS logger at the matching severity."""

    def __init__(self, ros_logger: Any) -> None:
        """`ros_logger`: e.g. node.get_logger()."""
        super().__init__()
        self.ros_logger = ros_logger

    def emit(self, record: logging.LogRecord) -> None:
        """Send one record (formatted message) to the ROS logger."""
        try:
            text = self.format(record)
            if record.levelno >= logging.CRITICAL:
                self.ros_logger.fatal(text)
            elif record.levelno >= logging.ERROR:
                self.ros_logger.error(text)
            elif record.levelno >= logging.WARNING:
                self.ros_logger.warning(text)
            elif record.levelno >= logging.INFO:
                self.ros_logger.info(text)
            else:
                self.ros_logger.debug(text)
        except Exception:  # a logging failure must never break the caller
            self.handleError(record)


def forward_to_ros_logger(logger_name: str, ros_logger: Any,
                          record_filter: logging.Filter | None = None) -> Callable[[], None]:
    """Send the records of Python logger `logger_name` (and its children) to `ros_logger`.

    `record_filter` sees each record first (it may drop it, or change its level). Returns a
    function that stops the forwarding (call it when the node releases its algorithm, e.g. on
    cleanup).
    """
    python_logger = logging.getLogger(logger_name)
    handler = RosLoggerHandler(ros_logger)
    if record_filter is not None:
        handler.addFilter(record_filter)
    python_logger.addHandler(handler)

    def stop() -> None:
        python_logger.removeHandler(handler)

    return stop


__all__ = ["ThrottledLogger", "RosLoggerHandler", "forward_to_ros_logger"]
