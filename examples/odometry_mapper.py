"""The course's occupancy-grid mapping with known poses: it trusts the odometry, no scan matching.

A small, readable amr_common.plugins.interfaces.Mapper: the project's Mapper is graph SLAM (each
scan matched against the map, keyframes, loop closures, a pose graph). This one takes the odometry
pose as the truth and draws every scan into a log-odds grid at that pose, so you see what
SLAM is for: as the odometry drifts, the walls it draws again later land beside the first ones
and the map smears. Run it in place of the project's:

    .venv/bin/python scripts/run_sim.py --world lab02 --profile turtlebot3_clean --slam \
        --mapper examples.odometry_mapper:OdometryMapper --map-out out/odometry_map
    .venv/bin/python scripts/evaluate.py --slam --worlds lab02 --profiles turtlebot3_clean \
        --duration 120 --mapper examples.odometry_mapper:OdometryMapper --out out/odometry

The grid is a square of `map_size_m` centred on the map frame's origin (the odometry frame at
the first scan), each cell holding the log-odds l = log(p / (1 - p)) of being occupied, 0 =
unknown. For every scan at the robot pose (x, y, theta) and every return r along the ray at
angle a: the cells the ray crosses (sampled every half cell from the LiDAR up to r) lose
`log_odds_miss` (free), the cell it ends in gains `log_odds_hit` (occupied); each cell counts
once per scan. Returns beyond `max_range_m` clear the cells up to max_range_m and mark nothing.
The map: occupied where l > occupied_log_odds, free where l < free_log_odds, else unknown.
Log-odds are clamped to +-log_odds_limit, so a cell can change its mind when it is seen again.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from amr_common.plugins.parameter_table import above, checked_values, ruled
from amr_common.sensors.scan_returns import return_mask
from amr_common.world.cell_grid import cell_index
from amr_common.world.map_raster import FREE, OCCUPIED, UNKNOWN, Raster

_PARAMETERS = ruled({
    "lidar_offset_x_m": (0.0, "Where the LiDAR sits ahead of the robot centre [m] (the run "
                              "scripts set the profile's; /tf_static overrides it)"),
    "max_range_m": (3.5, "Returns farther than this are not drawn as walls [m]"),
    "resolution_m": (0.02, "Cell size [m]"),
    "map_size_m": (20.0, "Side of the square map, centred on the first pose [m]; rays beyond "
                         "it are cut"),
    "log_odds_hit": (0.9, "Log-odds added to the cell a ray ends in"),
    "log_odds_miss": (0.4, "Log-odds taken from each cell a ray crosses"),
    "occupied_log_odds": (0.6, "A cell is occupied above this log-odds"),
    "free_log_odds": (-0.4, "A cell is free below this log-odds"),
    "log_odds_limit": (5.0, "Log-odds are kept within +-this"),
}, above(0.0), lidar_offset_x_m=None, free_log_odds=None)


@dataclass(frozen=True)
class OdometryEstimate:
    """What update() returns (the interface's MappingEstimate)."""

    pose: tuple[float, float, float]  # map frame
    status: str  # "odometry", "first" or "rejected: <why>"


class OdometryMapper:
    """Occupancy-grid mapping at the odometry poses (see the module docstring)."""

    @staticmethod
    def parameter_descriptions() -> dict[str, tuple[Any, str]]:
        """Each parameter: name -> (default, description); the slam node declares them."""
        return dict(_PARAMETERS)

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        self.p = checked_values(_PARAMETERS, params, "OdometryMapper")  # ValueError
        if not self.p["free_log_odds"] < self.p["occupied_log_odds"]:
            raise ValueError("OdometryMapper: free_log_odds must be below occupied_log_odds")
        self.resolution = float(self.p["resolution_m"])
        cells = int(math.ceil(self.p["map_size_m"] / self.resolution))
        self.log_odds = np.zeros((cells, cells), dtype=np.float32)  # [row = y, col = x]
        self.origin = (-0.5 * cells * self.resolution, -0.5 * cells * self.resolution)
        self._pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._last_stamp = -math.inf
        self._stats: dict[str, Any] = {"updates": 0, "rejected": {}}

    # --- the interface's members -----------------------------------------------------------
    @property
    def pose(self) -> tuple[float, float, float]:
        """The newest pose: the odometry's (the map frame is the odometry frame)."""
        return self._pose

    @property
    def map_to_odom(self) -> tuple[float, float, float]:
        """Identity: the map frame is the odometry frame (no correction, ever)."""
        return (0.0, 0.0, 0.0)

    @property
    def lidar_offset_x_m(self) -> float:
        """Where it draws the rays from (m ahead of the robot centre)."""
        return float(self.p["lidar_offset_x_m"])

    @property
    def max_range_m(self) -> float:
        """Returns beyond this are not drawn as walls (m)."""
        return float(self.p["max_range_m"])

    def statistics(self) -> dict[str, Any]:
        """Scans drawn and scans rejected (by reason)."""
        return {"updates": self._stats["updates"], "rejected": dict(self._stats["rejected"])}

    def update(self, scan: Any, odom_pose, stamp: float) -> OdometryEstimate:
        """Draw the scan at the odometry pose; bad input is skipped, never raised."""
        try:
            pose = tuple(float(v) for v in odom_pose)
            stamp = float(stamp)
            ranges = np.asarray(scan.ranges, dtype=np.float64)
            angles = float(scan.angle_min) + float(scan.angle_increment) * np.arange(len(ranges))
            limits = (float(scan.range_min), float(scan.range_max))
        except (AttributeError, TypeError, ValueError):
            return self._reject("bad_input")
        if len(pose) != 3 or not all(math.isfinite(v) for v in (*pose, stamp)):
            return self._reject("non_finite")
        if stamp <= self._last_stamp:
            return self._reject("out_of_order")
        first = self._stats["updates"] == 0
        self._last_stamp = stamp
        self._pose = pose
        self._stats["updates"] += 1
        self._draw_scan(pose, ranges, angles, *limits)
        return OdometryEstimate(pose, "first" if first else "odometry")

    def occupancy_raster(self) -> Raster:
        """The map: the cells seen so far (their bounding box), thresholded."""
        seen_rows, seen_cols = np.nonzero(self.log_odds)
        if len(seen_rows) == 0:
            return Raster(np.full((1, 1), UNKNOWN, dtype=np.int8), self.resolution, self.origin)
        r0, r1, c0, c1 = seen_rows.min(), seen_rows.max() + 1, seen_cols.min(), seen_cols.max() + 1
        log_odds = self.log_odds[r0:r1, c0:c1]
        values = np.full(log_odds.shape, UNKNOWN, dtype=np.int8)
        values[log_odds > self.p["occupied_log_odds"]] = OCCUPIED
        values[log_odds < self.p["free_log_odds"]] = FREE
        return Raster(values, self.resolution, (self.origin[0] + c0 * self.resolution,
                                                self.origin[1] + r0 * self.resolution))

    # --- drawing ---------------------------------------------------------------------------
    def _draw_scan(self, pose, ranges: np.ndarray, angles: np.ndarray, range_min: float,
                   range_max: float) -> None:
        """Misses along each ray, a hit where it ends (see the module docstring)."""
        x, y, theta = pose
        lidar_x = x + self.lidar_offset_x_m * math.cos(theta)
        lidar_y = y + self.lidar_offset_x_m * math.sin(theta)
        returns = return_mask(ranges, range_min, range_max)
        r = ranges[returns]
        directions = theta + angles[returns]
        walls = r <= self.max_range_m  # farther: free up to max_range_m, no wall drawn
        cleared = np.minimum(r, self.max_range_m)
        # Ray marching by samples every half cell, stopping half a cell short of the end.
        step = 0.5 * self.resolution
        along = np.arange(0.0, self.max_range_m, step)
        inside = along[None, :] < (cleared - step)[:, None]  # (rays, samples)
        sx = lidar_x + along[None, :] * np.cos(directions)[:, None]
        sy = lidar_y + along[None, :] * np.sin(directions)[:, None]
        free = self._cells(sx[inside], sy[inside])
        hits = self._cells(lidar_x + r[walls] * np.cos(directions[walls]),
                           lidar_y + r[walls] * np.sin(directions[walls]))
        free = np.setdiff1d(free, hits)  # unique: each cell counts once per scan
        hits = np.unique(hits)
        flat = self.log_odds.reshape(-1)  # a view: updates go to the grid
        limit = self.p["log_odds_limit"]
        flat[free] = np.maximum(flat[free] - self.p["log_odds_miss"], -limit)
        flat[hits] = np.minimum(flat[hits] + self.p["log_odds_hit"], limit)

    def _cells(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Flat indices of the cells holding the points; points off the grid dropped."""
        rows = cell_index(y, self.origin[1], self.resolution)
        cols = cell_index(x, self.origin[0], self.resolution)
        size = self.log_odds.shape[0]
        on_grid = (rows >= 0) & (rows < size) & (cols >= 0) & (cols < size)
        return (rows[on_grid] * size + cols[on_grid]).astype(np.intp)

    def _reject(self, reason: str) -> OdometryEstimate:
        rejected = self._stats["rejected"]
        rejected[reason] = rejected.get(reason, 0) + 1
        return OdometryEstimate(self._pose, f"rejected: {reason}")
