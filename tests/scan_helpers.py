"""A synthetic LiDAR for the wall follower's tests: scan layouts and exact ray casting.

`cast(segments, layout, pose)` reads wall segments as a scanner with one of the layouts below
would (no_return outside [range_min, range_max]); plain numpy, independent of
amr_common.world.raycast.
"""
from __future__ import annotations

import math

import numpy as np

# Scan layouts: (rays, angle_min, range_min, range_max, no_return)
COURSE_240 = (240, 0.0, 0.016, 8.0, math.nan)
LDS01_360 = (360, 0.0, 0.12, 3.5, 0.0)
LDS02_ODD = (452, -3.05, 0.0, 100.0, math.nan)   # count and start angle unlike the others


def cast(segments, layout, pose=(0.0, 0.0, 0.0), rays=None):
    """Ranges a LiDAR at `pose` reads from wall segments [[x1, y1, x2, y2], ...]."""
    n, angle_min, range_min, range_max, no_return = layout
    n = rays or n
    x, y, th = pose
    angles = th + angle_min + 2.0 * math.pi / n * np.arange(n)
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    seg = np.asarray(segments, dtype=float)
    ax, ay = seg[:, 0] - x, seg[:, 1] - y
    ex, ey = seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ax * ey - ay * ex) / denom
        u = (ax * dy - ay * dx) / denom
    t = np.where((np.abs(denom) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1), t, np.inf)
    r = t.min(axis=1)
    return np.where((r >= range_min) & (r <= range_max), r, no_return)
