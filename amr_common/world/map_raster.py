"""Occupancy rasters in the ROS map convention (no ROS import), and a map's cells to walls.

Values as nav_msgs/OccupancyGrid: FREE 0, OCCUPIED 100, UNKNOWN -1. Row r, column c is the cell
[x0 + c*res, x0 + (c+1)*res) x [y0 + r*res, y0 + (r+1)*res): row 0 is the southmost (the
message's data is this array flattened row by row), indexed as every grid
(amr_common.world.cell_grid). A world's raster is its occupancy grid's
(amr_common.world.occupancy_grid: OccupancyGrid.from_world(world, resolution).raster(), the cells
the planner and the filter use): OCCUPIED where a wall passes through a cell or it lies inside an
obstacle, UNKNOWN outside the boundary, else FREE.

The other way (a map read from a file, amr_common.world.map_file, or built by SLAM): only FREE
cells (value 0, as AMCL counts free) are free space; occupied, unknown and in-between values and
everything beyond the raster are walls. `boundary_segments` gives the edges between free and
non-free cells merged into maximal straight segments: the walls the simulator, the ray
casting and the clearances of a map world use (a 2 cm lab02: 36 segments for its 16 polygon
walls, not one per cell edge).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amr_common.world.cell_grid import CellIndexing
from amr_common.world.coverage_grid import inside_polygon_points

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


def likely_wall_segments(raster: Raster) -> np.ndarray:
    """(N, 4) segments where the map's walls most likely are: inside the occupied cells.

    A map marks the cells a wall passes through (world_to_map) or that rays hit (SLAM), so the
    wall lies inside its occupied cells, not on their free-side edges (boundary_segments, up to
    a cell into the free space: what a robot must not enter, not what a LiDAR measures). Each
    free/non-free edge is moved into the non-free side: to the middle of a band of exactly two
    occupied cells (SLAM marks both cells around a wall: the wall is between them), else to the
    first cell's centre (a converted map's one-cell walls, solid blocks, unknown cells).
    Segments are extended at their ends by as much, so a corner of the free space stays closed
    to rays, except at a wall's tip (free on both sides beyond it), where they stop at the cell
    centre.
    """
    free = np.zeros((raster.values.shape[0] + 2, raster.values.shape[1] + 2), dtype=bool)
    free[1:-1, 1:-1] = raster.free
    occupied = np.zeros_like(free)
    occupied[1:-1, 1:-1] = raster.values == OCCUPIED
    res, (x0, y0) = raster.resolution, raster.origin
    parts = []
    for along_x in (True, False):  # edges on horizontal grid lines, then on vertical ones
        f, o = (free, occupied) if along_x else (free.T, occupied.T)
        for free_below in (True, False):
            for line, start, stop in _moved_edges(f, o, free_below):
                if along_x:
                    parts.append(np.column_stack([x0 + start * res, y0 + line * res,
                                                  x0 + stop * res, y0 + line * res]))
                else:
                    parts.append(np.column_stack([x0 + line * res, y0 + start * res,
                                                  x0 + line * res, y0 + stop * res]))
    return np.ascontiguousarray(np.vstack(parts), dtype=np.float64)


def _moved_edges(free: np.ndarray, occupied: np.ndarray, free_below: bool):
    """(line, start, stop) in cells of the edges between padded rows i and i + 1, moved.

    Edges with the free cell below (free_below) or above, moved into the non-free side (see
    likely_wall_segments); yields one array triple per depth (half a cell, one cell).
    """
    low, high = free[:-1], free[1:]
    free_side, wall_side = (low, high) if free_below else (high, low)
    edge = free_side & ~wall_side
    step = 1 if free_below else -1
    first_wall = np.arange(edge.shape[0]) + (1 if free_below else 0)  # padded row of the cell

    def occupied_at(k: int) -> np.ndarray:  # the k-th non-free cell beyond each edge
        rows = first_wall + step * k
        inside = (rows >= 0) & (rows < occupied.shape[0])
        out = np.zeros_like(edge)
        out[inside] = occupied[rows[inside]]
        return out

    two = occupied_at(0) & occupied_at(1) & ~occupied_at(2)
    for mask, depth in ((edge & ~two, 0.5), (edge & two, 1.0)):
        line, first, end = _runs(mask[:, 1:-1])
        rows, before, after = line.astype(np.intp), first.astype(np.intp), end.astype(np.intp) + 1
        # Beyond an end (padded columns `before` and `after`): free on both sides = a wall's tip.
        tip_before = free_side[rows, before] & wall_side[rows, before]
        tip_after = free_side[rows, after] & wall_side[rows, after]
        yield (line + step * depth, first - np.where(tip_before, -depth, depth),
               end + np.where(tip_after, -depth, depth))


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


__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "Raster", "boundary_segments", "likely_wall_segments",
           "points_in_polygon"]
