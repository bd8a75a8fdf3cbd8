"""What a real scanner needs on top of point_cloud_kernels: de-skewed rays and an obstacle memory.

De-skew. The Burger's LiDARs (LDS-01, LDS-02) turn clockwise and their drivers stamp a scan at
the END of its revolution: a ray at angle a (counter-clockwise, rad) was measured
revolution * (a mod 2 pi) / (2 pi) before the stamp (docs/reality-gap.md, "Scan skew"). A robot
driving at 0.2 m/s sees the wall on its right 3 cm too far ahead, a robot turning at 1.5 rad/s
sees its surroundings smeared over 17 deg. `deskew_point` moves each ray's point from the pose
the ray was measured at to the pose at the stamp, with the odometry twist (constant over one
revolution).

Memory. The points of the last scans stay in `memory` (used for the swept-path check only) for
`memory_time` seconds after a scan last showed a point in their cell, within `memory_range` of
the robot. Why: the end of a thin wall seen end-on returns no ray at all (every ray passes beside
it, or grazes it and returns nothing), so a robot driving along the wall's line toward its end
sees free space up to the contact; the wall end was in earlier scans, taken from beside the line.
The memory is kept in the odometry frame on a grid of `cell` m (one point per cell, the newest):
a new point replaces only the point of its own cell. Replacing an old point by any new point
near it instead lets a wall's end creep away scan after scan, as the grazing rays that still
return hit the wall ever farther from its end. A remembered point counts only where the current
cloud has no point within `match` of it (what the scans show now is taken from them).

Numba-compiled through amr_common.jit (the plain functions are the twins); no rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit
from amr_common.robot import arc_displacement_kernel

TWO_PI = 2.0 * math.pi
CELL_OFFSET = 1 << 30   # grid indices made non-negative (cells of >= 1 mm over 1,000 km)
CELL_SPAN = 1 << 31


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
def advance_pose(pose, distance, rotation, dt):
    """In place: pose = [x, y, theta, time] (odometry frame) after a step of the odometry."""
    shift_x, shift_y = arc_displacement_kernel(pose[2], distance, rotation)
    pose[0] += shift_x
    pose[1] += shift_y
    pose[2] += rotation
    pose[3] += dt


@jit
def remember(memory, cloud, n_new, pose, memory_time, memory_range, cell):
    """The memory after a new scan: the newest point per cell of the new scan and the memory.

    memory: (3, m) rows x, y (odometry frame, m), time last seen (s); cloud: the merged cloud
    (robot frame), its first n_new columns the new scan's points; pose: [x, y, theta, time].
    Points older than memory_time or farther than memory_range from the robot are dropped.
    """
    if memory_time <= 0.0:
        return np.zeros((3, 0))
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    now = pose[3]
    range_squared = memory_range * memory_range
    total = memory.shape[1] + n_new
    points = np.empty((3, total))
    keys = np.empty(total, np.int64)
    m = 0
    for source in range(2):
        count = memory.shape[1] if source == 0 else n_new
        for i in range(count):
            if source == 0:
                x = memory[0, i]
                y = memory[1, i]
                seen = memory[2, i]
                if now - seen >= memory_time:
                    continue
            else:
                x = pose[0] + c * cloud[0, i] - s * cloud[1, i]
                y = pose[1] + s * cloud[0, i] + c * cloud[1, i]
                seen = now
            dx = x - pose[0]
            dy = y - pose[1]
            if dx * dx + dy * dy > range_squared:
                continue
            points[0, m] = x
            points[1, m] = y
            points[2, m] = seen
            keys[m] = (int(math.floor(x / cell)) + CELL_OFFSET) * CELL_SPAN + (
                int(math.floor(y / cell)) + CELL_OFFSET)
            m += 1
    order = np.argsort(keys[:m], kind="mergesort")   # stable: the newest of a cell comes last
    out = np.empty((3, m))
    k = 0
    for j in range(m):
        i = order[j]
        if j + 1 < m and keys[order[j + 1]] == keys[i]:
            continue
        out[0, k] = points[0, i]
        out[1, k] = points[1, i]
        out[2, k] = points[2, i]
        k += 1
    return out[:, :k].copy()  # contiguous: one array type for the kernels


@jit
def memory_path_distance(memory, pose, half_width, cloud, match, best):
    """The swept path's length (see point_cloud_kernels.path_distance) with the memory's points.

    `best`: the path length through the cloud's points. A remembered point shortens it only if
    no point of the cloud (robot frame) lies within `match` of it: the scans still show that
    place, and the range noise of 15 scans would otherwise bring every wall closer by their
    worst draw. Returns min(best, the closest such point's x ahead).
    """
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    match_squared = match * match
    for i in range(memory.shape[1]):
        dx = memory[0, i] - pose[0]
        dy = memory[1, i] - pose[1]
        x = c * dx + s * dy
        y = -s * dx + c * dy
        if not (0.0 < x < best and abs(y) <= half_width):
            continue
        explained = False
        for j in range(cloud.shape[1]):
            ex = cloud[0, j] - x
            ey = cloud[1, j] - y
            if ex * ex + ey * ey <= match_squared:
                explained = True
                break
        if not explained:
            best = x
    return best
