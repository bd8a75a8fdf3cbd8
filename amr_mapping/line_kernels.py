"""Compiled loops of the sub-cell refinement: local wall lines and point-to-line Gauss-Newton.

The correlative search (match_kernels) finds the best pose on a lattice of one cell and one
angular step; this refines it below a millimetre where the map allows. Each cell gets the line
fitted to the hits of its 3 x 3 neighbourhood (their mean and the direction of least spread,
from the moments grid_kernels.trace_rays keeps), if those hits lie along a line; a scan point's
residual is its distance to the line of the cell it falls in (point-to-line ICP, as PL-ICP and
NDT do, on the map rather than on one scan). Gauss-Newton minimises the sum of the squared
residuals over sigma_point^2 (points farther than max_distance from their line are outliers,
left out) plus the prior's, so directions the walls do not fix (along a featureless corridor)
stay with the odometry.

Grid coordinates as grid_kernels: cell units from the window's corner, cell (r, c) covers
[c, c + 1) x [r, r + 1). The `*_python` functions are the plain twins of the compiled ones.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit


def _small_eigen_python(a, b, c):
    """(smaller eigenvalue, larger, unit eigenvector x, y of the smaller) of [[a, b], [b, c]]."""
    half = 0.5 * (a + c)
    disc = math.sqrt(max(0.25 * (a - c) * (a - c) + b * b, 0.0))
    small = half - disc
    ax = b
    ay = small - a
    bx = small - c
    by = b
    if ax * ax + ay * ay >= bx * bx + by * by:
        vx, vy = ax, ay
    else:
        vx, vy = bx, by
    norm = math.sqrt(vx * vx + vy * vy)
    if not norm > 0.0:  # isotropic
        return small, half + disc, 1.0, 0.0
    return small, half + disc, vx / norm, vy / norm


_small_eigen = jit(_small_eigen_python)


def fit_lines_python(hits, sums, row_off, col_off, min_hits, max_ratio, lines):
    """lines[:, r, c] = (nx, ny, d, valid): the line n . p = d of each cell of a window.

    Window cell (r, c) is grid cell (r + row_off, c + col_off) of hits / sums (the grid's);
    n . p = d in window cell units. From the hits of the 3 x 3 cells around it; valid 1 when
    there are at least min_hits and the smaller eigenvalue of their covariance is at most
    max_ratio times the larger.
    """
    grid_rows, grid_cols = hits.shape
    rows = lines.shape[1]
    cols = lines.shape[2]
    for i in range(rows):
        for j in range(cols):
            lines[3, i, j] = 0.0
            n = 0.0
            sx = 0.0
            sy = 0.0
            sxx = 0.0
            sxy = 0.0
            syy = 0.0
            for di in range(-1, 2):
                ii = i + di + row_off
                if ii < 0 or ii >= grid_rows:
                    continue
                for dj in range(-1, 2):
                    jj = j + dj + col_off
                    if jj < 0 or jj >= grid_cols:
                        continue
                    h = hits[ii, jj]
                    if h <= 0:
                        continue
                    s0 = sums[0, ii, jj]
                    s1 = sums[1, ii, jj]
                    # moments about (jj, ii): shift them to the corner of cell (i, j)
                    n += h
                    sx += s0 + h * dj
                    sy += s1 + h * di
                    sxx += sums[2, ii, jj] + 2.0 * dj * s0 + h * dj * dj
                    sxy += sums[3, ii, jj] + dj * s1 + di * s0 + h * dj * di
                    syy += sums[4, ii, jj] + 2.0 * di * s1 + h * di * di
            if n < min_hits:
                continue
            mx = sx / n
            my = sy / n
            cxx = sxx / n - mx * mx
            cxy = sxy / n - mx * my
            cyy = syy / n - my * my
            # the normal of the line: the direction of least spread
            small, large, nx, ny = _small_eigen(cxx, cxy, cyy)
            if not large > 0.0 or small > max_ratio * large:
                continue
            lines[0, i, j] = nx
            lines[1, i, j] = ny
            lines[2, i, j] = nx * (mx + j) + ny * (my + i)
            lines[3, i, j] = 1.0


def _solve3_python(a, b, out):
    """Solve a x = -b into out for a symmetric 3 x 3 a (Cramer's rule); False if singular."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    if not abs(det) > 1e-300:
        return False
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    inv = -1.0 / det
    out[0] = inv * (c00 * b[0] + c01 * b[1] + c02 * b[2])
    out[1] = inv * (c01 * b[0] + c11 * b[1] + c12 * b[2])
    out[2] = inv * (c02 * b[0] + c12 * b[1] + c22 * b[2])
    return True


_solve3 = jit(_solve3_python)


def refine_lines_python(lines, col0, row0, resolution, points, pose, prior, prior_weights,
                        point_weight, max_distance, iterations, degenerate_ratio, out):
    """Gauss-Newton of point-to-line residuals from pose; writes [x, y, theta, points used].

    lines: (4, rows, cols) from fit_lines over the window whose corner is global cell
    (row0, col0); points (N, 2) robot frame; prior (x, y, theta) with prior_weights
    [1/sigma_x, 1/sigma_y, 1/sigma_theta] (0: no prior); point_weight 1/sigma_point (1/m);
    max_distance (m): points farther from their line are left out. Steps are limited to one
    cell and 0.02 rad; stops after `iterations` or when a step is below 1e-7.
    Degeneracy (with a prior): if the walls fix one direction of translation less than
    degenerate_ratio times the other (the eigenvalues of the points' information), the
    result keeps the prior's position along it (solution remapping, Zhang et al. 2016): slight
    tilts of the fitted lines along a featureless corridor are not information.
    Long: one compiled loop on purpose (~100 lines): the residuals and the 3 x 3 normal equations
    are accumulated in place, per point, per iteration.
    """
    rows = lines.shape[1]
    cols = lines.shape[2]
    inv_res = 1.0 / resolution
    x = pose[0]
    y = pose[1]
    th = pose[2]
    hess = np.zeros((3, 3))
    grad = np.zeros(3)
    step = np.zeros(3)
    used = 0
    info_xx = info_xy = info_yy = 0.0  # the points' information on x, y (last iteration)
    for _ in range(iterations):
        c = math.cos(th)
        s = math.sin(th)
        hess[:, :] = 0.0
        grad[:] = 0.0
        used = 0
        for k in range(points.shape[0]):
            p0 = points[k, 0]
            p1 = points[k, 1]
            u = (x + c * p0 - s * p1) * inv_res - col0
            v = (y + s * p0 + c * p1) * inv_res - row0
            i = math.floor(v)
            j = math.floor(u)
            if i < 0 or j < 0 or i >= rows or j >= cols or lines[3, i, j] == 0.0:
                continue
            nx = lines[0, i, j]
            ny = lines[1, i, j]
            distance = (nx * u + ny * v - lines[2, i, j]) * resolution
            if abs(distance) > max_distance:
                continue
            used += 1
            r = point_weight * distance
            j0 = point_weight * nx
            j1 = point_weight * ny
            j2 = point_weight * (nx * (-s * p0 - c * p1) + ny * (c * p0 - s * p1))
            hess[0, 0] += j0 * j0
            hess[0, 1] += j0 * j1
            hess[0, 2] += j0 * j2
            hess[1, 1] += j1 * j1
            hess[1, 2] += j1 * j2
            hess[2, 2] += j2 * j2
            grad[0] += j0 * r
            grad[1] += j1 * r
            grad[2] += j2 * r
        info_xx = hess[0, 0]
        info_xy = hess[0, 1]
        info_yy = hess[1, 1]
        dth = th - prior[2]
        dth -= 2.0 * math.pi * math.floor((dth + math.pi) / (2.0 * math.pi))
        wx2 = prior_weights[0] * prior_weights[0]
        wy2 = prior_weights[1] * prior_weights[1]
        wt2 = prior_weights[2] * prior_weights[2]
        hess[0, 0] += wx2 + 1e-6
        hess[1, 1] += wy2 + 1e-6
        hess[2, 2] += wt2 + 1e-6
        grad[0] += wx2 * (x - prior[0])
        grad[1] += wy2 * (y - prior[1])
        grad[2] += wt2 * dth
        hess[1, 0] = hess[0, 1]
        hess[2, 0] = hess[0, 2]
        hess[2, 1] = hess[1, 2]
        if not _solve3(hess, grad, step):
            break
        limit = max(abs(step[0]), abs(step[1])) * inv_res
        if limit > 1.0:
            step[0] /= limit
            step[1] /= limit
            step[2] /= limit
        if abs(step[2]) > 0.02:
            scale = 0.02 / abs(step[2])
            step[0] *= scale
            step[1] *= scale
            step[2] *= scale
        x += step[0]
        y += step[1]
        th += step[2]
        if abs(step[0]) + abs(step[1]) < 1e-7 and abs(step[2]) < 1e-7:
            break
    if prior_weights[0] > 0.0 and used > 0:
        small, large, dx, dy = _small_eigen(info_xx, info_xy, info_yy)
        if small < degenerate_ratio * large:
            along = dx * (prior[0] - x) + dy * (prior[1] - y)
            x += along * dx
            y += along * dy
    out[0] = x
    out[1] = y
    out[2] = th
    out[3] = used


fit_lines = jit(fit_lines_python)
refine_lines = jit(refine_lines_python)

__all__ = ["fit_lines", "fit_lines_python", "refine_lines", "refine_lines_python"]
