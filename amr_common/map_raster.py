"""A world's walls as an occupancy raster in the ROS map convention (no ROS import).

Values as nav_msgs/OccupancyGrid: FREE 0, OCCUPIED 100, UNKNOWN -1. Row r, column c is the cell
[x0 + c*res, x0 + (c+1)*res) x [y0 + r*res, y0 + (r+1)*res): row 0 is the southmost (the
message's data is this array flattened row by row). A cell is OCCUPIED when a wall passes through
it or it lies inside an obstacle (a world's `holes`), UNKNOWN outside the boundary, else FREE.
The cells are those of amr_common.occupancy_grid (the planner's grid: centres on multiples of
the resolution), padded by `padding_m` of UNKNOWN.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.geometry import points_in_polygon
from amr_common.occupancy_grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid


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


def rasterize_world(world, resolution: float = 0.05, padding_m: float = 0.1) -> Raster:
    """The occupancy raster of an amr_common.world.World at `resolution` metres per cell."""
    if isinstance(resolution, bool) or not (isinstance(resolution, (int, float))
                                            and math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"map resolution must be > 0 m, got {resolution!r}")
    grid = OccupancyGrid.from_world(world, resolution, padding_m)
    return Raster(grid.occupancy_values(), grid.resolution, grid.origin)


__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "Raster", "points_in_polygon", "rasterize_world"]
