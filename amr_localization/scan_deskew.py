"""Scan de-skewing: each ray moved to where the LiDAR is NOW, from the odometry of the last second.

A LiDAR measures its rays one after the other while the robot drives and turns: an LDS scan
spans 0.2 s, in which the Burger turns up to 0.5 rad, so the pose at the stamp explains the rays
measured early in the revolution badly (docs/reality-gap.md: the true pose explains 61 % of a
turning robot's rays within 3 cm). The filter keeps the motion its predictions integrated
(MotionHistory: the odometry twists over the last second) and, for each ray measured `age`
seconds ago (range_sensor.RangeSensor.ray_ages: the driver's stamp convention), takes the
robot's pose at that time relative to now, puts the ray's end point in the frame of the LiDAR
now, and reports it as a range and an angle from there. The particles, the expected-range table
and the exact scan match then all see a scan taken from one pose: the particles' pose now.
Missing returns keep their range (no return) and turn with the robot. No rclpy import.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

HISTORY_S = 1.0  # the motion kept: a revolution (0.2 s) plus the age of a held scan
MAX_LEAD_S = 0.1  # a stamp at most this far after the newest prediction is extrapolated to
_MAX_ROWS = 4096  # at most this many predictions kept (a 1 kHz caller: 4 s)


class MotionHistory:
    """The robot's pose over the last HISTORY_S seconds in a frame of its own (odometry)."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Start again: the robot has been where it is now ever since."""
        self._rows: deque[tuple[float, float, float, float]] = deque([(0.0, 0.0, 0.0, 0.0)])
        self._rate = (0.0, 0.0, 0.0)  # the newest twist in this frame: dx/dt, dy/dt, dtheta/dt

    def add(self, v: float, w: float, dt: float) -> None:
        """Integrate a twist (v m/s, w rad/s) over dt s (mid-point heading, as the filter)."""
        t, x, y, theta = self._rows[-1]
        mid = theta + 0.5 * w * dt
        row = (t + dt, x + v * dt * math.cos(mid), y + v * dt * math.sin(mid), theta + w * dt)
        self._rows.append(row)
        self._rate = (v * math.cos(mid), v * math.sin(mid), w)
        while len(self._rows) > _MAX_ROWS or \
                (len(self._rows) > 2 and row[0] - self._rows[1][0] >= HISTORY_S):
            self._rows.popleft()

    def relative_poses(self, ages: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, theta) of the robot `ages` seconds ago, in the frame of the robot now.

        Before the oldest pose kept: the oldest (nothing known of earlier motion); a negative
        age (a stamp after the newest prediction): the newest twist carried on.
        """
        rows = np.asarray(self._rows)
        t, x, y, theta = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
        times = t[-1] - np.asarray(ages, dtype=np.float64)
        ahead = np.clip(times - t[-1], 0.0, MAX_LEAD_S)
        px = np.interp(times, t, x) + self._rate[0] * ahead
        py = np.interp(times, t, y) + self._rate[1] * ahead
        ptheta = np.interp(times, t, theta) + self._rate[2] * ahead
        c, s = math.cos(theta[-1]), math.sin(theta[-1])
        dx, dy = px - x[-1], py - y[-1]
        return c * dx + s * dy, -s * dx + c * dy, ptheta - theta[-1]


def deskew(angles: np.ndarray, ranges: np.ndarray, valid: np.ndarray, ages: np.ndarray,
           history: MotionHistory, lidar_offset: float) -> tuple[np.ndarray, np.ndarray]:
    """(angles, ranges) of the scan's rays as seen from the LiDAR's pose now.

    angles (rad, in the LiDAR frame), ranges (m) and valid (bool: a return) of each ray; ages
    (s): how long before now each ray was measured; lidar_offset (m): the LiDAR ahead of the
    robot centre. Rays without a return keep their range and turn with the robot.
    """
    rx, ry, rtheta = history.relative_poses(ages)
    direction = angles + rtheta
    with np.errstate(invalid="ignore"):  # NaN and inf readings: no return, left as they are
        # The ray's end point in the robot's frame now, then from the LiDAR now.
        ex = rx + lidar_offset * np.cos(rtheta) + ranges * np.cos(direction) - lidar_offset
        ey = ry + lidar_offset * np.sin(rtheta) + ranges * np.sin(direction)
        new_ranges = np.where(valid, np.hypot(ex, ey), ranges)
        new_angles = np.where(valid, np.arctan2(ey, ex), direction)
    return new_angles, new_ranges


__all__ = ["MotionHistory", "deskew", "HISTORY_S"]
