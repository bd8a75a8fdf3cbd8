"""The odometry pose at any stamp: a short history of stamped planar poses, interpolated.

A LiDAR scan and the odometry come at their own rates (the Burger: /scan at 5 Hz stamped after
the revolution, /odom at 20 Hz); a scan must be placed with the odometry pose OF ITS STAMP, not
of the nearest message (at 2.84 rad/s, 25 ms off is 0.07 rad). PoseHistory keeps the poses of
the last `span_s` seconds and answers `pose_at(stamp)` by linear interpolation between the two
poses around it (the heading the short way round). Plain Python, no rclpy.

    history = PoseHistory()
    history.add(stamp_ns, (x, y, theta))      # every odometry message
    answer = history.pose_at(scan_stamp_ns)   # a pose, or one of LATER / OLDER / GAP
"""
from __future__ import annotations

import bisect
import math
from typing import Sequence

from amr_common.geometry import angle_difference

LATER = "later"  # the stamp is newer than the newest pose: wait for the next message
OLDER = "older"  # the stamp is older than the history reaches back
GAP = "gap"  # the poses around the stamp are farther apart than max_gap_s
NON_FINITE = "non_finite"
OUT_OF_ORDER = "out_of_order"


class PoseHistory:
    """Stamped (x, y, theta) poses of the last `span_s` seconds, in stamp order."""

    def __init__(self, span_s: float = 5.0, max_gap_s: float = 0.5) -> None:
        """span_s: how far back poses are kept; max_gap_s: largest gap interpolated across."""
        self._span_ns = int(span_s * 1e9)
        self._max_gap_ns = int(max_gap_s * 1e9)
        self._stamps: list[int] = []
        self._poses: list[tuple[float, float, float]] = []

    def __len__(self) -> int:
        return len(self._stamps)

    @property
    def newest_stamp(self) -> int | None:
        """The newest stamp held (ns), or None when empty."""
        return self._stamps[-1] if self._stamps else None

    def clear(self) -> None:
        """Forget every pose."""
        self._stamps.clear()
        self._poses.clear()

    def add(self, stamp_ns: int, pose: Sequence[float]) -> str | None:
        """Append a pose; None if taken, else why not (NON_FINITE, OUT_OF_ORDER).

        A stamp not after the newest is refused, unless it lies more than max_gap_s before
        it: time went back (a restarted clock, a replayed bag, a stamp far in the future
        before), so the history starts again from this pose rather than refusing all that
        follows.
        """
        try:
            x, y, theta = (float(v) for v in pose)
        except (TypeError, ValueError):
            return NON_FINITE
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(theta)):
            return NON_FINITE
        if self._stamps and stamp_ns <= self._stamps[-1]:
            if self._stamps[-1] - stamp_ns <= self._max_gap_ns:
                return OUT_OF_ORDER
            self.clear()
        self._stamps.append(int(stamp_ns))
        self._poses.append((x, y, theta))
        oldest = stamp_ns - self._span_ns
        if self._stamps[0] < oldest:
            cut = bisect.bisect_left(self._stamps, oldest)
            cut = min(cut, len(self._stamps) - 2)  # keep two: a bracket for the newest
            if cut > 0:
                del self._stamps[:cut]
                del self._poses[:cut]
        return None

    def pose_at(self, stamp_ns: int) -> tuple[float, float, float] | str:
        """The pose at `stamp_ns`, interpolated; or LATER, OLDER or GAP (see the constants)."""
        stamps = self._stamps
        if not stamps or stamp_ns > stamps[-1]:
            return LATER
        if stamp_ns < stamps[0]:
            return OLDER
        i = bisect.bisect_left(stamps, stamp_ns)
        if stamps[i] == stamp_ns:
            return self._poses[i]
        before, after = stamps[i - 1], stamps[i]
        if after - before > self._max_gap_ns:
            return GAP
        f = (stamp_ns - before) / (after - before)
        (x0, y0, t0), (x1, y1, t1) = self._poses[i - 1], self._poses[i]
        return (x0 + f * (x1 - x0), y0 + f * (y1 - y0), t0 + f * angle_difference(t1, t0))


__all__ = ["GAP", "LATER", "NON_FINITE", "OLDER", "OUT_OF_ORDER", "PoseHistory"]
