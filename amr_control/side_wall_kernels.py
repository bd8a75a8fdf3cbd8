"""Loop kernels for the walls beside the robot, in LocalPointCloud's cloud (scan_sectors.py).

The side queries of point_cloud_kernels.perceive and of the outer-corner decision: how close the
points on one side are, where the followed wall ends and resumes, the line fitted to the wall
alongside and how far ahead it reaches. Same conventions and the same reason for loops as
point_cloud_kernels.py: the cloud is one (3, n) array (x, y in m, robot frame, REP 103; ages in
s); `side` is +1.0 (left) or -1.0 (right); "none" results are NaN, "open" distances inf.
No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit

MIN_LATERAL_M = 0.02   # points closer than this to the robot's x axis are on neither side


@jit
def beside_distance(cloud, side, half_length):
    """Smallest lateral distance of the points on one side with |x| <= half_length; inf if none."""
    px = cloud[0]
    py = cloud[1]
    best = math.inf
    for i in range(px.shape[0]):
        lateral = side * py[i]
        if lateral >= MIN_LATERAL_M and abs(px[i]) <= half_length and lateral < best:
            best = lateral
    return best


@jit
def side_gap(cloud, side, max_lateral, lookback, ahead):
    """Points on one side within max_lateral: the last one behind and those ahead.

    Returns the largest x in [-lookback, 0] (NaN if none) and the number of points with x > 0,
    whose x are written to `ahead` in cloud order.
    """
    px = cloud[0]
    py = cloud[1]
    wall_end = math.nan
    count = 0
    for i in range(px.shape[0]):
        lateral = side * py[i]
        if lateral < MIN_LATERAL_M or lateral > max_lateral:
            continue
        x = px[i]
        if x > 0.0:
            ahead[count] = x
            count += 1
        elif x >= -lookback and not (x <= wall_end):   # also replaces the initial NaN
            wall_end = x
    return wall_end, count


@jit
def beside_points(cloud, side, max_lateral, half_length):
    """x, y and lateral distance of the points on one side beside the robot, in cloud order.

    Beside: within max_lateral and |x| <= half_length.
    """
    px = cloud[0]
    py = cloud[1]
    n = px.shape[0]
    xs = np.empty(n)
    ys = np.empty(n)
    lateral = np.empty(n)
    count = 0
    for i in range(n):
        d = side * py[i]
        if d >= MIN_LATERAL_M and d <= max_lateral and abs(px[i]) <= half_length:
            xs[count] = px[i]
            ys[count] = py[i]
            lateral[count] = d
            count += 1
    return xs[:count], ys[:count], lateral[:count]


@jit
def wall_reach(xs, lateral, side, window, fit_distance, fit_angle, beside):
    """How far ahead (x, m) the wall beside the robot continues without a 4 cm gap.

    From the beside points (x, lateral distance; see beside_points); NaN if there is none. Its
    points are those within 4 cm of the fitted line (fit_distance, fit_angle; NaN = no fit:
    within 4 cm of the `beside` distance; a fit steeper than 1 rad: all points).
    """
    if xs.shape[0] == 0:
        return math.nan
    have_fit = not math.isnan(fit_distance)
    slope = side * math.tan(fit_angle) if have_fit else 0.0
    chosen = np.empty(xs.shape[0])
    count = 0
    for i in range(xs.shape[0]):
        x = xs[i]
        if have_fit and abs(fit_angle) < 1.0:
            near = abs(lateral[i] - (fit_distance + x * slope)) <= 0.04
        elif not have_fit:
            near = abs(lateral[i] - beside) <= 0.04
        else:
            near = True
        if near and x >= -window:
            chosen[count] = x
            count += 1
    if count == 0:
        return math.nan
    ordered = np.sort(chosen[:count])
    previous = ordered[0]
    for x in ordered:                 # the first gap ends the wall
        if x - previous > 0.04:
            return previous
        previous = x
    return previous


@jit
def _fit_line(xs, ys, mask, min_points, min_span):
    """Total least squares line through the masked points.

    Returns (ok, distance, angle, span, mean x, mean y, normal x, normal y); the line's
    direction has a non-negative x component.
    """
    n = 0
    sum_x = 0.0
    sum_y = 0.0
    low = math.inf
    high = -math.inf
    for i in range(xs.shape[0]):
        if mask[i]:
            n += 1
            sum_x += xs[i]
            sum_y += ys[i]
            low = min(low, xs[i])
            high = max(high, xs[i])
    if n < min_points or high - low < min_span:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    mean_x = sum_x / n
    mean_y = sum_y / n
    sxx = 0.0
    sxy = 0.0
    syy = 0.0
    for i in range(xs.shape[0]):
        if mask[i]:
            cx = xs[i] - mean_x
            cy = ys[i] - mean_y
            sxx += cx * cx
            sxy += cx * cy
            syy += cy * cy
    # Principal axis of the 2x2 scatter matrix in closed form.
    theta = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    dx = math.cos(theta)
    dy = math.sin(theta)
    if dx < 0.0:
        dx = -dx
        dy = -dy
    normal_x = -dy
    normal_y = dx
    distance = abs(normal_x * mean_x + normal_y * mean_y)
    return True, distance, math.atan2(dy, dx), high - low, mean_x, mean_y, normal_x, normal_y


@jit
def fit_side_wall(xs, ys, lateral, min_points, min_span):
    """Line through the beside points (see beside_points) of one side, with outlier rejection.

    Start from the points within 6 cm of the median lateral distance (the wall
    alongside, not a wall leaving sideways at a corner), then refit on the points within 3 cm
    of the line until the inlier set stops changing (at most 3 fits).

    Returns (ok, distance, angle, rms residual, span along x, inlier count).
    """
    count = xs.shape[0]
    if count < min_points:
        return False, 0.0, 0.0, 0.0, 0.0, 0
    ordered = np.sort(lateral)
    half = count // 2
    median = ordered[half] if count % 2 else (ordered[half - 1] + ordered[half]) / 2.0
    mask = np.empty(count, np.bool_)
    for i in range(count):
        mask[i] = abs(lateral[i] - median) <= 0.06
    fit_mask = mask.copy()
    ok, distance, angle, span, mean_x, mean_y, nx, ny = _fit_line(xs, ys, mask, min_points,
                                                                  min_span)
    for iteration in range(3):
        if iteration > 0 and not np.array_equal(mask, fit_mask):
            # The same inliers give the same fit: refit only when the set changed.
            fit_mask = mask.copy()
            ok, distance, angle, span, mean_x, mean_y, nx, ny = _fit_line(
                xs, ys, mask, min_points, min_span)
        if not ok:
            return False, 0.0, 0.0, 0.0, 0.0, 0
        for i in range(count):
            mask[i] = abs((xs[i] - mean_x) * nx + (ys[i] - mean_y) * ny) <= 0.03
        if np.array_equal(mask, fit_mask):
            break                     # converged: further passes would repeat this one
    inliers = 0
    for i in range(count):
        if mask[i]:
            inliers += 1
    if not np.array_equal(mask, fit_mask):
        refit = _fit_line(xs, ys, mask, min_points, min_span)
        if refit[0]:
            ok, distance, angle, span, mean_x, mean_y, nx, ny = refit
            fit_mask = mask
    squares = 0.0
    used = 0
    for i in range(count):
        if fit_mask[i]:
            residual = (xs[i] - mean_x) * nx + (ys[i] - mean_y) * ny
            squares += residual * residual
            used += 1
    return True, distance, angle, math.sqrt(squares / used), span, inliers
