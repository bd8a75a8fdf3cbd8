"""LiDAR perception for the wall follower.

Scan geometry, a local obstacle point cloud kept between scans, angular sectors, and a
straight-line fit of the wall beside the robot.

Everything is in the robot frame (REP 103: x forward, y left, angles counter-clockwise from x).
No rclpy import: the same code runs in the headless simulator, in tests and in the ROS node.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from amr_control import point_cloud_kernels as kernels
from amr_control import side_wall_kernels


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
        """Finite values, a ray spacing in (1e-4, pi] rad and 0 <= range_min < range_max."""
        return (all(math.isfinite(v) for v in (self.angle_min, self.angle_increment,
                                                self.range_min, self.range_max))
                and 1e-4 < abs(self.angle_increment) <= math.pi
                and 0.0 <= self.range_min < self.range_max)


class WallFit(NamedTuple):
    """A straight wall beside the robot, fitted to the points of the scan.

    distance_m: perpendicular distance from the robot centre to the wall line.
    angle_rad: direction of the wall line in the robot frame, in (-pi/2, pi/2]; 0 = parallel.
    residual_m: RMS distance of the used points to the line (noise, or a bent wall if large).
    span_m: extent of the used points along the robot's x axis.
    points: number of points on the line.
    """

    distance_m: float
    angle_rad: float
    residual_m: float
    span_m: float
    points: int

    @property
    def gives_direction(self) -> bool:
        """Good enough (under 2 cm RMS, at least 15 cm long) to take the walls' direction from."""
        return self.residual_m < 0.02 and self.span_m >= 0.15


@dataclass(frozen=True)
class ScanTiming:
    """When a scan's rays were measured, and how long points it no longer shows are kept.

    revolution_s: one scan's rays span this much time, measured clockwise and stamped at the
      end (the LDS-01 and LDS-02 drivers; 0 = all rays at once): each ray is de-skewed with the
      odometry (point_memory_kernels.deskew_point).
    memory_time_s, memory_range_m, memory_cell_m: the scans' points stay obstacles for the
      swept path for memory_time_s after a scan last showed a point in their memory_cell_m
      cell (odometry frame), within memory_range_m of the robot (0 s: no memory), where
      the cloud has no point within memory_match_m of them; see point_memory_kernels.
    """

    revolution_s: float = 0.0
    memory_time_s: float = 0.0
    memory_range_m: float = 0.0
    memory_cell_m: float = 0.02
    memory_match_m: float = 0.03


class PerceptionSpec:
    """What the controller wants perceived each step: named sectors and the followed side.

    Sectors: centre directions in rad, a common half-width < pi/2, and per sector the percentile
    of its ranges to report (0 = the closest). The followed side's geometry: see Perception.
    """

    def __init__(self, side_sign: float, sectors: dict[str, float], sector_half_width_rad: float,
                 sector_percentiles: dict[str, float], path_half_width_m: float,
                 side_window_m: float, side_open_m: float, fit_half_length_m: float,
                 fit_min_points: int = 6, fit_min_span_m: float = 0.06) -> None:
        if not 0.0 < sector_half_width_rad < 0.5 * math.pi:
            raise ValueError("sector half-width must be in (0, pi/2) rad, got "
                             f"{sector_half_width_rad}")
        if side_sign not in (1.0, -1.0):
            raise ValueError(f"side_sign must be +1 (left) or -1 (right), got {side_sign}")
        self.sector_names = tuple(sectors)
        centres = [sectors[name] for name in self.sector_names]
        self.sector_table = np.array([np.cos(centres), np.sin(centres),
                                      [sector_percentiles.get(n, 0.0) for n in self.sector_names]])
        self.config = {"side": float(side_sign), "sector_half_width": float(sector_half_width_rad),
                       "path_half_width": float(path_half_width_m),
                       "side_window": float(side_window_m), "side_open": float(side_open_m),
                       "fit_half_length": float(fit_half_length_m),
                       "min_points": float(fit_min_points), "min_span": float(fit_min_span_m)}


class Perception(NamedTuple):
    """What one control step needs from the local point cloud (distances in m, robot frame).

    sectors: closest obstacle (or the sector's percentile range) per named sector; inf = open.
    path_m: distance ahead to the first point in the corridor the body sweeps driving forward.
    beside_m / beside_other_m: lateral distance to the closest point right beside the robot on
      the followed / other side (|x| within the side window); inf if there is none.
    fit: the followed wall as a line (points within side_open and +-fit_half_length), or None.
    wall_reach_m: how far ahead the followed wall continues without a gap (None: no points).
    """

    sectors: dict[str, float]
    path_m: float
    beside_m: float
    beside_other_m: float
    fit: WallFit | None
    wall_reach_m: float | None


class LocalPointCloud:
    """Obstacle points in the robot frame, from each new scan, carried along between scans.

    The odometry moves them: the LDS-01 refreshes at 5 Hz while the controller runs at 20 Hz.

    A ray that returns nothing right after it saw something close keeps that close point for
    `hold_time_s`: an LDS-01 reports 0.0 below 0.12 m, so "no return" next to a wall must not
    look like open space.

    The work is done by the loop kernels of amr_control.point_cloud_kernels and
    side_wall_kernels (numba-compiled), one call per control step; this class keeps the arrays
    and the per-geometry ray tables.
    """

    def __init__(self, hold_time_s: float, hold_range_m: float, lidar_offset_x_m: float,
                 spec: PerceptionSpec, timing: ScanTiming | None = None) -> None:
        timing = timing or ScanTiming()
        values = dict(spec.config, hold_range=hold_range_m, hold_time=hold_time_s,
                      lidar_offset_x=lidar_offset_x_m, revolution=timing.revolution_s,
                      memory_time=timing.memory_time_s, memory_range=timing.memory_range_m,
                      memory_cell=timing.memory_cell_m,
                      memory_match=timing.memory_match_m)
        self._config = np.array([values[name] for name in kernels.CONFIG_FIELDS], dtype=float)
        self._spec = spec
        self._sector_out = np.empty(len(spec.sector_names))
        self._ahead = np.empty(720)       # side_gap's output buffer
        self._cloud = np.zeros((3, 0))    # rows: x, y (m, robot frame), age (s)
        self._memory = np.zeros((3, 0))   # rows: x, y (m, odometry frame), time last seen (s)
        self._pose = np.zeros(4)          # the odometry pose x, y, theta and time since start
        self._last_scan = np.zeros(0)     # the last merged scan: a held one is not merged again
        self._ray_key: tuple | None = None
        self._ray_cos = self._ray_sin = np.zeros(0)
        self._geometry = (0.0, 1.0, 0.0, 1.0)
        kernels.warm_up()

    @property
    def size(self) -> int:
        """Number of points in the cloud."""
        return int(self._cloud.shape[1])

    @property
    def memory_size(self) -> int:
        """Number of remembered points (one per cell, see ScanTiming)."""
        return int(self._memory.shape[1])

    def step(self, distance_m: float, rotation_rad: float, dt: float,
             ranges: np.ndarray | None, geometry: ScanGeometry | None
             ) -> tuple[int | None, Perception]:
        """One control step: move the cloud with the odometry, merge a new scan, perceive.

        The robot drove `distance_m` along the chord of an arc and turned `rotation_rad`
        (odometry; every point ages by dt); `ranges` (a contiguous float64
        array the cloud may keep, or None) is the scan, merged when it differs from the last
        merged one (a held LaserScan is not new):
        its valid points replace the cloud, plus the held close points whose ray returned
        nothing. Returns (valid readings of the merged scan, or None if none was merged, and
        the Perception of the cloud).
        """
        scan_given = ranges is not None and geometry is not None
        if scan_given:
            key = (geometry, ranges.size)
            if key != self._ray_key:
                angles = geometry.angle_min + geometry.angle_increment * np.arange(ranges.size)
                self._ray_cos, self._ray_sin = np.cos(angles), np.sin(angles)
                self._geometry = (float(geometry.angle_min), float(geometry.angle_increment),
                                  float(geometry.range_min), float(geometry.range_max))
                self._ray_key = key
        else:
            ranges = self._last_scan
        (self._cloud, self._memory, valid, path, beside, beside_other, fit,
         reach) = kernels.step_cloud(
            self._cloud, self._memory, self._pose, float(distance_m), float(rotation_rad),
            float(dt), ranges, scan_given, self._last_scan, self._ray_cos, self._ray_sin,
            *self._geometry, self._config, self._spec.sector_table, self._sector_out)
        if valid >= 0:
            self._last_scan = ranges   # not copied: the caller hands over a fresh array
        ok, distance, angle, rms, span, inliers = fit
        return (valid if valid >= 0 else None), Perception(
            sectors=dict(zip(self._spec.sector_names, self._sector_out.tolist())),
            path_m=path, beside_m=beside, beside_other_m=beside_other,
            fit=WallFit(distance, angle, rms, span, inliers) if ok else None,
            wall_reach_m=None if math.isnan(reach) else reach)

    def side_gap(self, side_sign: float, max_lateral_m: float, lookback_m: float = 0.6
                 ) -> tuple[float | None, np.ndarray]:
        """For an opening on one side: the last wall point behind, and the points ahead.

        Returns x of the last wall point behind the robot (None if there is none within
        lookback_m) and the x of the side points ahead (a view of a buffer the next call
        overwrites). Asked only at openings, so not part of step().
        """
        if self._ahead.size < self._cloud.shape[1]:
            self._ahead = np.empty(2 * self._cloud.shape[1])
        wall_end, count = side_wall_kernels.side_gap(
            self._cloud, float(side_sign), float(max_lateral_m), float(lookback_m), self._ahead)
        return (None if math.isnan(wall_end) else wall_end), self._ahead[:count]
