"""The expected-range table of the beam model, on the world's occupancy grid.

For every cell of amr_common.world.occupancy_grid.OccupancyGrid (the grid the planner and /map use:
cell centres on multiples of the resolution, so a 0.4 m corridor's centre line runs through cell
centres) where a LiDAR can be, and every one of `angles` directions, the range (mm, uint16) a
LiDAR at the cell centre would measure.

Built once per world with the simulator's own ray-casting arithmetic (amr_common.world.raycast), so
the filter's idea of a range is exactly the simulated LiDAR's. Only cells at least `min_clearance`
inside the free space get a row of ranges (`rows` maps every grid cell to its row); every other
cell shares row 0, all zeros, which matches no reading. So the table grows with the free area,
not with the map's bounding box.
Why a table and not a likelihood field: in 0.4 m corridors on a 0.4 m grid, rotated or shifted
poses put every beam endpoint near SOME wall, so a likelihood field scores them almost as well as
the true pose; the expected range along each beam tells them apart (localization-planning.md).
Size: 720 bytes per 2 cm cell at 360 angles, ~10 MB for a 2.4 m maze but 1.8 GB per 1,000 m^2
of free space: table_memory chooses coarser cells and fewer angles for big maps.
Building (table_build): cells in blocks, directions in sectors, each ray tested only against
the walls it can reach first, in slices that a Ctrl-C stops within ~0.1 s; a sample of it first
estimates the whole build (estimated_build_s), so a map whose table would take too long is
refused before it is built (particle_filter_params.check_world).
Tables are cached per (world file, walls, resolution, angles) for the life of the process, so
batch evaluations build each one once; a build sampled for its estimate is kept and finished
by the next expected_range_table() of the same key.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from amr_common.robot import ROBOT_RADIUS
from amr_common.stop_flag import stop_requested
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world import World
from amr_localization.table_build import TableBuild, TableBuildInterrupted
from amr_localization.table_kernels import NO_RANGE_MM

MIN_CLEARANCE_M = 0.01  # cells closer to a wall get no row (the LiDAR cannot be there)
_CACHE: dict[tuple, "ExpectedRangeTable"] = {}
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 8
_STARTED: dict[tuple, TableBuild] = {}  # the build last sampled for its estimate


@dataclass(frozen=True)
class ExpectedRangeTable:
    """Expected ranges (mm) per grid cell and world direction.

    ranges[rows[cell], k]: expected range in mm from the centre of grid cell `cell` (row-major,
    row * width + col, as the grid's arrays) along the world direction k * 2 pi / angles (k = 0
    is +x); rows[cell] == 0 (all zeros) where no LiDAR can be.
    """

    grid: OccupancyGrid
    angles: int
    rows: np.ndarray  # (cells,) int32: the cell's row of `ranges`
    ranges: np.ndarray  # (1 + cells with a row, angles) uint16, mm

    # The grid in the terms of the compiled kernels: lower-left corner, cell size, columns, rows.
    @property
    def x0(self) -> float:
        """The x of the grid's lower-left corner (m)."""
        return self.grid.origin[0]

    @property
    def y0(self) -> float:
        """The y of the grid's lower-left corner (m)."""
        return self.grid.origin[1]

    @property
    def resolution(self) -> float:
        """Cell size (m)."""
        return self.grid.resolution

    @property
    def nx(self) -> int:
        """Columns (cells along x)."""
        return self.grid.width

    @property
    def ny(self) -> int:
        """Rows (cells along y)."""
        return self.grid.height

    @property
    def cells(self) -> int:
        """Cells of the grid."""
        return int(self.rows.size)

    @property
    def nbytes(self) -> int:
        """Memory of the table (bytes): the ranges and the cells' row numbers."""
        return int(self.ranges.nbytes + self.rows.nbytes)

    def cell_ranges(self, cell: int) -> np.ndarray:
        """(angles,) expected ranges (mm) from the centre of grid cell `cell` (zeros: no row)."""
        return self.ranges[self.rows[cell]]

    def cell_index(self, x: float, y: float) -> int:
        """Row-major index of the cell holding (x, y), or -1 off the grid (or not finite)."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return -1
        row, col = self.grid.cell_of(x, y)
        return row * self.nx + col if self.grid.contains_cell(row, col) else -1

    def cell_centres(self, cells: np.ndarray | None = None) -> np.ndarray:
        """(K, 2) centres of the listed cells (row-major indices; default: every cell)."""
        cells = np.arange(self.cells) if cells is None else np.asarray(cells)
        rows, cols = np.divmod(cells, self.nx)
        return self.grid.cell_centres(rows, cols)

    def robot_cells(self, radius: float = ROBOT_RADIUS, slack: float = 0.0) -> np.ndarray:
        """(cells,) uint8: 1 where a robot centre may be (clearance >= radius - slack > 0)."""
        return (self.grid.clearance.ravel() >= max(radius - slack, 1e-9)).astype(np.uint8)


def start_build(world: World, resolution: float = 0.02, angles: int = 360,
                min_clearance: float = MIN_CLEARANCE_M,
                segments: np.ndarray | None = None) -> TableBuild:
    """The build of the table (nothing cast yet): its grid, cells and walls.

    segments: the walls the rays hit (default the world's; a map world's likely walls, see
    amr_common.world.map_raster.likely_wall_segments); the grid stays the world's.
    """
    segments = world.segments if segments is None else segments
    if not (isinstance(angles, int) and 8 <= angles <= 4096):
        raise ValueError(f"table angles must be an integer in [8, 4096], got {angles!r}")
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise ValueError(f"grid resolution must be > 0 m, got {resolution}")
    grid = OccupancyGrid.from_world(world, resolution)
    cells = np.flatnonzero(grid.clearance.ravel() >= min_clearance).astype(np.int64)
    return TableBuild(grid, segments, angles, cells)


def build_expected_range_table(world: World, resolution: float = 0.02, angles: int = 360,
                               min_clearance: float = MIN_CLEARANCE_M,
                               segments: np.ndarray | None = None,
                               stop: Callable[[], bool] = stop_requested) -> ExpectedRangeTable:
    """Build the table (uncached); see expected_range_table() for the cached one.

    TableBuildInterrupted when `stop()` turns true (default: a script's StopFlag was set).
    """
    build = start_build(world, resolution, angles, min_clearance, segments)
    return ExpectedRangeTable(build.grid, angles, build.rows, build.finish(stop))


def _key(world: World, walls: np.ndarray, resolution: float, angles: int) -> tuple:
    return (world.source, walls.tobytes(), float(resolution), int(angles))


def _walls(world: World, segments: np.ndarray | None) -> np.ndarray:
    return world.segments if segments is None else np.ascontiguousarray(segments,
                                                                        dtype=np.float64)


def estimated_build_s(world: World, resolution: float = 0.02, angles: int = 360,
                      segments: np.ndarray | None = None) -> float:
    """Seconds the table would take to build here and now (0 if cached), from a sample.

    The sampled build is kept: expected_range_table() of the same table goes on from it.
    """
    walls = _walls(world, segments)
    key = _key(world, walls, resolution, angles)
    with _CACHE_LOCK:
        if key in _CACHE:
            return 0.0
        build = _STARTED.get(key)
    if build is None:
        build = start_build(world, resolution, angles, segments=walls)
        build.sample()
        with _CACHE_LOCK:
            _STARTED.clear()  # one at a time: each holds its table's memory
            if build.done:  # the sample was the whole table (a small map): cached at once
                _store(key, ExpectedRangeTable(build.grid, angles, build.rows, build.ranges))
            else:
                _STARTED[key] = build
    return float(build.estimate_s)


def forget_started_builds() -> None:
    """Drop the build kept by estimated_build_s (a map refused: its memory is not needed)."""
    with _CACHE_LOCK:
        _STARTED.clear()


def expected_range_table(world: World, resolution: float = 0.02, angles: int = 360,
                         segments: np.ndarray | None = None,
                         stop: Callable[[], bool] = stop_requested) -> ExpectedRangeTable:
    """The table for `world` (rays hitting `segments`, default its walls), cached.

    Built on first use (or finished from the build estimated_build_s sampled) and cached in
    this process, keyed by the world file, the walls, the resolution and the number of angles.
    TableBuildInterrupted when `stop()` turns true while it is built (nothing is cached).
    """
    walls = _walls(world, segments)
    key = _key(world, walls, resolution, angles)
    with _CACHE_LOCK:
        table = _CACHE.get(key)
        build = _STARTED.pop(key, None)
    if table is not None:
        return table
    if build is None:
        build = start_build(world, resolution, angles, segments=walls)
    table = ExpectedRangeTable(build.grid, angles, build.rows, build.finish(stop))
    with _CACHE_LOCK:
        _store(key, table)
    return table


def _store(key: tuple, table: ExpectedRangeTable) -> None:
    """Cache `table` under `key` (the caller holds _CACHE_LOCK)."""
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = table


__all__ = ["ExpectedRangeTable", "MIN_CLEARANCE_M", "NO_RANGE_MM", "TableBuildInterrupted",
           "build_expected_range_table", "estimated_build_s", "expected_range_table",
           "forget_started_builds", "start_build"]
