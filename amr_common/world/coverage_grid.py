"""The coverage grid of a world: square cells behind the "explored" and "laps" metrics.

A cell is free when its centre is inside the boundary, outside every hole and farther than a
margin (the robot radius) from every wall. The grid is aligned with the map: its lines pass
through `origin` (the world file's `grid_origin`, by default the lower-left corner of the
boundary's bounding box), so a course map whose 0.4 m corridors start at its boundary has one
cell centred in each corridor square.

Rasterized with numpy: each polygon is scan-converted row by row over the cells of its bounding
box (even-odd rule, the same arithmetic as a point-by-point test) and each wall marks only the
cells within the margin of its bounding box, so the cost grows with the cells plus the walls,
not with their product (a 2,500-obstacle world: well under a second instead of minutes).
A grid of more than MAX_GRID_CELLS cells is refused with GridTooLargeError (+-1e6 m coordinates
at 0.4 m would need 2.5e13 cells). The /map raster (amr_common.world.map_raster) uses the same
polygon fill, bounding boxes and limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from amr_common.world.cell_grid import CellIndexing

MAX_GRID_CELLS = 4_000_000  # 800 m x 800 m at 0.4 m; about 30 MB of working arrays
_CHUNK_CELLS = 262_144  # rows are processed in blocks of about this many cells
_EPS = 1e-9  # relative slack so that a boundary on a grid line does not add a row of cells


class GridTooLargeError(ValueError):
    """A grid over a world would have too many cells; the message says what to change."""


def check_grid_size(columns: float, rows: float, cell_size: float, what: str,
                    remedy: str) -> None:
    """Raise GridTooLargeError if a rows x columns grid exceeds MAX_GRID_CELLS.

    Floats: an absurd count is reported, never allocated. `what` names the grid (and its
    file), `remedy` says what to change.
    """
    if columns * rows > MAX_GRID_CELLS:
        raise GridTooLargeError(
            f"{what} would need {_count(columns)} x {_count(rows)} = {_count(columns * rows)} "
            f"cells of {cell_size:g} m (limit {MAX_GRID_CELLS:,}): {remedy}")


def _count(value: float) -> str:
    """A cell count as a user reads it: '4,002,000' (not '4e+06', which reads as the limit)."""
    return f"{value:,.0f}" if value < 1e18 else f"{value:.3g}"


@dataclass(frozen=True)
class CoverageGrid(CellIndexing):
    """Square cells of `cell_size` m and which of them are free.

    Indexed as every grid of a world (amr_common.world.cell_grid): cell (row i, column j) has its
    centre at (origin_x + (j + 0.5) * cell_size, origin_y + (i + 0.5) * cell_size).
    """

    resolution: float  # the cell size, m
    origin: tuple[float, float]  # (x, y) of the lower-left corner of cell (0, 0), m
    free: np.ndarray  # (rows, columns) bool

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns)."""
        return self.free.shape

    @property
    def cell_size(self) -> float:
        """The cell size (m): the world file's `cell_size`."""
        return self.resolution

    def free_centres(self) -> np.ndarray:
        """(K, 2) centres of the free cells, row by row (y, then x, increasing)."""
        rows, columns = np.nonzero(self.free)
        return np.column_stack([self.x_centres[columns], self.y_centres[rows]])

    def visited(self, positions: np.ndarray) -> np.ndarray:
        """(rows, columns) bool: cells whose centre some position passed within cell_size / 2."""
        pos = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        row, column = self.cells_of(pos[:, 0], pos[:, 1])
        # A point within cs / 2 of a centre lies in that centre's cell.
        centres = self.cell_centres(row, column)
        near = np.hypot(centres[:, 0] - pos[:, 0], centres[:, 1] - pos[:, 1]) <= \
            self.resolution / 2
        rows, columns = self.free.shape
        keep = near & (column >= 0) & (column < columns) & (row >= 0) & (row < rows)
        out = np.zeros(self.free.shape, dtype=bool)
        out[row[keep].astype(np.intp), column[keep].astype(np.intp)] = True
        return out


def build_coverage_grid(segments: np.ndarray, boundary: np.ndarray | None,
                        holes: Sequence[np.ndarray], cell_size: float,
                        origin: tuple[float, float] | None, margin: float,
                        source: str = "world",
                        clearances: Callable[[np.ndarray], np.ndarray] | None = None
                        ) -> CoverageGrid:
    """Rasterize the free cells over the boundary's bounding box (all walls' without one).

    `origin`: a point the grid lines pass through; None = the box's lower-left corner.
    `clearances`: the distance from each of (K, 2) points to the nearest wall, if the world
    answers it faster than the walls one by one (World.clearances of a map with millions of
    walls); the same cells. Raises GridTooLargeError naming `source` if the grid would exceed
    MAX_GRID_CELLS.
    """
    extent = boundary if boundary is not None else segments.reshape(-1, 2)
    xmin, ymin = (float(v) for v in extent.min(axis=0))
    xmax, ymax = (float(v) for v in extent.max(axis=0))
    ox, oy = origin if origin is not None else (xmin, ymin)
    cs = float(cell_size)
    first_x, count_x = _cell_range(xmin, xmax, ox, cs)
    first_y, count_y = _cell_range(ymin, ymax, oy, cs)
    check_grid_size(count_x, count_y, cs, f"{source}: the coverage grid over "
                    f"{xmax - xmin:.3g} m x {ymax - ymin:.3g} m",
                    "set a larger cell_size in the world file")
    grid_x, grid_y = ox + first_x * cs, oy + first_y * cs
    xs = grid_x + (np.arange(int(count_x)) + 0.5) * cs
    ys = grid_y + (np.arange(int(count_y)) + 0.5) * cs
    free = inside_polygon_grid(boundary, xs, ys) if boundary is not None else \
        np.ones((ys.size, xs.size), dtype=bool)
    for hole in holes:
        columns, rows = box_slices(xs, ys, *hole.min(axis=0), *hole.max(axis=0))
        free[rows, columns] &= ~inside_polygon_grid(hole, xs[columns], ys[rows])
    if clearances is not None:
        rows, columns = np.nonzero(free)
        free[rows, columns] = clearances(np.column_stack([xs[columns], ys[rows]])) > margin
        return CoverageGrid(cs, (grid_x, grid_y), free)
    for segment in segments:
        _clear_near_segment(free, segment, xs, ys, margin)
    return CoverageGrid(cs, (grid_x, grid_y), free)


def inside_polygon_points(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(K,) bool: points of a (K, 2) array inside a closed polygon (even-odd rule)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    px, py = polygon[:, 0], polygon[:, 1]
    qx, qy = np.roll(px, -1), np.roll(py, -1)
    out = np.empty(len(pts), dtype=bool)
    step = max(1, _CHUNK_CELLS // max(len(polygon), 1))
    for start in range(0, len(pts), step):
        x = pts[start:start + step, 0:1]
        y = pts[start:start + step, 1:2]
        crosses = (py > y) != (qy > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = px + (y - py) * (qx - px) / (qy - py)
        out[start:start + step] = np.count_nonzero(crosses & (x < x_cross), axis=1) % 2 == 1
    return out


def _cell_range(low: float, high: float, origin: float, cs: float) -> tuple[float, float]:
    """First cell index and cell count covering [low, high] on a grid through `origin`.

    Floats, so an absurd count is reported rather than allocated.
    """
    first = math.floor((low - origin) / cs + _EPS)
    last = math.ceil((high - origin) / cs - _EPS)
    return float(first), float(max(last - first, 0))


def inside_polygon_grid(polygon: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(len(ys), len(xs)) bool: grid points (xs increasing) inside a closed polygon.

    Even-odd rule, row by row: the same arithmetic as inside_polygon_points, at a cost of
    rows x edges + points instead of points x edges.
    """
    px, py = polygon[:, 0], polygon[:, 1]
    qx, qy = np.roll(px, -1), np.roll(py, -1)
    out = np.zeros((np.size(ys), np.size(xs)), dtype=bool)
    for row, y in enumerate(ys):
        crosses = (py > y) != (qy > y)
        if not crosses.any():
            continue
        a, b, c, d = px[crosses], py[crosses], qx[crosses], qy[crosses]
        x_cross = np.sort(a + (y - b) * (c - a) / (d - b))
        # The number of crossings right of each centre (x < x_cross), as a point-by-point test.
        right = x_cross.size - np.searchsorted(x_cross, xs, side="right")
        out[row] = right % 2 == 1
    return out


def box_slices(xs: np.ndarray, ys: np.ndarray, x0: float, y0: float, x1: float, y1: float
               ) -> tuple[slice, slice]:
    """Column and row slices of the grid points (xs, ys increasing) within [x0, x1] x [y0, y1].

    Polygons and walls touch only the cells of their bounding box: restricting the work to it
    keeps a world of thousands of small obstacles cheap.
    """
    return (slice(int(np.searchsorted(xs, x0, side="left")),
                  int(np.searchsorted(xs, x1, side="right"))),
            slice(int(np.searchsorted(ys, y0, side="left")),
                  int(np.searchsorted(ys, y1, side="right"))))


def _clear_near_segment(free: np.ndarray, segment: np.ndarray, xs: np.ndarray, ys: np.ndarray,
                        margin: float) -> None:
    """Clear the cells whose centre is within `margin` of the segment (clearance <= margin)."""
    x1, y1, x2, y2 = (float(v) for v in segment)
    columns, rows = box_slices(xs, ys, min(x1, x2) - margin, min(y1, y2) - margin,
                                max(x1, x2) + margin, max(y1, y2) + margin)
    width = columns.stop - columns.start
    if width <= 0 or rows.start >= rows.stop:
        return
    ex, ey = x2 - x1, y2 - y1
    px = xs[columns][None, :]
    block = max(1, _CHUNK_CELLS // width)
    for top in range(rows.start, rows.stop, block):
        band = slice(top, min(top + block, rows.stop))
        py = ys[band][:, None]
        t = np.clip(((px - x1) * ex + (py - y1) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
        dx, dy = x1 + t * ex - px, y1 + t * ey - py
        free[band, columns] &= np.sqrt(dx * dx + dy * dy) > margin


__all__ = ["MAX_GRID_CELLS", "GridTooLargeError", "check_grid_size", "CoverageGrid",
           "build_coverage_grid", "inside_polygon_points", "inside_polygon_grid", "box_slices"]
