"""What the WallFollower accepts and what it may send (no rclpy).

Inputs: a scan that is not an array of numbers is ignored, an odometry twist that is not a
finite number or physically impossible is replaced by the last command (a corrupt message would
poison the integrated heading and position that turns and loop detection rely on). Output: a
command limited to the Burger's speeds and slowed down before an obstacle in the swept path.
Each kind of warning goes through a ThrottledLogger (bad input repeats with every message).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from amr_common.python_logging import ThrottledLogger
from amr_common.robot import (
    MAX_LINEAR_SPEED,
    MAX_PLAUSIBLE_ANGULAR_SPEED,
    MAX_PLAUSIBLE_LINEAR_SPEED,
    is_plausible_twist,
)


def is_finite_number(value: Any) -> bool:
    """True for anything float() turns into a finite number."""
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def checked_odometry(z_v: Any, z_w: Any, fallback: tuple[float, float],
                     log: ThrottledLogger) -> tuple[float, float]:
    """The odometry twist (m/s, rad/s), each bad value replaced by `fallback`'s (v, w)."""
    v = float(z_v) if is_finite_number(z_v) else fallback[0]
    w = float(z_w) if is_finite_number(z_w) else fallback[1]
    if not is_plausible_twist(v, w):  # finite here
        log.warning("odometry", "WallFollower: physically impossible odometry (v=%r "
                    "m/s, w=%r rad/s) ignored", z_v, z_w)
        v = v if abs(v) <= MAX_PLAUSIBLE_LINEAR_SPEED else fallback[0]
        w = w if abs(w) <= MAX_PLAUSIBLE_ANGULAR_SPEED else fallback[1]
    return v, w


def as_ranges(z_scan: Any, log: ThrottledLogger) -> np.ndarray | None:
    """The scan as a 1-D float array, or None (with a warning) if it is not one."""
    try:
        # A copy as a contiguous float64 array: the one array type the kernels are compiled
        # for, and the controller may keep it (the caller may reuse its own array).
        ranges = np.array(z_scan, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        log.warning("scan", "WallFollower: scan is not a sequence of numbers; ignored")
        return None
    if ranges.size < 4:
        log.warning("readings", "WallFollower: scan has %d readings; ignored", ranges.size)
        return None
    return ranges


def limit_to_free_path(v: float, w: float, path_m: float, stop_distance_m: float,
                  slowdown_distance_m: float, max_linear: float, max_angular: float,
                  track_m: float) -> tuple[float, float]:
    """(v, w) within the limits.

    Zero if not finite; |w| <= max_angular; the forward speed ramped down to 0 as the free path
    ahead (`path_m`) shrinks to the stop distance; both wheels within the Burger's linear speed
    limit, the rotation taking priority.
    """
    if not (math.isfinite(v) and math.isfinite(w)):
        return 0.0, 0.0
    w = max(-max_angular, min(max_angular, w))
    if v > 0.0:
        ramp = (path_m - stop_distance_m) / max(slowdown_distance_m, 1e-3)
        v = min(v, max_linear * max(0.0, min(1.0, ramp)))
    v_max = max(0.0, MAX_LINEAR_SPEED - abs(w) * 0.5 * track_m)
    v = max(-v_max, min(v_max, v))
    return float(v), float(w)
