"""A LaserScan-like input as points in the robot frame, with the unusable returns left out.

The scan is any object with `ranges`, `angle_min`, `angle_increment`, `range_min` and
`range_max` (sensor_msgs/LaserScan, or `Scan` below). The geometry comes from each scan itself,
never from a fixed ray count: the LDS-02 changes its count and angles from scan to scan.
A return is used when it is finite, > 0, within [range_min, range_max] and within max_range
(0.0 is the LDS-01's "no return", NaN the LDS-02's). `scan_time` (LaserScan's: the time the
revolution took, its rays measured clockwise before the stamp as the Burger's drivers do) says
how old each ray is for de-skewing (scan_revolution_s); a scan without one was taken at once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from amr_common.sensors.scan_returns import return_mask

MAX_RAYS = 100_000  # more rays than any 2D LiDAR gives: refused as malformed
MAX_SCAN_TIME_S = 1.0  # a revolution longer than this is not a Burger's LiDAR (5 Hz: 0.2 s)


@dataclass(frozen=True)
class Scan:
    """The fields of a sensor_msgs/LaserScan the mapper reads."""

    ranges: Sequence[float] | np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    scan_time: float = 0.0  # s the revolution took (0: all rays at once)


class ScanError(ValueError):
    """A scan whose geometry or ranges cannot be used at all."""


def scan_revolution_s(scan: Any) -> float | None:
    """The scan's `scan_time` (s): 0.0 when it has none or says 0, None when it is unusable.

    Unusable: not a number, not finite, negative, or longer than MAX_SCAN_TIME_S.
    """
    value = getattr(scan, "scan_time", 0.0)
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if 0.0 <= value <= MAX_SCAN_TIME_S else None  # NaN fails both


RangesFilter = Callable[[np.ndarray, np.ndarray, float], np.ndarray]


def scan_points(scan: Any, lidar_offset_x: float, max_range: float,
                ranges_filter: RangesFilter | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((N, 2) float64 points in the robot frame (LiDAR at lidar_offset_x), (N,) their angles).

    The points and the angles (rad, the LiDAR frame) of the usable returns; `ranges_filter`
    (usable ranges, their angles, the scan's angle_increment) -> ranges changes them first
    (amr_mapping.scan_smoothing.ranges_filter: the unit's calibration, noise smoothing).

    Raises ScanError for a scan that is not a scan: non-numeric or non-finite geometry,
    angle_increment 0, ranges that are not a flat list of numbers, more than MAX_RAYS rays.
    """
    try:
        angle_min = float(scan.angle_min)
        increment = float(scan.angle_increment)
        range_min = float(scan.range_min)
        range_max = float(scan.range_max)
        ranges = np.asarray(scan.ranges, dtype=np.float64)
    except (AttributeError, TypeError, ValueError) as exc:
        raise ScanError(f"not a usable scan ({exc})") from None
    if not all(math.isfinite(v) for v in (angle_min, increment, range_min)) or \
            math.isnan(range_max) or increment == 0.0:
        raise ScanError(f"unusable scan geometry: angle_min {angle_min}, angle_increment "
                        f"{increment}, range_min {range_min}, range_max {range_max}")
    if ranges.ndim != 1 or ranges.size > MAX_RAYS:
        raise ScanError(f"ranges must be a flat list of at most {MAX_RAYS} numbers "
                        f"(got shape {ranges.shape})")
    upper = min(range_max, max_range)
    index = np.flatnonzero(return_mask(ranges, range_min, upper))
    angles = angle_min + increment * index
    r = ranges[index]
    if ranges_filter is not None and r.size:
        r = ranges_filter(r, angles, increment)
    return np.column_stack([lidar_offset_x + r * np.cos(angles), r * np.sin(angles)]), angles


__all__ = ["MAX_RAYS", "RangesFilter", "MAX_SCAN_TIME_S", "Scan", "ScanError", "scan_points",
           "scan_revolution_s"]
