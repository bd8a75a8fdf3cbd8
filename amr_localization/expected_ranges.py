"""The expected-range table of the beam model, on the world's occupancy grid.

For every cell of amr_common.occupancy_grid.OccupancyGrid (the grid the planner and /map use:
cell centres on multiples of the resolution, so a 0.4 m corridor's centre line runs through cell
centres) and every one of `angles` directions, the range (mm, uint16) a LiDAR at the cell centre
would measure.

Built once per world with the simulator's own ray-casting kernel (amr_common.raycast), so the
filter's idea of a range is exactly the simulated LiDAR's. Cells where the LiDAR cannot be (outside
the free space, or closer than `min_clearance` to a wall) hold 0, which matches no reading.
Why a table and not a likelihood field: in 0.4 m corridors on a 0.4 m grid, rotated or shifted
poses put every beam endpoint near SOME wall, so a likelihood field scores them almost as well as
the true pose; the expected range along each beam tells them apart (localization-planning.md).
Size: 2 cm cells x 360 angles over a 2.4 m maze ~ 11 MB; built in well under a second with numba.
Tables are cached per (world file, resolution, angles) for the life of the process, so batch
evaluations build each one once.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

from amr_common.jit import HAVE_NUMBA, jit
from amr_common.occupancy_grid import OccupancyGrid
from amr_common.raycast import scan_kernel, scan_numpy
from amr_common.robot import ROBOT_RADIUS
from amr_common.world import World

NO_RANGE_MM = 65535  # a ray that hits nothing (or beyond 65.5 m)
_CACHE: dict[tuple, "ExpectedRangeTable"] = {}
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 8


@dataclass(frozen=True)
class ExpectedRangeTable:
    """Expected ranges (mm) per grid cell and world direction.

    ranges[cell, k]: expected range in mm from the centre of grid cell `cell` (row-major,
    row * width + col, as the grid's arrays) along the world direction k * 2 pi / angles (k = 0
    is +x).
    """

    grid: OccupancyGrid
    angles: int
    ranges: np.ndarray  # (cells, angles) uint16, mm

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
    def nbytes(self) -> int:
        """Memory of the table (bytes)."""
        return int(self.ranges.nbytes)

    def cell_index(self, x: float, y: float) -> int:
        """Row-major index of the cell holding (x, y), or -1 off the grid (or not finite)."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return -1
        row, col = self.grid.cell_of(x, y)
        return row * self.nx + col if self.grid.contains_cell(row, col) else -1

    def cell_centres(self) -> np.ndarray:
        """(cells, 2) cell centres in row-major order."""
        rows, cols = np.divmod(np.arange(self.ranges.shape[0]), self.nx)
        return self.grid.cell_centres(rows, cols)

    def robot_cells(self, radius: float = ROBOT_RADIUS, slack: float = 0.0) -> np.ndarray:
        """(cells,) uint8: 1 where a robot centre may be (clearance >= radius - slack > 0)."""
        return (self.grid.clearance.ravel() >= max(radius - slack, 1e-9)).astype(np.uint8)



def _fill_python(segments, centres, cells, base_cos, base_sin, out):
    """Ranges (mm) of every listed cell into out[cell, :], with the shared scan kernel."""
    n = base_cos.shape[0]
    ranges = np.empty(n)
    noise = np.zeros(n)
    for c in range(cells.shape[0]):
        cell = cells[c]
        scan_kernel(segments, centres[cell, 0], centres[cell, 1], 0.0, base_cos, base_sin,
                    0.0, np.inf, np.inf, noise, ranges)
        for k in range(n):
            mm = ranges[k] * 1000.0
            out[cell, k] = NO_RANGE_MM if not (mm < NO_RANGE_MM) else np.uint16(round(mm))


_fill_kernel = jit(_fill_python)


def _fill_numpy(segments, centres, cells, base_cos, base_sin, out):
    ranges = np.empty(base_cos.shape[0])
    zeros = np.zeros_like(ranges)
    for cell in cells:
        scan_numpy(segments, centres[cell, 0], centres[cell, 1], 0.0, base_cos, base_sin,
                   0.0, np.inf, np.inf, zeros, ranges)
        mm = np.where(ranges * 1000.0 < NO_RANGE_MM, np.round(ranges * 1000.0), NO_RANGE_MM)
        out[cell] = mm.astype(np.uint16)


def build_expected_range_table(world: World, resolution: float = 0.02, angles: int = 360,
                               min_clearance: float = 0.01) -> ExpectedRangeTable:
    """Build the table (uncached); see expected_range_table() for the cached one."""
    if not (isinstance(angles, int) and 8 <= angles <= 4096):
        raise ValueError(f"table angles must be an integer in [8, 4096], got {angles!r}")
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise ValueError(f"grid resolution must be > 0 m, got {resolution}")
    grid = OccupancyGrid.from_world(world, resolution)
    directions = np.arange(angles) * (2.0 * math.pi / angles)
    base_cos, base_sin = np.cos(directions), np.sin(directions)
    cells = np.flatnonzero(grid.clearance.ravel() >= min_clearance).astype(np.int64)
    ranges = np.zeros((grid.clearance.size, angles), dtype=np.uint16)
    table = ExpectedRangeTable(grid, angles, ranges)
    fill = _fill_kernel if HAVE_NUMBA else _fill_numpy
    fill(world.segments, table.cell_centres(), cells, base_cos, base_sin, ranges)
    return table


def expected_range_table(world: World, resolution: float = 0.02,
                         angles: int = 360) -> ExpectedRangeTable:
    """The table for `world`, built on first use and cached in this process.

    Keyed by the world file, its walls, the resolution and the number of angles.
    """
    key = (world.source, world.segments.tobytes(), float(resolution), int(angles))
    with _CACHE_LOCK:
        table = _CACHE.get(key)
    if table is not None:
        return table
    table = build_expected_range_table(world, resolution, angles)
    with _CACHE_LOCK:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = table
    return table
