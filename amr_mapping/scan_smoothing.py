"""Smoothing a scan's range noise along the walls it sees (edge-preserving line fits).

A datasheet LiDAR's range noise grows with the range (LDS-01: up to 3.5 % beyond 0.5 m), each
ray on its own. Neighbouring rays that land on one straight wall tell where the wall is far
better than any one of them: each return is moved along its own ray onto a line fitted (total
least squares) through a window of `2 * half_window + 1` neighbouring returns. Of the windows
that contain the return, the straightest is used (so a window never reaches round a corner);
when even that one is not straight within `straightness` times the expected noise, the return
stays as measured (an obstacle's corner, clutter).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from amr_common.lidar_models import LIDAR_MODELS
from amr_common.range_calibration import RangeCorrection

MIN_INCIDENCE_COS = 0.5  # a return within 60 deg of grazing its line stays as measured
MAX_MOVE_SIGMAS = 2.0  # ... and one the line would move more than 2 expected sigmas


def smooth_ranges(ranges: np.ndarray, angles: np.ndarray, increment: float, half_window: int,
                  sigma: np.ndarray, straightness: float = 1.5) -> np.ndarray:
    """Ranges moved onto the straightest window's line (see the module docstring).

    ranges, angles: the usable returns (LiDAR frame), in scan order; increment: the scan's
    angle step (rays further apart than 1.5 steps are not neighbours); sigma: each return's
    expected noise (m).
    """
    n = ranges.size
    width = 2 * half_window + 1
    if half_window <= 0 or n < width:
        return ranges
    x, y = ranges * np.cos(angles), ranges * np.sin(angles)
    gap = np.abs(np.diff(angles)) > 1.5 * abs(increment)
    # prefix sums: window [j, j + width) has statistics from S[j + width] - S[j]
    def windows(values: np.ndarray) -> np.ndarray:
        s = np.concatenate([[0.0], np.cumsum(values)])
        return s[width:] - s[:-width]
    gaps = windows(np.concatenate([gap.astype(np.float64), [0.0]]))
    # a window [j, j + width) is contiguous when none of the gaps j .. j + width - 2 is set
    gaps = gaps - np.concatenate([gap.astype(np.float64), [0.0]])[width - 1:]
    mx, my = windows(x) / width, windows(y) / width
    cxx = windows(x * x) / width - mx * mx
    cyy = windows(y * y) / width - my * my
    cxy = windows(x * y) / width - mx * my
    half_trace = 0.5 * (cxx + cyy)
    root = np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    residual = np.maximum(half_trace - root, 0.0)  # mean squared distance from the line
    # the line's normal: the eigenvector of the smaller eigenvalue
    nx, ny = cxy, residual - cxx
    alt = np.abs(nx) + np.abs(ny) < 1e-15
    nx, ny = np.where(alt, residual - cyy, nx), np.where(alt, cxy, ny)
    norm = np.hypot(nx, ny)
    norm[norm == 0.0] = 1.0
    nx, ny = nx / norm, ny / norm
    windows_count = n - width + 1
    sigma_window = windows(sigma) / width
    score = residual / (sigma_window * sigma_window)
    score[gaps > 0.5] = np.inf
    # for return i, the windows starting at i - width + 1 .. i: the most central straight one
    # (its line is known best at its centre), else the straightest
    finite = np.isfinite(score)
    typical = float(np.median(score[finite])) if finite.any() else 1.0
    limit = straightness * straightness * typical
    best = np.full(n, np.inf)
    best_window = np.zeros(n, dtype=np.int64)
    chosen = np.zeros(n, dtype=bool)
    for k in sorted(range(width), key=lambda k: abs(k - half_window)):
        start = np.arange(n) - k
        valid = (start >= 0) & (start < windows_count)
        candidate = np.full(n, np.inf)
        candidate[valid] = score[start[valid]]
        take = ~chosen & (candidate <= limit)
        better = take | (~chosen & (candidate < best))
        best[better] = candidate[better]
        best_window[better] = start[better]
        chosen |= take
    w = best_window
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    along = nx[w] * cos_a + ny[w] * sin_a
    offset = nx[w] * mx[w] + ny[w] * my[w]
    with np.errstate(divide="ignore", invalid="ignore"):
        fitted = offset / along
    use = (best <= straightness * straightness) & (np.abs(along) > MIN_INCIDENCE_COS) \
        & np.isfinite(fitted) & (fitted > 0.0) & (np.abs(fitted - ranges) <= MAX_MOVE_SIGMAS * sigma)
    return np.where(use, fitted, ranges)


def ranges_filter(params: dict[str, Any]
                  ) -> Callable[[np.ndarray, np.ndarray, float], np.ndarray] | None:
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


__all__ = ["ranges_filter", "smooth_ranges"]
