"""The figures of a mapping run, from the simulator's truth.

- Trajectory error: each SLAM pose (map frame = the odometry frame at the start) against the
  true pose expressed in the start's frame ("after aligning the start"): RMSE and max of the
  position error, RMSE of the heading error.
- Precision: share of the map's OCCUPIED cells whose centre lies within `tolerance` (3 cm) of a
  true wall.
- Recall: the walls sampled every 1 cm; a sample counts as seen when a noise-free ray of the
  run (from the true LiDAR pose, amr_common.world.raycast) ended within SEEN_RADIUS of it; recall
  is the share of the seen samples with an OCCUPIED cell centre within `tolerance`.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.geometry import compose, inverse, wrap_angles
from amr_common.sensors.scan_returns import return_mask
from amr_common.world.cell_grid import cell_index
from amr_common.world.map_raster import OCCUPIED, Raster
from amr_common.world.raycast import scan_into
from amr_common.world.world import World

TOLERANCE_M = 0.03
SAMPLE_SPACING_M = 0.01
SEEN_RADIUS_M = 0.01  # a wall sample this close to a ray's end point was hit
_HIT_CELL_M = 0.005  # cells of the hit-point record


def transform_points(pose, points: np.ndarray) -> np.ndarray:
    """(N, 2) points given in the frame of `pose` (x, y, theta), expressed in its parent."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([pose[0] + c * points[:, 0] - s * points[:, 1],
                            pose[1] + s * points[:, 0] + c * points[:, 1]])


def trajectory_errors(start, truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """RMSE / max position error (m) and heading RMSE (rad) of estimate rows [x, y, theta].

    truth rows are world poses, aligned by expressing them in the start pose's frame.
    """
    if len(estimate) == 0:
        return {"trajectory_rmse_m": math.nan, "trajectory_max_m": math.nan,
                "heading_rmse_rad": math.nan}
    origin = inverse(tuple(start))
    aligned = np.array([compose(origin, tuple(row)) for row in truth])
    position = np.hypot(estimate[:, 0] - aligned[:, 0], estimate[:, 1] - aligned[:, 1])
    heading = wrap_angles(estimate[:, 2] - aligned[:, 2])
    return {"trajectory_rmse_m": float(np.sqrt(np.mean(position ** 2))),
            "trajectory_max_m": float(position.max()),
            "heading_rmse_rad": float(np.sqrt(np.mean(heading ** 2)))}


def occupied_centres(raster: Raster) -> np.ndarray:
    """(K, 2) centres of the OCCUPIED cells (map frame)."""
    rows, cols = np.nonzero(raster.values == OCCUPIED)
    return raster.cell_centres(rows, cols)


def map_precision(raster: Raster, world: World, start,
                  tolerance: float = TOLERANCE_M) -> float:
    """Share of OCCUPIED cells within `tolerance` of a true wall (nan without any)."""
    centres = occupied_centres(raster)
    if len(centres) == 0:
        return math.nan
    distances = world.clearances(transform_points(start, centres))
    return float(np.mean(distances <= tolerance))


def wall_samples(world: World, spacing: float = SAMPLE_SPACING_M) -> np.ndarray:
    """(K, 2) points every `spacing` along every wall (world frame)."""
    parts = []
    for x1, y1, x2, y2 in world.segments:
        n = max(int(math.ceil(math.hypot(x2 - x1, y2 - y1) / spacing)), 1)
        t = (np.arange(n) + 0.5) / n
        parts.append(np.column_stack([x1 + t * (x2 - x1), y1 + t * (y2 - y1)]))
    return np.vstack(parts)


class RayHits:
    """Where noise-free rays of the run ended: a boolean grid of _HIT_CELL_M cells."""

    def __init__(self, world: World, angle_min: float, angle_increment: float, rays: int,
                 range_min: float, range_max: float) -> None:
        xmin, ymin, xmax, ymax = world.bounds
        margin = 2 * SEEN_RADIUS_M
        self._origin = (xmin - margin, ymin - margin)
        self._shape = (int(math.ceil((ymax - ymin + 2 * margin) / _HIT_CELL_M)) + 1,
                       int(math.ceil((xmax - xmin + 2 * margin) / _HIT_CELL_M)) + 1)
        self.hit = np.zeros(self._shape, dtype=bool)
        angles = angle_min + angle_increment * np.arange(rays)
        self._cos, self._sin = np.cos(angles), np.sin(angles)
        self._limits = (float(range_min), float(range_max))
        self._segments = world.segments
        self._zeros = np.zeros(rays)
        self._ranges = np.empty(rays)

    def add(self, lidar_x: float, lidar_y: float, theta: float) -> None:
        """Record the ends of one noise-free scan from the LiDAR pose."""
        ranges = self._ranges
        scan_into(self._segments, lidar_x, lidar_y, theta, self._cos, self._sin,
                  self._limits[0], self._limits[1], math.nan, self._zeros, ranges)
        ok = return_mask(ranges, *self._limits)
        c, s = math.cos(theta), math.sin(theta)
        x = lidar_x + ranges[ok] * (c * self._cos[ok] - s * self._sin[ok])
        y = lidar_y + ranges[ok] * (s * self._cos[ok] + c * self._sin[ok])
        self.hit[self._cells(x, y)] = True

    def _cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rows = np.clip(cell_index(y, self._origin[1], _HIT_CELL_M).astype(np.int64), 0,
                       self._shape[0] - 1)
        cols = np.clip(cell_index(x, self._origin[0], _HIT_CELL_M).astype(np.int64), 0,
                       self._shape[1] - 1)
        return rows, cols

    def seen(self, samples: np.ndarray) -> np.ndarray:
        """Bool per sample: some ray ended within about SEEN_RADIUS_M of it."""
        reach = int(math.ceil(SEEN_RADIUS_M / _HIT_CELL_M))
        rows, cols = self._cells(samples[:, 0], samples[:, 1])
        seen = np.zeros(len(samples), dtype=bool)
        for dr in range(-reach, reach + 1):
            for dc in range(-reach, reach + 1):
                seen |= self.hit[np.clip(rows + dr, 0, self._shape[0] - 1),
                                 np.clip(cols + dc, 0, self._shape[1] - 1)]
        return seen


def near_occupied(raster: Raster, points: np.ndarray, tolerance: float = TOLERANCE_M
                  ) -> np.ndarray:
    """Bool per (N, 2) map-frame point: an OCCUPIED cell centre lies within `tolerance`."""
    res = raster.resolution
    rows_n, cols_n = raster.values.shape
    row, col = (index.astype(np.int64) for index in raster.cells_of(points[:, 0], points[:, 1]))
    reach = int(math.ceil(tolerance / res)) + 1
    found = np.zeros(len(points), dtype=bool)
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            r, c = row + dr, col + dc
            inside = (r >= 0) & (r < rows_n) & (c >= 0) & (c < cols_n)
            occupied = np.zeros(len(points), dtype=bool)
            occupied[inside] = raster.values[r[inside], c[inside]] == OCCUPIED
            cx = raster.origin[0] + (c + 0.5) * res
            cy = raster.origin[1] + (r + 0.5) * res
            found |= occupied & (np.hypot(cx - points[:, 0], cy - points[:, 1]) <= tolerance)
    return found


def map_recall(raster: Raster, world: World, start, hits: RayHits,
               tolerance: float = TOLERANCE_M) -> tuple[float, float]:
    """(recall, seen wall length in m): see the module docstring."""
    samples = wall_samples(world)
    seen = hits.seen(samples)
    if not seen.any():
        return math.nan, 0.0
    in_map = transform_points(inverse(tuple(start)), samples[seen])
    return float(np.mean(near_occupied(raster, in_map, tolerance))), \
        float(seen.sum() * SAMPLE_SPACING_M)


def mapping_figures(world: World, start, truth: np.ndarray, estimate: np.ndarray,
                    raster: Raster, hits: RayHits) -> dict[str, float]:
    """The figures of a mapping run: trajectory RMSE / max / heading RMSE, precision, recall.

    `start`: the pose of the map frame in the world (the robot's start when the map frame is
    the odometry frame at the first scan; (0, 0, 0) when the map was built in the world's
    frame); truth: (N, 3) true poses at the estimate's rows (N, 3) [x, y, theta]; `hits`: the
    noise-free rays of the run from the true poses.
    """
    recall, seen = map_recall(raster, world, start, hits)
    return {**trajectory_errors(start, truth, estimate),
            "precision": map_precision(raster, world, start), "recall": recall,
            "seen_wall_m": seen}


__all__ = ["RayHits", "TOLERANCE_M", "map_precision", "map_recall", "mapping_figures",
           "near_occupied", "occupied_centres", "trajectory_errors", "transform_points",
           "wall_samples"]
