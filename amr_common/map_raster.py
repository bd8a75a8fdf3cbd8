"""A world's walls as an occupancy raster in the ROS map convention (no ROS import).

Values as nav_msgs/OccupancyGrid: FREE 0, OCCUPIED 100, UNKNOWN -1. Row r, column c is the cell
[x0 + c*res, x0 + (c+1)*res) x [y0 + r*res, y0 + (r+1)*res): row 0 is the southmost (the
message's data is this array flattened row by row). A cell is OCCUPIED when a wall passes through
it or it lies inside an obstacle (a world's `holes`), UNKNOWN outside the boundary, else FREE.
The grid is aligned with multiples of the resolution and padded by `padding_m` of UNKNOWN; one
of more than amr_common.coverage_grid.MAX_GRID_CELLS cells raises GridTooLargeError.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.coverage_grid import (
    box_slices,
    check_grid_size,
    inside_polygon_grid,
    inside_polygon_points,
)
from amr_common.occupancy_grid import FREE, OCCUPIED, UNKNOWN, wall_cells


@dataclass(frozen=True)
class Raster:
    """values: (rows, cols) int8; origin: (x, y) of the lower-left corner of cell (0, 0), m."""

    values: np.ndarray
    resolution: float
    origin: tuple[float, float]

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell containing (x, y) (may lie outside the raster)."""
        return (int(math.floor((y - self.origin[1]) / self.resolution)),
                int(math.floor((x - self.origin[0]) / self.resolution)))

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """X and y of every cell centre, each shaped like `values`."""
        rows, cols = self.values.shape
        xs = self.origin[0] + (np.arange(cols) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(rows) + 0.5) * self.resolution
        return np.meshgrid(xs, ys)


def points_in_polygon(polygon: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Even-odd test of many points against one closed polygon ((K, 2) vertices)."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    points = np.column_stack([x.ravel(), y.ravel()])
    return inside_polygon_points(polygon, points).reshape(x.shape)


def rasterize_world(world, resolution: float = 0.05, padding_m: float = 0.1) -> Raster:
    """The occupancy raster of an amr_common.world.World at `resolution` metres per cell."""
    if isinstance(resolution, bool) or not (isinstance(resolution, (int, float))
                                            and math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"map resolution must be > 0 m, got {resolution!r}")
    xmin, ymin, xmax, ymax = world.bounds
    x0 = math.floor((xmin - padding_m) / resolution) * resolution
    y0 = math.floor((ymin - padding_m) / resolution) * resolution
    cols = math.ceil((xmax + padding_m - x0) / resolution)
    rows = math.ceil((ymax + padding_m - y0) / resolution)
    check_grid_size(float(cols), float(rows), resolution,
                    f"{world.source}: the map raster over {xmax - xmin:.3g} m x "
                    f"{ymax - ymin:.3g} m", "set a larger map resolution")
    raster = Raster(np.full((rows, cols), FREE, dtype=np.int8), float(resolution), (x0, y0))
    values = raster.values
    xs = x0 + (np.arange(cols) + 0.5) * resolution
    ys = y0 + (np.arange(rows) + 0.5) * resolution
    if world.boundary is not None:
        values[~inside_polygon_grid(world.boundary, xs, ys)] = UNKNOWN
    for hole in world.holes:  # each within its bounding box: thousands of obstacles stay cheap
        columns, band = box_slices(xs, ys, *hole.min(axis=0), *hole.max(axis=0))
        block = values[band, columns]
        block[inside_polygon_grid(hole, xs[columns], ys[band])] = OCCUPIED
    values[wall_cells(world.segments, (x0, y0), resolution, (rows, cols))] = OCCUPIED
    return raster


__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "Raster", "points_in_polygon", "rasterize_world"]
