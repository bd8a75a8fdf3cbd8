"""Throttled warnings of the plain-Python modules and their bridge to a ROS logger."""
from __future__ import annotations

import logging

from amr_common.python_logging import ThrottledLogger, forward_to_ros_logger


def test_each_kind_is_logged_once_per_period_and_says_how_many_were_dropped(caplog):
    now = [100.0]
    log = ThrottledLogger(logging.getLogger("amr_test.throttle"), period_s=5.0,
                          clock=lambda: now[0])
    with caplog.at_level("WARNING", logger="amr_test.throttle"):
        for _ in range(10):
            log.warning("a", "problem A %d", 1)
            log.warning("b", "problem B")
            now[0] += 1.0
        log.warning("a", "problem A %d", 2)
    assert [r.getMessage() for r in caplog.records] == [
        "problem A 1", "problem B", "problem A 1 (4 more like this in the last 5 s)",
        "problem B (4 more like this in the last 5 s)", "problem A 2 (4 more like this in the "
        "last 5 s)"]


class RecordingRosLogger:
    def __init__(self):
        self.lines = []

    def __getattr__(self, level):
        return lambda text: self.lines.append((level, text))


def test_forwarding_sends_records_at_their_level_until_stopped():
    ros_logger = RecordingRosLogger()
    stop = forward_to_ros_logger("amr_test.forward", ros_logger)
    child = logging.getLogger("amr_test.forward.module")
    child.warning("seen %s", "here")
    child.error("broken")
    stop()
    child.warning("not forwarded")
    assert ros_logger.lines == [("warning", "seen here"), ("error", "broken")]
