"""The occupancy grid of a World: free/occupied cells and each cell's distance to the walls.

The one raster of a world: the planner's costs, the particle filter's expected-range table, the
simulator's /map and map files (amr_common.world.map_file) are all on these cells.

    grid = OccupancyGrid.from_world(World.load("lab02"), resolution=0.02)
    row, col = grid.cell_of(1.0, -1.0)
    grid.clearance[row, col]          # 0.2: the centre of a 0.4 m corridor
    grid.occupancy_values()           # int8, row-major from the lower-left cell (nav_msgs order)
    grid.raster()                     # the same as an amr_common.world.map_raster.Raster (/map)

Layout (as nav_msgs/OccupancyGrid, indexed by amr_common.world.cell_grid): cell (row, col) covers x
in origin_x + [col, col + 1) * resolution and y in origin_y + [row, row + 1) * resolution; arrays
are indexed [row, col], row 0 at the bottom (smallest y). Cell CENTRES lie on multiples of the
resolution, so walls and corridor centre lines on a grid of multiples of it (lab02: 0.4 m) pass
exactly through cell centres: a 0.4 m corridor has a row of cells on its centre line, 0.2 m
from both walls.

- `clearance`: exact Euclidean distance (m) from each cell centre to the nearest wall segment,
  computed from the segments (not a distance transform of the raster, so no staircase error);
  0 for centres outside the free space (outside the boundary or inside an obstacle). Computed
  on first use (a /map of 2,500 obstacles does not pay for it).
- `in_boundary`: the centre is inside the boundary (beyond its walls: "unknown" on /map).
- `walls`: a wall passes through the cell (each wall is walked in quarter-cell steps, so every
  point of every wall lies in such a cell).
- `free`: the centre is in the free space and no wall passes through the cell.

A map world's grid is its map's cells (free: value 0; unknown: -1; any other value: a wall)
with the same exact clearances to its walls (the edges of its free cells, World.segments), by a
distance transform (amr_common.world.distance_transform).

No planner specifics (inflation, costs) and no rclpy.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from amr_common.world.cell_grid import CellIndexing, cell_index
from amr_common.world.coverage_grid import box_slices, check_grid_size, inside_polygon_grid
from amr_common.world.distance_transform import free_cell_clearances
from amr_common.world.map_raster import FREE, OCCUPIED, UNKNOWN, Raster

if TYPE_CHECKING:  # world.py builds on the modules this one imports
    from amr_common.world.world import World


@dataclass(frozen=True)
class OccupancyGrid(CellIndexing):
    """Cells of a world at one resolution (see the module docstring for the layout)."""

    resolution: float  # m per cell
    origin: tuple[float, float]  # (x, y) of the lower-left corner of cell (0, 0), m
    free: np.ndarray  # (height, width) bool
    in_boundary: np.ndarray  # (height, width) bool
    walls: np.ndarray  # (height, width) bool: a wall passes through the cell
    # What `clearance` is computed from on first use: the world, and for a polygon world the
    # cell centres' coordinates (xs, ys) and which centres are in its free space.
    world: World = field(repr=False, compare=False)
    centre_axes: tuple[np.ndarray, np.ndarray] | None = field(repr=False, compare=False)
    inside: np.ndarray | None = field(repr=False, compare=False)

    @functools.cached_property
    def clearance(self) -> np.ndarray:
        """(height, width) float64 (m): centres' distances to the walls, 0 off the free space."""
        if self.centre_axes is None:  # a map world: the distances to its free cells' edges
            return free_cell_clearances(self.free, self.resolution)
        xs, ys = self.centre_axes
        gx, gy = np.meshgrid(xs, ys)
        distance = self.world.clearances(np.column_stack([gx.ravel(), gy.ravel()]))
        return np.where(self.inside, distance.reshape(self.shape), 0.0)

    @classmethod
    def from_world(cls, world: World, resolution: float = 0.02,
                   padding_m: float | None = None) -> "OccupancyGrid":
        """Rasterize `world`: cells from `padding_m` (default one cell) beyond its walls.

        A map world (world.raster set): the map's own cells at its own resolution, whatever
        `resolution` and `padding_m` say (a re-rasterization of its walls would move them).
        """
        if world.raster is not None:
            return cls._from_map_world(world)
        if isinstance(resolution, bool) or not (isinstance(resolution, (int, float))
                                                and math.isfinite(resolution)
                                                and resolution > 0):
            raise ValueError(f"resolution must be a positive number of metres, got {resolution!r}")
        resolution = float(resolution)
        first, (height, width) = _first_cell_and_shape(world, resolution, padding_m)
        check_grid_size(float(width), float(height), resolution,
                        f"{world.source}: the occupancy grid", "use a larger resolution")
        xs = (first[0] + np.arange(width)) * resolution
        ys = (first[1] + np.arange(height)) * resolution
        in_boundary = np.ones((height, width), dtype=bool) if world.boundary is None else \
            inside_polygon_grid(world.boundary, xs, ys)
        inside = in_boundary & ~_hole_cells(world.holes, xs, ys)
        origin = (float(xs[0] - 0.5 * resolution), float(ys[0] - 0.5 * resolution))
        walls = wall_cells(world.segments, origin, resolution, (height, width))
        return cls(resolution, origin, inside & ~walls, in_boundary, walls, world, (xs, ys),
                   inside)

    @classmethod
    def _from_map_world(cls, world: World) -> "OccupancyGrid":
        raster = world.raster
        free = raster.free
        in_boundary = raster.values != UNKNOWN
        return cls(float(raster.resolution), (float(raster.origin[0]), float(raster.origin[1])),
                   free, in_boundary, in_boundary & ~free, world, None, None)

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width)."""
        return self.free.shape

    def clearance_at(self, x: float, y: float) -> float:
        """Clearance of the cell containing (x, y) (0 outside the grid)."""
        row, col = self.cell_of(x, y)
        return float(self.clearance[row, col]) if self.contains_cell(row, col) else 0.0

    def occupancy_values(self) -> np.ndarray:
        """Int8 (height, width) cell values: free 0, occupied 100, unknown -1.

        Occupied: walls and obstacles; unknown: beyond the boundary walls.
        """
        values = np.where(self.free, FREE, OCCUPIED).astype(np.int8)
        values[~self.in_boundary & ~self.walls] = UNKNOWN
        return values

    def raster(self) -> Raster:
        """The grid as a Raster of occupancy_values(): what /map and map files carry."""
        return Raster(self.occupancy_values(), self.resolution, self.origin)


def grid_shape(world: World, resolution: float, padding_m: float | None = None
               ) -> tuple[int, int]:
    """(height, width) of OccupancyGrid.from_world(world, resolution, padding_m), not built.

    A map world's: its map's (resolution and padding_m do not apply, as in from_world).
    """
    if world.raster is not None:
        height, width = world.raster.values.shape
        return int(height), int(width)
    return _first_cell_and_shape(world, float(resolution), padding_m)[1]


def _first_cell_and_shape(world: World, resolution: float, padding_m: float | None):
    pad = 1 if padding_m is None else max(0, math.ceil(round(padding_m / resolution, 6)))
    xmin, ymin, xmax, ymax = world.bounds
    # Index of the cell whose centre is at k * resolution; rounding first so that -1.2 / 0.02
    # (= -60.000000000000014 in floating point) counts as -60.
    first = [math.floor(round(v / resolution, 6)) - pad for v in (xmin, ymin)]
    last = [math.ceil(round(v / resolution, 6)) + pad for v in (xmax, ymax)]
    return first, (last[1] - first[1] + 1, last[0] - first[0] + 1)


def _hole_cells(holes, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(len(ys), len(xs)) bool: cell centres inside some obstacle (each within its box).

    The even-odd test of World.contains_points, row by row over each hole's bounding box: a
    world of thousands of obstacles stays cheap.
    """
    cells = np.zeros((ys.size, xs.size), dtype=bool)
    for hole in holes:
        columns, band = box_slices(xs, ys, *hole.min(axis=0), *hole.max(axis=0))
        cells[band, columns] |= inside_polygon_grid(hole, xs[columns], ys[band])
    return cells


def wall_cells(segments: np.ndarray, origin: tuple[float, float], resolution: float,
               shape: tuple[int, int]) -> np.ndarray:
    """(height, width) bool: the cells some wall passes through (walked in quarter cells)."""
    cells = np.zeros(shape, dtype=bool)
    for x1, y1, x2, y2 in segments:
        n = max(2, math.ceil(math.hypot(x2 - x1, y2 - y1) / (0.25 * resolution)) + 1)
        t = np.linspace(0.0, 1.0, n)
        rows = cell_index(y1 + t * (y2 - y1), origin[1], resolution).astype(int)
        cols = cell_index(x1 + t * (x2 - x1), origin[0], resolution).astype(int)
        keep = (rows >= 0) & (rows < shape[0]) & (cols >= 0) & (cols < shape[1])
        cells[rows[keep], cols[keep]] = True
    return cells


__all__ = ["OccupancyGrid", "FREE", "OCCUPIED", "UNKNOWN", "grid_shape", "wall_cells"]
