"""Loop kernels behind LocalPointCloud (scan_sectors.py).

They move the points with the odometry, merge a new scan, and answer the per-step queries
(sectors, swept path; the side walls and their line fit: side_wall_kernels.py), all in one call
per control step (step_cloud).

Why loops: the wall follower runs these on a few hundred points every control step, and as
numpy expressions they were ~75 small array operations (~0.3 ms per step, most of it call
overhead). As numba-compiled loops they take a few microseconds each. Without numba the same
functions run as plain Python (slower, ~ms per step, still far inside a 50 ms control period).

Conventions: the cloud is one (3, n) array whose rows are the points' x and y (m, robot frame,
REP 103) and their ages (s since their ray last returned them); `side` is +1.0 (left) or -1.0
(right); "none" results are NaN, "open" distances inf. No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit
from amr_common.robot import arc_displacement_kernel
from amr_common.sensors.scan_returns import is_return
from amr_control.point_memory_kernels import (
    advance_pose,
    deskew_point,
    memory_path_distance,
    remember,
)
from amr_control.side_wall_kernels import (
    beside_distance,
    beside_points,
    fit_side_wall,
    side_gap,
    wall_reach,
)

TWO_PI = 2.0 * math.pi


@jit
def move_points(cloud, distance, rotation, dt):
    """In place: age every point by dt and move it into the robot frame after a motion.

    The robot drove `distance` (m) along the chord of an arc and turned `rotation` (rad).
    """
    px = cloud[0]
    py = cloud[1]
    ages = cloud[2]
    n = px.shape[0]
    for i in range(n):
        ages[i] += dt
    if n == 0 or (distance == 0.0 and rotation == 0.0):
        return
    shift_x, shift_y = arc_displacement_kernel(0.0, distance, rotation)  # in the old frame
    c = math.cos(rotation)
    s = math.sin(rotation)
    for i in range(n):
        sx = px[i] - shift_x
        sy = py[i] - shift_y
        # Rotate by -rotation: the new frame is the old one turned by +rotation.
        px[i] = c * sx + s * sy
        py[i] = -s * sx + c * sy


@jit
def same_readings(last, ranges):
    """True if two scans have the same readings (NaN equal to NaN): a held LaserScan."""
    if last.shape[0] != ranges.shape[0]:
        return False
    for i in range(ranges.shape[0]):
        a = last[i]
        b = ranges[i]
        if a != b and not (math.isnan(a) and math.isnan(b)):
            return False
    return True


@jit
def merge_scan(cloud, ranges, ray_cos, ray_sin, angle_min, angle_increment,
               range_min, range_max, hold_range, hold_time, lidar_offset_x,
               revolution, speed, turn_rate):
    """The cloud after a new scan: its valid readings (age 0) followed by the held points.

    Held: close points younger than hold_time whose ray in this scan returned nothing. Each
    reading is de-skewed to the scan's stamp (point_memory_kernels.deskew_point: `revolution`
    s per scan, the odometry twist `speed`, `turn_rate`; revolution 0: rays taken at once).

    Returns (new cloud, number of valid readings).
    """
    px = cloud[0]
    py = cloud[1]
    ages = cloud[2]
    n_rays = ranges.shape[0]
    valid = np.empty(n_rays, np.bool_)
    n_new = 0
    for i in range(n_rays):
        r = ranges[i]
        ok = is_return(r, range_min, range_max)
        valid[i] = ok
        if ok:
            n_new += 1
    # With every ray valid no point can be held: skip the per-point bearings (atan2 is most
    # of this kernel's time, and the ideal profile's scans are always complete).
    n_old = px.shape[0] if n_new < n_rays else 0
    keep = np.empty(n_old, np.int64)
    n_keep = 0
    step = abs(angle_increment)
    direction = 1.0 if angle_increment > 0.0 else -1.0
    full_turn = int(round(TWO_PI / step))
    hold_range_squared = hold_range * hold_range
    for j in range(n_old):
        if px[j] * px[j] + py[j] * py[j] <= hold_range_squared and ages[j] < hold_time:
            offset = ((math.atan2(py[j], px[j]) - angle_min) * direction) % TWO_PI
            ray = int(round(offset / step))
            if ray >= full_turn:
                ray -= full_turn
            if not (0 <= ray < n_rays and valid[ray]):
                keep[n_keep] = j
                n_keep += 1
    merged = np.empty((3, n_new + n_keep))
    k = 0
    for i in range(n_rays):
        if valid[i]:
            x, y = deskew_point(ranges[i] * ray_cos[i] + lidar_offset_x, ranges[i] * ray_sin[i],
                                angle_min + i * angle_increment, revolution, speed, turn_rate)
            merged[0, k] = x
            merged[1, k] = y
            merged[2, k] = 0.0
            k += 1
    for m in range(n_keep):
        j = keep[m]
        merged[0, k] = px[j]
        merged[1, k] = py[j]
        merged[2, k] = ages[j]
        k += 1
    return merged, n_new


@jit
def sector_distances(cloud, centre_cos, centre_sin, half_width, percentiles, out):
    """For each sector: the closest range in it, or a percentile; inf if it is empty.

    A sector is a centre direction (centre_cos, centre_sin) +-half_width < pi/2; its
    `percentiles[s]`-th percentile (lowest-rank value) is reported when that is > 0.
    """
    n = cloud.shape[1]
    ranges = np.empty(n)
    for i in range(n):
        ranges[i] = math.sqrt(cloud[0, i] * cloud[0, i] + cloud[1, i] * cloud[1, i])
    cos_half_width = math.cos(half_width)
    inside = np.empty(n)
    for s in range(centre_cos.shape[0]):
        cc = centre_cos[s]
        sc = centre_sin[s]
        closest = math.inf
        count = 0
        for i in range(n):
            r = ranges[i]
            # Within half_width of the centre direction: cos(angle between) >= cos(half_width).
            if cloud[0, i] * cc + cloud[1, i] * sc >= r * cos_half_width:
                if r < closest:
                    closest = r
                inside[count] = r
                count += 1
        if percentiles[s] <= 0.0 or count == 0:
            out[s] = closest
        else:
            k = int(percentiles[s] / 100.0 * (count - 1))
            out[s] = np.sort(inside[:count])[k]


@jit
def path_distance(cloud, half_width):
    """Smallest x > 0 of the points with |y| <= half_width (the swept corridor ahead).

    inf if there is none.
    """
    px = cloud[0]
    py = cloud[1]
    best = math.inf
    for i in range(px.shape[0]):
        x = px[i]
        if x > 0.0 and abs(py[i]) <= half_width and x < best:
            best = x
    return best


@jit
def perceive(cloud, side, sector_cos, sector_sin, sector_half_width, sector_percentiles,
             path_half_width, side_window, side_open, fit_half_length, min_points, min_span,
             sector_out):
    """Everything the wall follower asks of the cloud in one control step, in one call.

    Each separate call from Python costs ~2 us of dispatch, as much as the work itself.

    sector_out: sector_distances of the sectors given (closest or percentile range, inf = open).
    Returns (path distance, beside distance on the followed side, beside distance on the other
    side (both within +-side_window along x), fit_side_wall's 6 values for the followed side
    within side_open and +-fit_half_length, and wall_reach of that side (NaN = none)).
    """
    sector_distances(cloud, sector_cos, sector_sin, sector_half_width, sector_percentiles,
                     sector_out)
    path = path_distance(cloud, path_half_width)
    beside_followed = beside_distance(cloud, side, side_window)
    beside_other = beside_distance(cloud, -side, side_window)
    xs, ys, lateral = beside_points(cloud, side, side_open, fit_half_length)
    fit = fit_side_wall(xs, ys, lateral, min_points, min_span)
    reach = wall_reach(xs, lateral, side, side_window, fit[1] if fit[0] else math.nan, fit[2],
                       beside_followed)
    return path, beside_followed, beside_other, fit, reach


# Layout of step_cloud's `config` array (values fixed for a controller's lifetime).
CONFIG_FIELDS = ("hold_range", "hold_time", "lidar_offset_x", "side", "sector_half_width",
                 "path_half_width", "side_window", "side_open", "fit_half_length", "min_points",
                 "min_span", "revolution", "memory_time", "memory_range", "memory_cell",
                 "memory_match")


@jit
def step_cloud(cloud, memory, pose, distance, rotation, dt, ranges, scan_given, last_scan,
               ray_cos, ray_sin, angle_min, angle_increment, range_min, range_max, config,
               sectors, sector_out):
    """One control step in one call: move the cloud, merge the scan, remember, perceive.

    The cloud moves with the odometry (and `pose`, the odometry pose [x, y, theta, time], in
    place); the scan is merged (de-skewed with this step's odometry twist) if it differs from
    `last_scan`, and its points go into the memory (point_memory_kernels.remember); then
    perceive (see perceive; `sectors` rows: centre cos, centre sin, percentile), the swept path
    also through the memory's points. One call instead of several matters inside a ROS loop:
    every call wakes numba's dispatcher, which costs ~20 us when the caches are cold.

    Returns (cloud, memory, valid readings of the merged scan or -1 if none was merged, then
    perceive's values).
    """
    move_points(cloud, distance, rotation, dt)
    advance_pose(pose, distance, rotation, dt)
    valid = -1
    if scan_given and not same_readings(last_scan, ranges):
        cloud, valid = merge_scan(
            cloud, ranges, ray_cos, ray_sin, angle_min, angle_increment, range_min, range_max,
            config[0], config[1], config[2], config[11], distance / dt, rotation / dt)
        memory = remember(memory, cloud, valid, pose, config[12], config[13], config[14])
    path, beside, beside_other, fit, reach = perceive(
        cloud, config[3], sectors[0], sectors[1], config[4], sectors[2], config[5], config[6],
        config[7], config[8], int(config[9]), config[10], sector_out)
    path = memory_path_distance(memory, pose, config[5], cloud, config[15], path)
    return cloud, memory, valid, path, beside, beside_other, fit, reach


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel now, on tiny inputs.

    So that the first control step does not pay for it (seconds on a first run, ~0.1 s from
    the cache).
    """
    cloud = np.array([[0.3, 0.1, -0.2], [0.2, -0.2, 0.25], [0.0, 0.0, 0.0]])
    ranges = np.array([1.0, 0.2, math.nan, 0.0])
    table = np.array([1.0, 0.0, -1.0, 0.0])
    config = np.array([0.3, 0.6, 0.0, -1.0, 0.2, 0.135, 0.03, 0.32, 0.15, 6.0, 0.06, 0.2, 8.0,
                       0.7, 0.02, 0.03])
    sectors = np.array([table, table, table])
    cloud = step_cloud(cloud, np.zeros((3, 0)), np.zeros(4), 0.01, 0.01, 0.05, ranges, True,
                       np.zeros(0), table, table, 0.0, math.pi / 2, 0.1, 3.5, config, sectors,
                       np.empty(4))[0]
    side_gap(cloud, -1.0, 0.32, 0.6, np.empty(cloud.shape[1]))
