"""Scan de-skewing: each ray moved to where the LiDAR is NOW, from the odometry of the last second.

A LiDAR measures its rays one after the other while the robot drives and turns: an LDS scan
spans 0.2 s, in which the Burger turns up to 0.5 rad, so the pose at the stamp explains the rays
measured early in the revolution badly (docs/reality-gap.md: the true pose explains 61 % of a
turning robot's rays within 3 cm). The user keeps the motion it knows (MotionHistory: odometry
twists, or odometry poses as steps, over the last second) and, for each ray measured `age`
seconds ago (lidar_models.revolution_ages: the drivers' stamp convention), takes the robot's
pose at that time relative to now and puts the ray's end point in the robot's frame now
(`points_now`). One home for the particle filter (amr_localization.scan_input: `deskew`, which
reports the moved rays as ranges and angles from the LiDAR now, so the particles, the
expected-range table and the exact scan match all see a scan taken from one pose; missing
returns keep their range and turn with the robot) and the SLAM Mapper (amr_mapping.mapper:
`points_now` on the scan's points before matching and drawing). The wall follower's compiled
kernel (amr_control.point_memory_kernels.deskew_point) does the same per point with a constant
twist. No rclpy import.
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

    def add_motion(self, motion: tuple[float, float, float], dt: float, steps: int = 4) -> None:
        """Add an odometry step: `motion` (dx, dy, dtheta in the frame of the pose before) in dt s.

        Taken as an arc (the chord's length and the turn) in `steps` equal twists, so that the
        poses between the two odometry poses lie on the arc, not on the chord. A step that is
        not finite or not forward in time leaves the history at rest (nothing known).
        """
        dx, dy, dtheta = motion
        if not (dt > 0.0 and math.isfinite(dt) and math.isfinite(dx) and math.isfinite(dy)
                and math.isfinite(dtheta)):
            self.clear()
            return
        chord = math.hypot(dx, dy)
        distance = math.copysign(chord, dx) if chord > 0.0 else 0.0
        # The arc of a turn dtheta whose chord is `chord` (sinc: arc / chord).
        half = 0.5 * dtheta
        arc = distance if abs(half) < 1e-9 else distance * half / math.sin(half)
        for _ in range(steps):
            self.add(arc / dt, dtheta / dt, dt / steps)

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


def points_now(points: np.ndarray, ages: np.ndarray, history: MotionHistory) -> np.ndarray:
    """(N, 2) points measured `ages` (s) ago in the robot's frame then, in its frame now.

    The same motion as `deskew` (the robot's pose at each age, relative to now), applied to
    end points already in the robot's frame: the Mapper's scan points.
    """
    rx, ry, rtheta = history.relative_poses(ages)
    c, s = np.cos(rtheta), np.sin(rtheta)
    x, y = points[:, 0], points[:, 1]
    return np.column_stack([rx + c * x - s * y, ry + s * x + c * y])


__all__ = ["MotionHistory", "deskew", "points_now", "HISTORY_S"]
