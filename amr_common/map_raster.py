"""A world's walls as an occupancy raster in the ROS map convention (no ROS import).

Values as nav_msgs/OccupancyGrid: FREE 0, OCCUPIED 100, UNKNOWN -1. Row r, column c is the cell
[x0 + c*res, x0 + (c+1)*res) x [y0 + r*res, y0 + (r+1)*res): row 0 is the southmost (the
message's data is this array flattened row by row). A cell is OCCUPIED when a wall passes through
it or it lies inside an obstacle (a world's `holes`), UNKNOWN outside the boundary, else FREE.
The grid is aligned with multiples of the resolution and padded by `padding_m` of UNKNOWN.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FREE, OCCUPIED, UNKNOWN = 0, 100, -1


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
    inside = np.zeros(np.shape(x), dtype=bool)
    px, py = polygon[:, 0], polygon[:, 1]
    qx, qy = np.roll(px, -1), np.roll(py, -1)
    for x1, y1, x2, y2 in zip(px, py, qx, qy):
        if y1 == y2:
            continue  # a horizontal edge never crosses the horizontal ray
        crosses = (y1 > y) != (y2 > y)
        x_cross = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (x < x_cross)
    return inside


def rasterize_world(world, resolution: float = 0.05, padding_m: float = 0.1) -> Raster:
    """The occupancy raster of a amr_common.world.World at `resolution` metres per cell."""
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"map resolution must be > 0 m, got {resolution!r}")
    xmin, ymin, xmax, ymax = world.bounds
    x0 = math.floor((xmin - padding_m) / resolution) * resolution
    y0 = math.floor((ymin - padding_m) / resolution) * resolution
    cols = int(math.ceil((xmax + padding_m - x0) / resolution))
    rows = int(math.ceil((ymax + padding_m - y0) / resolution))
    raster = Raster(np.full((rows, cols), FREE, dtype=np.int8), float(resolution), (x0, y0))
    values = raster.values
    cx, cy = raster.centres()
    if world.boundary is not None:
        values[~points_in_polygon(world.boundary, cx, cy)] = UNKNOWN
    for hole in world.holes:
        values[points_in_polygon(hole, cx, cy)] = OCCUPIED
    # Walls: every cell a segment passes through, sampled at a quarter cell.
    for x1, y1, x2, y2 in world.segments:
        n = max(2, int(math.ceil(math.hypot(x2 - x1, y2 - y1) / (0.25 * resolution))) + 1)
        t = np.linspace(0.0, 1.0, n)
        r = np.floor((y1 + t * (y2 - y1) - y0) / resolution).astype(int)
        c = np.floor((x1 + t * (x2 - x1) - x0) / resolution).astype(int)
        keep = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        values[r[keep], c[keep]] = OCCUPIED
    return raster


__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "Raster", "points_in_polygon", "rasterize_world"]
