"""The QoS profiles of the project's topics, in one place (no rclpy node needed to use them).

- RELIABLE_10: commands, odometry, poses, /clock (reliable, keep last 10: the course's depth).
- scan_qos(depth): best effort like a LiDAR driver's SensorDataQoS, so /scan from the real robot
  (best effort) is received; a reliable subscriber would get nothing.
- LATCHED: transient local, reliable, depth 1: maps, paths and /tf_static, so a subscriber that
  comes late still gets the last message.
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

RELIABLE_10 = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def scan_qos(depth: int = 10) -> QoSProfile:
    """Best effort, keep last `depth` (the LDS drivers' SensorDataQoS uses depth 5)."""
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.BEST_EFFORT,
                      history=HistoryPolicy.KEEP_LAST)


__all__ = ["RELIABLE_10", "LATCHED", "scan_qos"]
