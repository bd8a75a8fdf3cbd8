"""Loop closure for the wall follower's island escape.

A trail of odometry poses recorded every few centimetres, and the test "am I back at a pose I
passed, with the same heading?".

No rclpy import. The search runs every few control steps over up to 4,000 poses, as one
numba-compiled loop (as numpy expressions it cost ~20 us per step inside the ROS loop).
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit

CAPACITY = 4000          # poses kept; the oldest 1000 are dropped when it is full
SPACING_M = 0.05         # a pose is recorded every this much travel
MIN_LOOP_M = 1.0         # only poses at least this far back along the trail can close a loop
MATCH_RADIUS_M = 0.08    # same place: closer than this ...
MATCH_HEADING_RAD = 0.5  # ... with a heading closer than this


@jit
def _closing_pose(trail, count, odometer, x, y, heading):
    """Index of the first recorded pose that (x, y, heading) closes a loop with; -1 if none.

    Rows are (odometer, x, y, heading, winding). A match is at least MIN_LOOP_M of travel back,
    within MATCH_RADIUS_M of (x, y), with a heading within MATCH_HEADING_RAD.
    """
    for i in range(count):
        if odometer - trail[i, 0] < MIN_LOOP_M:
            break                     # odometer order: every later pose is more recent
        dx = x - trail[i, 1]
        dy = y - trail[i, 2]
        if abs(dx) > MATCH_RADIUS_M + 0.001 or abs(dy) > MATCH_RADIUS_M + 0.001:
            continue                  # cheap box test before the exact one
        d = heading - trail[i, 3]
        if (math.hypot(dx, dy) < MATCH_RADIUS_M
                and abs(math.atan2(math.sin(d), math.cos(d))) < MATCH_HEADING_RAD):
            return i
    return -1


class PoseTrail:
    """Odometry poses (odometer m, x m, y m, heading rad, winding rad) along the way."""

    def __init__(self) -> None:
        self._poses = np.zeros((CAPACITY + 1, 5))
        self._count = 0
        _closing_pose(self._poses, 0, 0.0, 0.0, 0.0, 0.0)   # compile / load now, not mid-run

    def __len__(self) -> int:
        return self._count

    def clear(self) -> None:
        """Forget every recorded pose."""
        self._count = 0

    def record_and_close(self, odometer: float, x: float, y: float, heading: float,
                         winding: float) -> float | None:
        """Record the pose if the robot travelled SPACING_M since the last one; find a loop.

        Returns the winding turned since the matching earlier pose (rad), or None if the pose
        was not recorded or closes no loop.
        """
        n = self._count
        if n and odometer - self._poses[n - 1, 0] < SPACING_M:
            return None
        self._poses[n] = (odometer, x, y, heading, winding)
        n += 1
        if n > CAPACITY:
            self._poses[:n - 1000] = self._poses[1000:n].copy()
            n -= 1000
        self._count = n
        i = _closing_pose(self._poses, n, odometer, x, y, heading)
        return None if i < 0 else winding - float(self._poses[i, 4])
