"""The cell indexing every grid of a world shares: which cell holds a point, where its centre is.

Layout (as nav_msgs/OccupancyGrid): square cells of `resolution` m; cell (row, col) covers x in
origin_x + [col, col + 1) * resolution and y in origin_y + [row, row + 1) * resolution; arrays
are indexed [row, col], row 0 at the bottom (smallest y).

`CellIndexing` is a mixin: a class with `resolution`, `origin` (x, y) and `shape` (rows, cols)
gets cell_of, cells_of, contains_cell, cell_centre(s) and the row / column centres. The world's
occupancy grid (amr_common.world.occupancy_grid: the planner, the particle filter, /map and map
files), a map's raster (amr_common.world.map_raster) and the coarse coverage grid of the "explored"
and "laps" metrics (amr_common.world.coverage_grid) all index their cells with it. No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np


def cell_index(values, origin: float, resolution: float) -> np.ndarray:
    """Float array: the row (or column) index of each coordinate (floor; NaN stays NaN)."""
    with np.errstate(invalid="ignore"):
        return np.floor((np.asarray(values, dtype=np.float64) - origin) / resolution)


class CellIndexing:
    """Cell arithmetic for a grid with `resolution`, `origin` and `shape` (see the module)."""

    resolution: float  # m per cell
    origin: tuple[float, float]  # (x, y) of the lower-left corner of cell (0, 0), m

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the grid."""
        raise NotImplementedError

    @property
    def width(self) -> int:
        """Number of columns (cells along x)."""
        return int(self.shape[1])

    @property
    def height(self) -> int:
        """Number of rows (cells along y)."""
        return int(self.shape[0])

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell containing the point; may lie outside the grid."""
        return (math.floor((y - self.origin[1]) / self.resolution),
                math.floor((x - self.origin[0]) / self.resolution))

    def cells_of(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) float arrays of the cells holding the points (x[k], y[k]).

        The same arithmetic as cell_of; may lie outside the grid; NaN for non-finite points.
        """
        return (cell_index(y, self.origin[1], self.resolution),
                cell_index(x, self.origin[0], self.resolution))

    def contains_cell(self, row: int, col: int) -> bool:
        """True if (row, col) is a cell of this grid."""
        return 0 <= row < self.height and 0 <= col < self.width

    def cell_centre(self, row: int, col: int) -> tuple[float, float]:
        """(x, y) of a cell's centre."""
        return (self.origin[0] + (col + 0.5) * self.resolution,
                self.origin[1] + (row + 0.5) * self.resolution)

    def cell_centres(self, rows, cols) -> np.ndarray:
        """(K, 2) centres of the cells (rows[k], cols[k])."""
        return np.column_stack([self.origin[0] + (np.asarray(cols) + 0.5) * self.resolution,
                                self.origin[1] + (np.asarray(rows) + 0.5) * self.resolution])

    @property
    def x_centres(self) -> np.ndarray:
        """Centre x of each column (m)."""
        return self.origin[0] + (np.arange(self.width) + 0.5) * self.resolution

    @property
    def y_centres(self) -> np.ndarray:
        """Centre y of each row (m)."""
        return self.origin[1] + (np.arange(self.height) + 0.5) * self.resolution


__all__ = ["CellIndexing", "cell_index"]
