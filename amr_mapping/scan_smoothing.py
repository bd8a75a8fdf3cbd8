"""Smoothing a scan's range noise along the walls it sees (edge-preserving line fits).

A datasheet LiDAR's range noise grows with the range (LDS-01: up to 3.5 % beyond 0.5 m), each
ray on its own: drawn as measured, a wall seen from 2 m lands several cells deep. Neighbouring
rays that land on one straight wall tell where it is far better than any one of them: each
return moves along its own ray onto a line fitted (total least squares) through a window of
`2 * half_window + 1` neighbouring returns. Of the windows that contain it, the most central
one that is straight (within `straightness` times the scan's typical window) is used, else the
straightest: a window never reaches round a corner, and a line is known best at its middle. A
return stays as measured when even that window is not straight within `straightness` times the
datasheet's noise (an obstacle's corner, clutter), when it grazes the line (within 60 deg), or
when the line would move it more than two sigmas. Compiled (amr_common.jit); the `*_python`
functions are the plain twins.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from amr_common.jit import jit
from amr_common.sensors.lidar_models import LIDAR_MODELS
from amr_common.sensors.range_calibration import RangeCorrection
from amr_mapping.line_kernels import _small_eigen
from amr_mapping.scan_points import RangesFilter

MIN_INCIDENCE_COS = 0.5  # a return within 60 deg of grazing its line stays as measured
MAX_MOVE_SIGMAS = 2.0  # ... and one the line would move more than 2 expected sigmas


def smooth_ranges(ranges: np.ndarray, angles: np.ndarray, increment: float, half_window: int,
                  sigma: np.ndarray, straightness: float = 1.5) -> np.ndarray:
    """Ranges moved onto their window's line (see the module docstring).

    ranges, angles: the usable returns (LiDAR frame), in scan order; increment: the scan's
    angle step (rays further apart than 1.5 steps are not neighbours); sigma: each return's
    expected noise (m), the datasheet's. The compiled smooth_ranges_kernel.
    """
    ranges = np.ascontiguousarray(ranges, dtype=np.float64)
    out = np.empty_like(ranges)
    smooth_ranges_kernel(ranges, np.ascontiguousarray(angles, dtype=np.float64),
                         float(increment), int(half_window),
                         np.ascontiguousarray(sigma, dtype=np.float64), float(straightness), out)
    return out


def smooth_ranges_python(ranges, angles, increment, half_window, sigma, straightness, out):
    """Out = the smoothed ranges (plain twin of smooth_ranges_kernel)."""
    n = ranges.size
    width = 2 * half_window + 1
    for i in range(n):
        out[i] = ranges[i]
    if half_window <= 0 or n < width:
        return
    windows = n - width + 1
    cos, sin = np.cos(angles), np.sin(angles)
    lines = np.empty((windows, 5))  # per window: centroid x, y, unit normal x, y, score
    _window_lines(ranges * cos, ranges * sin, angles, abs(increment) * 1.5, sigma, width,
                  lines)
    finite = lines[:, 4][np.isfinite(lines[:, 4])]
    typical = np.median(finite) if finite.size else 1.0
    limit = straightness * straightness * typical
    for i in range(n):
        w = _chosen_window(lines, i, half_window, limit)
        if w < 0 or not lines[w, 4] <= straightness * straightness:
            continue  # not straight by the datasheet's noise: as measured
        along = lines[w, 2] * cos[i] + lines[w, 3] * sin[i]
        if abs(along) <= MIN_INCIDENCE_COS:
            continue
        fitted = (lines[w, 2] * lines[w, 0] + lines[w, 3] * lines[w, 1]) / along
        if fitted > 0.0 and abs(fitted - ranges[i]) <= MAX_MOVE_SIGMAS * sigma[i]:
            out[i] = fitted


def _window_lines_python(x, y, angles, max_step, sigma, width, lines):
    """lines[j] = (centroid x, y, unit normal x, y, score) of the window [j, j + width).

    score: the mean squared distance from the line over the mean sigma squared; inf for a
    window with rays further apart than max_step.
    """
    for j in range(lines.shape[0]):
        sx = sy = ss = 0.0
        gap = False
        for k in range(j, j + width):
            sx += x[k]
            sy += y[k]
            ss += sigma[k]
            if k > j and abs(angles[k] - angles[k - 1]) > max_step:
                gap = True
        mx, my, mean_sigma = sx / width, sy / width, ss / width
        cxx = cyy = cxy = 0.0
        for k in range(j, j + width):
            dx = x[k] - mx
            dy = y[k] - my
            cxx += dx * dx
            cyy += dy * dy
            cxy += dx * dy
        small, _, nx, ny = _small_eigen(cxx / width, cxy / width, cyy / width)
        lines[j, 0], lines[j, 1], lines[j, 2], lines[j, 3] = mx, my, nx, ny
        lines[j, 4] = math.inf if gap else max(small, 0.0) / (mean_sigma * mean_sigma)


def _chosen_window_python(lines, i, half_window, limit):
    """Return i's window: the most central one scoring within limit, else the best (-1: none)."""
    best, chosen = math.inf, -1
    for distance in range(half_window + 1):
        for side in range(2):
            if distance == 0 and side == 1:
                continue
            start = i - (half_window - distance if side == 0 else half_window + distance)
            if start < 0 or start >= lines.shape[0]:
                continue
            score = lines[start, 4]
            if score <= limit:
                return start
            if score < best:
                best, chosen = score, start
    return chosen


_window_lines = jit(_window_lines_python)
_chosen_window = jit(_chosen_window_python)
smooth_ranges_kernel = jit(smooth_ranges_python)


def ranges_filter(params: dict[str, Any]) -> RangesFilter | None:
    """The Mapper's filter of a scan's usable ranges: calibration, then smoothing (or None).

    Parameters `range_correction`, `smooth_half_window`, `smooth_straightness`, `lidar_model`
    (its precision gives the noise's growth with the range; 'none': the same everywhere).
    """
    correction = RangeCorrection.from_list(params["range_correction"])
    half_window = int(params["smooth_half_window"])
    if correction is None and half_window == 0:
        return None
    model = LIDAR_MODELS.get(params["lidar_model"])
    straightness = float(params["smooth_straightness"])

    def apply(ranges: np.ndarray, angles: np.ndarray, increment: float) -> np.ndarray:
        if correction is not None:
            ranges = correction.apply(ranges)
        if half_window:
            sigma = model.bounds(ranges)[1] if model is not None else np.full(ranges.size, 0.01)
            ranges = smooth_ranges(ranges, angles, increment, half_window, sigma, straightness)
        return ranges
    return apply


__all__ = ["ranges_filter", "smooth_ranges", "smooth_ranges_kernel", "smooth_ranges_python"]
