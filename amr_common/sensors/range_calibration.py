"""A LiDAR unit's range calibration: measured against a tape measure, corrected by a table.

A datasheet LiDAR's ranges carry a per-unit systematic error (LDS-01: up to 15 mm below
0.5 m, up to 5 % of the range above; amr_common.sensors.lidar_models). A scan of such a unit is
self-consistent, and no odometry can reveal it (the wheels' radius is itself known only to
~2 %), so a map built from it is scaled. The cure is the one a surveyor uses: point the LiDAR
at a flat wall at distances measured with a tape, compare.

    points = np.vstack([wall_points(r, angle_min, angle_increment) for r in scans])
    correction = fit_correction({0.3: wall_distance(points_03), 1.0: ..., 2.0: ...})
    correction.apply(ranges)                                        # corrected ranges
    correction.as_list()   # [measured_1, correction_1, ...]: the `range_correction` parameter

The correction is piecewise linear in the measured range through the calibration points
(true = measured + correction), constant below the first, extended along the last two beyond
the last: the LDS-01's error (an offset below 0.5 m, a scale above) is followed within 5 mm.
Plain Python, no rclpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

WALL_HALF_ANGLE_RAD = 0.17  # rays within +-10 deg of straight ahead see the calibration wall
MIN_WALL_RETURNS = 5
MAX_CORRECTION_SHARE = 0.2  # a correction beyond 20 % of the range (+ 5 cm) is not a LiDAR's
MAX_CORRECTION_M = 0.05


@dataclass(frozen=True)
class RangeCorrection:
    """true range = measured + correction(measured), piecewise linear (module docstring)."""

    measured: tuple[float, ...]  # ascending calibration ranges as the unit measured them (m)
    correction: tuple[float, ...]  # true - measured at each (m)

    @classmethod
    def from_list(cls, values: Sequence[float]) -> "RangeCorrection | None":
        """From [measured_1, correction_1, measured_2, ...]; [] -> None (no correction).

        ValueError saying what is wrong: an odd count, a non-finite value, ranges not
        ascending or not positive, a correction no LiDAR needs (beyond 20 % of the range + 5 cm).
        """
        values = [float(v) for v in values]
        if not values:
            return None
        if len(values) % 2:
            raise ValueError(f"range_correction needs pairs [measured range, correction, ...], "
                             f"got {len(values)} numbers")
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"range_correction has a value that is not finite: {values}")
        measured, correction = tuple(values[0::2]), tuple(values[1::2])
        if measured[0] <= 0.0 or any(b <= a for a, b in zip(measured, measured[1:])):
            raise ValueError(f"range_correction's ranges must be positive and ascending: "
                             f"{list(measured)}")
        for r, c in zip(measured, correction):
            if abs(c) > MAX_CORRECTION_SHARE * r + MAX_CORRECTION_M:
                raise ValueError(f"range_correction of {c:+.3f} m at {r:.3f} m is more than "
                                 f"any LiDAR's error: recalibrate")
        return cls(measured, correction)

    def as_list(self) -> list[float]:
        """[measured_1, correction_1, ...] (the `range_correction` parameter's form)."""
        return [round(v, 5) for pair in zip(self.measured, self.correction) for v in pair]

    def apply(self, ranges: np.ndarray) -> np.ndarray:
        """Corrected ranges (NaN, inf and 0, the no-return values, stay as they are)."""
        ranges = np.asarray(ranges, dtype=np.float64)
        r, c = np.asarray(self.measured), np.asarray(self.correction)
        correction = np.interp(ranges, r, c)
        if r.size > 1:  # beyond the last point: along the last two
            slope = (c[-1] - c[-2]) / (r[-1] - r[-2])
            correction = np.where(ranges > r[-1], c[-1] + slope * (ranges - r[-1]), correction)
        usable = np.isfinite(ranges) & (ranges > 0.0)
        # inf + the extrapolated -inf would warn: no correction is added to a no-return value
        return np.where(usable, ranges + np.where(usable, correction, 0.0), ranges)


def wall_points(ranges: Sequence[float] | np.ndarray, angle_min: float, angle_increment: float,
                half_angle: float = WALL_HALF_ANGLE_RAD) -> np.ndarray:
    """(N, 2) points (LiDAR frame) of one scan's returns within `half_angle` of straight ahead."""
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = angle_min + angle_increment * np.arange(ranges.size)
    ahead = np.abs(np.arctan2(np.sin(angles), np.cos(angles))) <= half_angle
    usable = ahead & np.isfinite(ranges) & (ranges > 0.0)
    return np.column_stack([ranges[usable] * np.cos(angles[usable]),
                            ranges[usable] * np.sin(angles[usable])])


def wall_distance(points: np.ndarray) -> float | None:
    """Distance (m) from the LiDAR to the straight wall through `points`, or None.

    A total-least-squares line through the points of every scan taken at one place (pooled: a
    line through one noisy scan tilts, and a tilted line passes closer to the LiDAR); None with
    fewer than MIN_WALL_RETURNS points or when they are not on one line (residual above a
    tenth of the distance).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(points) < MIN_WALL_RETURNS:
        return None
    mean = points.mean(axis=0)
    eigenvalues, eigenvectors = np.linalg.eigh(np.cov(points.T, bias=True))
    normal = eigenvectors[:, 0]  # the smaller eigenvalue's vector: across the wall
    distance = abs(float(normal @ mean))
    if math.sqrt(max(eigenvalues[0], 0.0)) > 0.1 * distance:
        return None
    return distance


def fit_correction(measured_by_distance: Mapping[float, float | None]) -> RangeCorrection:
    """The correction from tape-measured distances -> the unit's wall_distance() there.

    ValueError for a distance without a reading (None: no wall seen).
    """
    points = []
    for true_distance, reading in sorted(measured_by_distance.items()):
        if reading is None or not math.isfinite(reading):
            raise ValueError(f"no reading of the wall at {true_distance:g} m")
        points += [float(reading), float(true_distance) - float(reading)]
    correction = RangeCorrection.from_list(points)
    assert correction is not None
    return correction


__all__ = ["RangeCorrection", "fit_correction", "wall_distance", "wall_points"]
