"""LiDAR perception for the wall follower: scan geometry, a local obstacle point cloud kept
between scans, angular sectors, and a straight-line fit of the wall beside the robot.

Everything is in the robot frame (REP 103: x forward, y left, angles counter-clockwise from x).
No rclpy import: the same code runs in the headless simulator, in tests and in the ROS node.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * math.pi


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Wrap an angle (or array of angles) to [-pi, pi) without losing the sign near +-pi."""
    return (angle + math.pi) % TWO_PI - math.pi


@dataclass(frozen=True)
class ScanGeometry:
    """Where the rays of a scan point and which ranges are trustworthy.

    angle_i = angle_min + i * angle_increment (rad, CCW, 0 = straight ahead);
    readings outside [range_min, range_max] (m) are "no return".
    """

    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float

    def is_sane(self) -> bool:
        return (all(math.isfinite(v) for v in (self.angle_min, self.angle_increment,
                                                self.range_min, self.range_max))
                and 1e-4 < abs(self.angle_increment) <= math.pi
                and 0.0 <= self.range_min < self.range_max)


def valid_readings(ranges: np.ndarray, range_min: float, range_max: float) -> np.ndarray:
    """Mask of usable readings: finite, not the 0.0 "no return" code, inside the range limits."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(ranges) & (ranges > 0.0) & (ranges >= range_min) & (ranges <= range_max)


@dataclass(frozen=True)
class WallFit:
    """A straight wall beside the robot, fitted to the points of the scan.

    distance_m: perpendicular distance from the robot centre to the wall line.
    angle_rad: direction of the wall line in the robot frame, in (-pi/2, pi/2]; 0 = parallel.
    residual_m: RMS distance of the used points to the line (noise, or a bent wall if large).
    span_m: extent of the used points along the robot's x axis.
    """

    distance_m: float
    angle_rad: float
    residual_m: float
    span_m: float
    points: int


class LocalPointCloud:
    """Obstacle points in the robot frame, built from each new scan and carried along with the
    odometry between scans (the LDS-01 refreshes at 5 Hz while the controller runs at 20 Hz).

    A ray that returns nothing right after it saw something close keeps that close point for
    `hold_time_s`: an LDS-01 reports 0.0 below 0.12 m, so "no return" next to a wall must not
    look like open space.
    """

    def __init__(self, hold_time_s: float, hold_range_m: float, lidar_offset_x_m: float) -> None:
        self._hold_time_s = hold_time_s
        self._hold_range_m = hold_range_m
        self._lidar_offset_x_m = lidar_offset_x_m
        self.points = np.zeros((0, 2))
        self._ages = np.zeros(0)          # s since the point's ray last returned it
        self._last_scan: np.ndarray | None = None
        self.ranges = np.zeros(0)
        self.angles = np.zeros(0)

    def move(self, distance_m: float, rotation_rad: float) -> None:
        """Express the points in the robot frame after the robot moved `distance_m` forward along
        the chord of an arc and turned `rotation_rad` (one control step of odometry)."""
        if self.points.size == 0 or (distance_m == 0.0 and rotation_rad == 0.0):
            return
        half = 0.5 * rotation_rad
        shifted = self.points - np.array([distance_m * math.cos(half), distance_m * math.sin(half)])
        c, s = math.cos(rotation_rad), math.sin(rotation_rad)
        # Rotate by -rotation: new frame is the old one turned by +rotation.
        self.points = np.column_stack((c * shifted[:, 0] + s * shifted[:, 1],
                                       -s * shifted[:, 0] + c * shifted[:, 1]))
        self._refresh_polar()

    def age(self, dt: float) -> None:
        self._ages = self._ages + dt

    def is_new_scan(self, ranges: np.ndarray) -> bool:
        """False when the scan is the same array of readings as last time (a held LaserScan)."""
        last = self._last_scan
        return last is None or last.shape != ranges.shape or not np.array_equal(last, ranges,
                                                                               equal_nan=True)

    def add_scan(self, ranges: np.ndarray, geometry: ScanGeometry) -> int:
        """Replace the cloud by the valid points of a new scan plus the held close points whose
        ray in this scan returned nothing. Returns the number of valid readings in the scan."""
        self._last_scan = ranges.copy()
        n = ranges.size
        angles = geometry.angle_min + geometry.angle_increment * np.arange(n)
        valid = valid_readings(ranges, geometry.range_min, geometry.range_max)
        r = ranges[valid]
        a = angles[valid]
        new_points = np.column_stack((r * np.cos(a) + self._lidar_offset_x_m, r * np.sin(a)))

        keep = np.zeros(self.points.shape[0], dtype=bool)
        if self.points.size:
            close = (self.ranges <= self._hold_range_m) & (self._ages < self._hold_time_s)
            if np.any(close):
                ray = self._nearest_ray(self.angles, geometry, n)
                covered = ray >= 0
                ray_valid = np.zeros_like(covered)
                ray_valid[covered] = valid[ray[covered]]
                keep = close & ~ray_valid
        self.points = np.vstack((new_points, self.points[keep]))
        self._ages = np.concatenate((np.zeros(new_points.shape[0]), self._ages[keep]))
        self._refresh_polar()
        return int(new_points.shape[0])

    @staticmethod
    def _nearest_ray(angles: np.ndarray, geometry: ScanGeometry, n: int) -> np.ndarray:
        """Index of the ray of a scan of `n` rays closest to each angle; -1 where none is."""
        step = abs(geometry.angle_increment)
        direction = 1.0 if geometry.angle_increment > 0 else -1.0
        offset = ((angles - geometry.angle_min) * direction) % TWO_PI
        idx = np.rint(offset / step).astype(int)
        full_turn = int(round(TWO_PI / step))
        idx = np.where(idx >= full_turn, idx - full_turn, idx)
        return np.where((idx >= 0) & (idx < n), idx, -1)

    def _refresh_polar(self) -> None:
        self.ranges = np.hypot(self.points[:, 0], self.points[:, 1])
        self.angles = np.arctan2(self.points[:, 1], self.points[:, 0])

    # ---- queries -------------------------------------------------------------------------
    def sector_distance(self, centre_rad: float, half_width_rad: float,
                        percentile: float = 0.0) -> float:
        """Closest obstacle within +-half_width of a direction (or a low percentile of the
        ranges there, to ignore single noisy readings); inf (open) if nothing returned."""
        if self.ranges.size == 0:
            return math.inf
        offset = np.abs(self.angles - wrap_angle(centre_rad))   # angles are in [-pi, pi]
        inside = np.minimum(offset, TWO_PI - offset) <= half_width_rad
        ranges = self.ranges[inside]
        if ranges.size == 0:
            return math.inf
        if percentile <= 0.0:
            return float(ranges.min())
        k = int(percentile / 100.0 * (ranges.size - 1))
        return float(np.partition(ranges, k)[k])

    def path_distance(self, half_width_m: float) -> float:
        """Distance ahead to the first obstacle inside the straight corridor the robot body would
        sweep driving forward (|y| <= half_width_m); inf if none."""
        if self.points.size == 0:
            return math.inf
        ahead = (self.points[:, 0] > 0.0) & (np.abs(self.points[:, 1]) <= half_width_m)
        return float(self.points[ahead, 0].min()) if np.any(ahead) else math.inf

    def nearest_distance(self) -> float:
        """Distance from the robot centre to the closest obstacle point in any direction."""
        return float(self.ranges.min()) if self.ranges.size else math.inf

    def side_band(self, side_sign: float, max_lateral_m: float, min_lateral_m: float = 0.02
                  ) -> np.ndarray:
        """Points on one side (side_sign +1 left, -1 right) within a lateral band."""
        if self.points.size == 0:
            return self.points
        lateral = side_sign * self.points[:, 1]
        return self.points[(lateral >= min_lateral_m) & (lateral <= max_lateral_m)]

    def beside_distance(self, side_sign: float, half_length_m: float) -> float:
        """Lateral distance to the closest point on one side with |x| <= half_length_m (right
        beside the robot); inf if there is none."""
        band = self.side_band(side_sign, math.inf)
        beside = band[np.abs(band[:, 0]) <= half_length_m] if band.size else band
        return float(np.abs(beside[:, 1]).min()) if beside.size else math.inf

    def side_gap(self, side_sign: float, max_lateral_m: float, lookback_m: float = 0.6
                 ) -> tuple[float | None, np.ndarray]:
        """For an opening on one side: x of the last wall point behind the robot (None if
        there is none within lookback_m) and the x of the side points ahead."""
        band = self.side_band(side_sign, max_lateral_m)
        if band.size == 0:
            return None, np.zeros(0)
        behind = band[(band[:, 0] <= 0.0) & (band[:, 0] >= -lookback_m), 0]
        return (float(behind.max()) if behind.size else None), band[band[:, 0] > 0.0, 0]

    def wall_reach(self, side_sign: float, max_lateral_m: float, half_length_m: float,
                   window_m: float, fit: WallFit | None, beside_m: float) -> float | None:
        """How far ahead (x, m) the wall beside the robot continues without a gap: its points
        are those near the fitted line (or near the beside distance without a fit)."""
        band = self.side_band(side_sign, max_lateral_m)
        near = band[np.abs(band[:, 0]) <= half_length_m] if band.size else band
        if near.size == 0:
            return None
        lateral = np.abs(near[:, 1])
        if fit is not None and abs(fit.angle_rad) < 1.0:
            expected = fit.distance_m + near[:, 0] * side_sign * math.tan(fit.angle_rad)
            near = near[np.abs(lateral - expected) <= 0.04]
        elif fit is None:
            near = near[np.abs(lateral - beside_m) <= 0.04]
        xs = np.sort(near[near[:, 0] >= -window_m, 0])
        if xs.size == 0:
            return None
        gaps = np.nonzero(np.diff(xs) > 0.04)[0]     # the first gap ends the wall
        return float(xs[gaps[0]] if gaps.size else xs[-1])

    def fit_side_wall(self, side_sign: float, max_lateral_m: float, half_length_m: float,
                      min_points: int = 6, min_span_m: float = 0.06) -> WallFit | None:
        """Total-least-squares line through the side points beside the robot
        (|x| <= half_length_m), with one pass of outlier rejection (corner points, held points).
        None if there are too few points or they span too little of the wall."""
        band = self.side_band(side_sign, max_lateral_m)
        pts = band[np.abs(band[:, 0]) <= half_length_m] if band.size else band
        if pts.shape[0] < min_points:
            return None
        # Start from the points near the median lateral distance (the wall alongside, not a wall
        # leaving sideways at a corner), then refine twice on all points close to the line.
        lateral = np.abs(pts[:, 1])
        inliers = pts[np.abs(lateral - np.median(lateral)) <= 0.06]
        fit = None
        for _ in range(3):
            fit = _fit_line(inliers, min_points, min_span_m)
            if fit is None:
                return None
            _, (_, _, _), mean, normal = fit
            inliers = pts[np.abs((pts - mean) @ normal) <= 0.03]
        residuals, (distance, angle, span), _, _ = _fit_line(inliers, min_points, min_span_m) or fit
        return WallFit(distance, angle, float(np.sqrt(np.mean(residuals ** 2))), span,
                       int(inliers.shape[0]))


def _fit_line(pts: np.ndarray, min_points: int, min_span_m: float
              ) -> tuple[np.ndarray, tuple[float, float, float], np.ndarray, np.ndarray] | None:
    """Total least squares: (residuals, (distance, angle, span), mean point, unit normal)."""
    if pts.shape[0] < min_points:
        return None
    span = float(pts[:, 0].max() - pts[:, 0].min())
    if span < min_span_m:
        return None
    mean = pts.mean(axis=0)
    centred = pts - mean
    sxx, sxy, syy = centred[:, 0] @ centred[:, 0], centred[:, 0] @ centred[:, 1], \
        centred[:, 1] @ centred[:, 1]
    # Principal axis of the 2x2 scatter matrix in closed form (what eigh gives, 10x cheaper).
    theta = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    direction = np.array([math.cos(theta), math.sin(theta)])
    if direction[0] < 0.0:
        direction = -direction
    normal = np.array([-direction[1], direction[0]])
    residuals = centred @ normal
    distance = abs(float(normal @ mean))
    angle = math.atan2(float(direction[1]), float(direction[0]))
    return residuals, (distance, angle, span), mean, normal
