"""Occupancy rasters in the ROS map convention (no ROS import), and a map's cells to walls.

Values as nav_msgs/OccupancyGrid: FREE 0, OCCUPIED 100, UNKNOWN -1. Row r, column c is the cell
[x0 + c*res, x0 + (c+1)*res) x [y0 + r*res, y0 + (r+1)*res): row 0 is the southmost (the
message's data is this array flattened row by row), indexed as every grid (amr_common.cell_grid).
A world's raster is its occupancy grid's (amr_common.occupancy_grid: OccupancyGrid.from_world(
world, resolution).raster(), the cells the planner and the filter use): OCCUPIED where a wall
passes through a cell or it lies inside an obstacle, UNKNOWN outside the boundary, else FREE.

The other way (a map read from a file, amr_common.map_file, or built by SLAM): only FREE cells
(value 0, as AMCL counts free) are free space; occupied, unknown and in-between values and
everything beyond the raster are walls. `boundary_segments` gives the edges between free and
non-free cells merged into maximal straight segments: the walls the simulator, the ray
casting and the clearances of a map world use (a 2 cm lab02: 36 segments for its 16 polygon
walls, not one per cell edge).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amr_common.cell_grid import CellIndexing
from amr_common.coverage_grid import inside_polygon_points

FREE, OCCUPIED, UNKNOWN = 0, 100, -1  # nav_msgs/OccupancyGrid values


@dataclass(frozen=True)
class Raster(CellIndexing):
    """values: (rows, cols) int8; origin: (x, y) of the lower-left corner of cell (0, 0), m."""

    values: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return self.values.shape

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """X and y of every cell centre, each shaped like `values`."""
        return np.meshgrid(self.x_centres, self.y_centres)

    @property
    def free(self) -> np.ndarray:
        """(rows, cols) bool: the free cells (value FREE); the rest is wall."""
        return self.values == FREE

    def free_at(self, points: np.ndarray) -> np.ndarray:
        """(K,) bool: which points of a (K, 2) array lie in a free cell (False off the raster)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        rows, cols = self.values.shape
        row, col = self.cells_of(pts[:, 0], pts[:, 1])
        with np.errstate(invalid="ignore"):  # NaN points: not free
            inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
        out = np.zeros(len(pts), dtype=bool)
        out[inside] = self.values[row[inside].astype(np.intp),
                                  col[inside].astype(np.intp)] == FREE
        return out


def boundary_segments(raster: Raster) -> np.ndarray:
    """(N, 4) segments [x1, y1, x2, y2]: every edge between a free cell and a non-free one.

    Cells beyond the raster count as non-free, so free cells on its border get a wall there.
    Collinear edges that touch are merged into one segment (maximal runs along each grid line).
    """
    free = np.zeros((raster.values.shape[0] + 2, raster.values.shape[1] + 2), dtype=bool)
    free[1:-1, 1:-1] = raster.free
    res, (x0, y0) = raster.resolution, raster.origin
    # Horizontal edges on grid line i (y = y0 + i res) under column c; vertical ones on line j.
    line, first, last = _runs(free[1:, 1:-1] != free[:-1, 1:-1])
    horizontal = np.column_stack([x0 + first * res, y0 + line * res, x0 + last * res,
                                  y0 + line * res])
    line, first, last = _runs((free[1:-1, 1:] != free[1:-1, :-1]).T)
    vertical = np.column_stack([x0 + line * res, y0 + first * res, x0 + line * res,
                                y0 + last * res])
    return np.ascontiguousarray(np.vstack([horizontal, vertical]), dtype=np.float64)


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, first, end) of each maximal run of True along the rows of a 2D bool array."""
    padded = np.zeros((mask.shape[0], mask.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = mask
    step = np.diff(padded, axis=1)
    rows, first = np.nonzero(step == 1)  # row-major order: starts and ends pair up
    _, end = np.nonzero(step == -1)
    return rows.astype(np.float64), first.astype(np.float64), end.astype(np.float64)


def points_in_polygon(polygon: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Even-odd test of many points against one closed polygon ((K, 2) vertices)."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    points = np.column_stack([x.ravel(), y.ravel()])
    return inside_polygon_points(polygon, points).reshape(x.shape)


__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "Raster", "boundary_segments", "points_in_polygon"]
