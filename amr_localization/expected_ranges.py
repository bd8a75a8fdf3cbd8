"""The expected-range table of the beam model, on the world's occupancy grid.

For every cell of amr_common.world.occupancy_grid.OccupancyGrid (the grid the planner and /map use:
cell centres on multiples of the resolution, so a 0.4 m corridor's centre line runs through cell
centres) where a LiDAR can be, and every one of `angles` directions, the range (mm, uint16) a
LiDAR at the cell centre would measure.

Built once per world with the simulator's own ray-casting kernel (amr_common.world.raycast), so the
filter's idea of a range is exactly the simulated LiDAR's. Only cells at least `min_clearance`
inside the free space get a row of ranges (`rows` maps every grid cell to its row); every other
cell shares row 0, all zeros, which matches no reading. So the table grows with the free area,
not with the map's bounding box.
Why a table and not a likelihood field: in 0.4 m corridors on a 0.4 m grid, rotated or shifted
poses put every beam endpoint near SOME wall, so a likelihood field scores them almost as well as
the true pose; the expected range along each beam tells them apart (localization-planning.md).
Size: 720 bytes per 2 cm cell at 360 angles, ~10 MB for a 2.4 m maze but 1.8 GB per 1,000 m^2
of free space: table_memory chooses coarser cells and fewer angles for big maps.
Building: each ray is cast first against the walls near its cell's block (0.5 m), then farther
ones only if it found no wall that close: the same kernel on fewer walls, the same ranges.
Tables are cached per (world file, resolution, angles) for the life of the process, so batch
evaluations build each one once.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

from amr_common.jit import HAVE_NUMBA, jit
from amr_common.robot import ROBOT_RADIUS
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.raycast import scan_kernel, scan_numpy, segment_offset
from amr_common.world.world import World

NO_RANGE_MM = 65535  # a ray that hits nothing (or beyond 65.5 m)
MIN_CLEARANCE_M = 0.01  # cells closer to a wall get no row (the LiDAR cannot be there)
_BLOCK_M = 0.5  # cells are cast in square blocks of about this size ...
_NEAR_M = 1.5  # ... first against the walls within this distance of the block's centre,
_FAR_M = 5.0  # ... then within this one, then all (only rays that found no wall closer)
_CACHE: dict[tuple, "ExpectedRangeTable"] = {}
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 8


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


def _store_mm_python(ranges, out_row):
    for k in range(ranges.shape[0]):
        mm = ranges[k] * 1000.0
        out_row[k] = NO_RANGE_MM if not (mm < NO_RANGE_MM) else np.uint16(round(mm))


# _fill_python calls `_store_mm`: the jitted version when numba is there (resolved when numba
# compiles it), the Python one otherwise.
_store_mm = jit(_store_mm_python)


def _fill_python(segments, x0, y0, resolution, nx, cells, block_starts, block_centres,
                 reach, rows, base_cos, base_sin, out):
    """Ranges (mm) of every listed cell into out[rows[cell], :], with the shared scan kernel.

    cells: grouped by block (block b: cells[block_starts[b]:block_starts[b + 1]], centred on
    block_centres[b]); reach: how far from a block's centre a cell is at most. A ray cast against
    the walls within R of the block's centre and hitting one within R - reach hit the nearest
    wall of all (any other wall is farther than R from the centre, so than R - reach from the
    cell): only the other rays are cast again, against more walls.
    """
    n_rays = base_cos.shape[0]
    n_seg = segments.shape[0]
    near = np.empty((n_seg, 4))
    far = np.empty((n_seg, 4))
    ranges = np.empty(n_rays)
    noise = np.zeros(n_rays)
    pending = np.empty(n_rays, dtype=np.int64)
    for b in range(block_starts.shape[0] - 1):
        bx = block_centres[b, 0]
        by = block_centres[b, 1]
        n_near = 0
        n_far = 0
        for s in range(n_seg):
            d = segment_offset(segments, s, bx, by)[2]
            if d <= _NEAR_M:
                near[n_near] = segments[s]
                n_near += 1
            if d <= _FAR_M:
                far[n_far] = segments[s]
                n_far += 1
        for i in range(block_starts[b], block_starts[b + 1]):
            cell = cells[i]
            x = x0 + (cell % nx + 0.5) * resolution
            y = y0 + (cell // nx + 0.5) * resolution
            scan_kernel(near[:n_near], x, y, 0.0, base_cos, base_sin, 0.0, np.inf, np.inf,
                        noise, ranges)
            for level in range(2):
                limit = (_NEAR_M if level == 0 else _FAR_M) - reach
                count = 0
                for k in range(n_rays):
                    if not ranges[k] <= limit:
                        pending[count] = k
                        count += 1
                if count == 0:
                    break
                rays = pending[:count]
                again = np.empty(count)
                if level == 0:
                    scan_kernel(far[:n_far], x, y, 0.0, base_cos[rays], base_sin[rays], 0.0,
                                np.inf, np.inf, noise[:count], again)
                else:
                    scan_kernel(segments, x, y, 0.0, base_cos[rays], base_sin[rays], 0.0,
                                np.inf, np.inf, noise[:count], again)
                for j in range(count):
                    ranges[rays[j]] = again[j]
            _store_mm(ranges, out[rows[cell]])


_fill_kernel = jit(_fill_python)


def _fill_numpy(segments, x0, y0, resolution, nx, cells, block_starts, block_centres, reach,
                rows, base_cos, base_sin, out):
    """Every ray against every wall (the fallback without numba: the same ranges)."""
    ranges = np.empty(base_cos.shape[0])
    zeros = np.zeros_like(ranges)
    for cell in cells:
        x, y = x0 + (cell % nx + 0.5) * resolution, y0 + (cell // nx + 0.5) * resolution
        scan_numpy(segments, x, y, 0.0, base_cos, base_sin, 0.0, np.inf, np.inf, zeros, ranges)
        mm = np.where(ranges * 1000.0 < NO_RANGE_MM, np.round(ranges * 1000.0), NO_RANGE_MM)
        out[rows[cell]] = mm.astype(np.uint16)


def _blocks(grid: OccupancyGrid, cells: np.ndarray) -> tuple[np.ndarray, ...]:
    """The cells grouped by square blocks of about _BLOCK_M: (cells, starts, centres, reach)."""
    side = max(1, int(round(_BLOCK_M / grid.resolution)))
    row, col = np.divmod(cells, grid.width)
    block = (row // side) * (grid.width // side + 1) + col // side
    order = np.argsort(block, kind="stable")
    cells, block, row, col = cells[order], block[order], row[order], col[order]
    starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1], True]).astype(np.int64)
    first = starts[:-1]
    corner_row, corner_col = (row[first] // side) * side, (col[first] // side) * side
    centres = grid.cell_centres(corner_row + (side - 1) / 2.0, corner_col + (side - 1) / 2.0)
    reach = (side - 1) / 2.0 * grid.resolution * math.sqrt(2.0) + 1e-9
    return cells, starts, np.ascontiguousarray(centres), reach


def build_expected_range_table(world: World, resolution: float = 0.02, angles: int = 360,
                               min_clearance: float = MIN_CLEARANCE_M,
                               segments: np.ndarray | None = None) -> ExpectedRangeTable:
    """Build the table (uncached); see expected_range_table() for the cached one.

    segments: the walls the rays hit (default the world's; a map world's likely walls, see
    amr_common.world.map_raster.likely_wall_segments); the grid stays the world's.
    """
    segments = world.segments if segments is None else np.ascontiguousarray(
        segments, dtype=np.float64)
    if not (isinstance(angles, int) and 8 <= angles <= 4096):
        raise ValueError(f"table angles must be an integer in [8, 4096], got {angles!r}")
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise ValueError(f"grid resolution must be > 0 m, got {resolution}")
    grid = OccupancyGrid.from_world(world, resolution)
    directions = np.arange(angles) * (2.0 * math.pi / angles)
    base_cos, base_sin = np.cos(directions), np.sin(directions)
    cells = np.flatnonzero(grid.clearance.ravel() >= min_clearance).astype(np.int64)
    rows = np.zeros(grid.clearance.size, dtype=np.int32)
    rows[cells] = np.arange(1, cells.size + 1, dtype=np.int32)
    ranges = np.zeros((cells.size + 1, angles), dtype=np.uint16)
    cells, starts, centres, reach = _blocks(grid, cells)
    fill = _fill_kernel if HAVE_NUMBA else _fill_numpy
    fill(segments, grid.origin[0], grid.origin[1], grid.resolution, grid.width, cells,
         starts, centres, reach, rows, base_cos, base_sin, ranges)
    return ExpectedRangeTable(grid, angles, rows, ranges)


def expected_range_table(world: World, resolution: float = 0.02, angles: int = 360,
                         segments: np.ndarray | None = None) -> ExpectedRangeTable:
    """The table for `world` (rays hitting `segments`, default its walls), cached.

    Built on first use and cached in this process, keyed by the world file, the walls, the
    resolution and the number of angles.
    """
    walls = world.segments if segments is None else np.ascontiguousarray(segments,
                                                                          dtype=np.float64)
    key = (world.source, walls.tobytes(), float(resolution), int(angles))
    with _CACHE_LOCK:
        table = _CACHE.get(key)
    if table is not None:
        return table
    table = build_expected_range_table(world, resolution, angles, segments=walls)
    with _CACHE_LOCK:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = table
    return table
