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
when the line would move it more than two sigmas. Vectorized numpy: ~0.5 ms for 360 rays.
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
    """Ranges moved onto their window's line (see the module docstring).

    ranges, angles: the usable returns (LiDAR frame), in scan order; increment: the scan's
    angle step (rays further apart than 1.5 steps are not neighbours); sigma: each return's
    expected noise (m), the datasheet's.
    """
    n = ranges.size
    width = 2 * half_window + 1
    if half_window <= 0 or n < width:
        return ranges
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    gap = np.abs(np.diff(angles)) > 1.5 * abs(increment)
    mx, my, nx, ny, score = _window_lines(ranges * cos_a, ranges * sin_a, sigma, gap, width)
    finite = np.isfinite(score)
    typical = float(np.median(score[finite])) if finite.any() else 1.0
    best, w = _chosen_windows(score, n, half_window, straightness * straightness * typical)
    along = nx[w] * cos_a + ny[w] * sin_a
    with np.errstate(divide="ignore", invalid="ignore"):
        fitted = (nx[w] * mx[w] + ny[w] * my[w]) / along
    use = (best <= straightness * straightness) & (np.abs(along) > MIN_INCIDENCE_COS) \
        & np.isfinite(fitted) & (fitted > 0.0) \
        & (np.abs(fitted - ranges) <= MAX_MOVE_SIGMAS * sigma)
    return np.where(use, fitted, ranges)


def _window_lines(x: np.ndarray, y: np.ndarray, sigma: np.ndarray, gap: np.ndarray,
                  width: int) -> tuple[np.ndarray, ...]:
    """Per window [j, j + width): centroid (mx, my), unit normal (nx, ny), and its score.

    score: the mean squared distance from the line over the mean sigma squared; inf for a
    window with a gap between its rays.
    """
    def sums(values: np.ndarray) -> np.ndarray:  # prefix sums: one subtraction per window
        s = np.concatenate([[0.0], np.cumsum(values)])
        return s[width:] - s[:-width]
    gaps = np.append(gap.astype(np.float64), 0.0)
    gaps_inside = sums(gaps) - gaps[width - 1:]  # the gaps j .. j + width - 2
    mx, my = sums(x) / width, sums(y) / width
    cxx = sums(x * x) / width - mx * mx
    cyy = sums(y * y) / width - my * my
    cxy = sums(x * y) / width - mx * my
    root = np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    residual = np.maximum(0.5 * (cxx + cyy) - root, 0.0)  # the smaller eigenvalue
    nx, ny = cxy, residual - cxx  # its eigenvector, or the other form where that vanishes
    degenerate = np.abs(nx) + np.abs(ny) < 1e-15
    nx, ny = np.where(degenerate, residual - cyy, nx), np.where(degenerate, cxy, ny)
    norm = np.hypot(nx, ny)
    norm[norm == 0.0] = 1.0
    mean_sigma = sums(sigma) / width
    score = residual / (mean_sigma * mean_sigma)
    score[gaps_inside > 0.5] = np.inf
    return mx, my, nx / norm, ny / norm, score


def _chosen_windows(score: np.ndarray, n: int, half_window: int,
                    limit: float) -> tuple[np.ndarray, np.ndarray]:
    """(score, start) of each return's window: the most central within limit, else the best."""
    width = 2 * half_window + 1
    best = np.full(n, np.inf)
    best_window = np.zeros(n, dtype=np.int64)
    chosen = np.zeros(n, dtype=bool)
    index = np.arange(n)
    for k in sorted(range(width), key=lambda k: abs(k - half_window)):
        start = index - k  # the window starting here holds return i at its k-th place
        valid = (start >= 0) & (start < score.size)
        candidate = np.full(n, np.inf)
        candidate[valid] = score[start[valid]]
        take = ~chosen & (candidate <= limit)
        better = take | (~chosen & (candidate < best))
        best[better] = candidate[better]
        best_window[better] = start[better]
        chosen |= take
    return best, best_window


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
