"""What a real scanner needs on top of point_cloud_kernels: de-skewed rays and an obstacle memory.

De-skew. The Burger's LiDARs (LDS-01, LDS-02) turn clockwise and their drivers stamp a scan at
the END of its revolution: a ray at angle a (counter-clockwise, rad) was measured
revolution * (a mod 2 pi) / (2 pi) before the stamp (docs/reality-gap.md, "Scan skew"). A robot
driving at 0.2 m/s sees the wall on its right 3 cm too far ahead, a robot turning at 1.5 rad/s
sees its surroundings smeared over 17 deg. `deskew_point` moves each ray's point from the pose
the ray was measured at to the pose at the stamp, with the odometry twist (constant over one
revolution).

Memory. A point seen before stays in `memory` (used for the swept-path check only) while the
newest scan does not explain it, i.e. has no point within `match` of it, for `memory_time`
seconds and within `memory_range` of the robot. Why: the end of a thin wall seen end-on returns
no ray at all (every ray passes beside it, or grazes it and returns nothing), so a robot driving
along the wall's line toward its end sees free space up to the contact; the wall end was in
earlier scans, taken from beside the line. Points the scan explains again are dropped (their
fresh twin is in the cloud), so the memory holds only what the scanner cannot see now.

Numba-compiled through amr_common.jit (the plain functions are the twins); no rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit
from amr_common.robot import arc_displacement_kernel

TWO_PI = 2.0 * math.pi


@jit
def deskew_point(x, y, angle, revolution, speed, turn_rate):
    """(x, y) of a ray's point (robot frame at the ray's time) in the robot frame at the stamp.

    The ray at `angle` (rad, counter-clockwise) was measured revolution * (angle mod 2 pi) /
    (2 pi) s before the stamp; since then the robot drove `speed` (m/s, along the chord) and
    turned `turn_rate` (rad/s). revolution 0: unchanged.
    """
    if revolution <= 0.0:
        return x, y
    age = revolution * (angle % TWO_PI) / TWO_PI
    rotation = turn_rate * age
    shift_x, shift_y = arc_displacement_kernel(0.0, speed * age, rotation)
    sx = x - shift_x
    sy = y - shift_y
    c = math.cos(rotation)
    s = math.sin(rotation)
    return c * sx + s * sy, -s * sx + c * sy


@jit
def _explained(x, y, new_cloud, ray_point, angle_min, angle_increment, lidar_offset_x,
               match):
    """True if a point of the new scan lies within `match` of (x, y) (robot frame, m).

    Only the rays whose direction passes within `match` of the point are searched (their index
    from the point's bearing seen from the LiDAR); ray_point[i] is ray i's column in new_cloud
    (-1: no return).
    """
    n_rays = ray_point.shape[0]
    lx = x - lidar_offset_x
    r = math.sqrt(lx * lx + y * y)
    step = abs(angle_increment)
    if r <= match:
        k = n_rays // 2
    else:
        k = int(math.asin(match / r) / step) + 1
    k = min(k, n_rays // 2)
    direction = 1.0 if angle_increment > 0.0 else -1.0
    centre = int(round((((math.atan2(y, lx) - angle_min) * direction) % TWO_PI) / step))
    full_turn = int(round(TWO_PI / step))
    match_squared = match * match
    for offset in range(-k, k + 1):
        ray = centre + offset
        if full_turn > 0:
            ray = ray % full_turn
        if ray < 0 or ray >= n_rays:
            continue
        j = ray_point[ray]
        if j < 0:
            continue
        dx = new_cloud[0, j] - x
        dy = new_cloud[1, j] - y
        if dx * dx + dy * dy <= match_squared:
            return True
    return False


@jit
def remember(old_cloud, memory, new_cloud, ray_point, angle_min, angle_increment,
             lidar_offset_x, memory_time, memory_range, match):
    """The memory after a new scan: old points (cloud and memory) the new scan does not explain.

    Kept: younger than memory_time (s since a scan last showed them), within memory_range of
    the robot centre, and no point of the new scan within `match` (m) of them (see _explained).
    Returns a (3, m) array: x, y, age.
    """
    n_cloud = old_cloud.shape[1]
    n_memory = memory.shape[1]
    out = np.empty((3, n_cloud + n_memory))
    if memory_time <= 0.0:
        return out[:, :0].copy()
    range_squared = memory_range * memory_range
    m = 0
    for source in range(2):
        points = old_cloud if source == 0 else memory
        for i in range(points.shape[1]):
            x = points[0, i]
            y = points[1, i]
            age = points[2, i]
            if age >= memory_time or x * x + y * y > range_squared:
                continue
            if _explained(x, y, new_cloud, ray_point, angle_min, angle_increment,
                          lidar_offset_x, match):
                continue
            out[0, m] = x
            out[1, m] = y
            out[2, m] = age
            m += 1
    return out[:, :m].copy()  # contiguous, as the cloud: one array type for the kernels
