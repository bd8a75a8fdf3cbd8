"""Building the expected-range table: exact ranges on any map, in slices that Ctrl-C can stop.

Every cell of the table gets the range along each of its directions to the nearest wall, as
the simulator's segment kernel computes it (amr_common.world.raycast.scan_python: the same
arithmetic, so the same ranges to the bit), without testing every ray against every wall:
- cells are taken in square blocks, directions in sectors of a few degrees; a block's rays of
  one sector are cast together (vectorised over the rays) against the walls they can reach;
- those walls come in rings around the block (walls within R1 of its centre, then 3 R1, 9 R1,
  ..., then all): a ray that hits a wall within the ring's radius minus the block's reach is
  done (any wall of a later ring is farther); only the others go on to the next ring;
- of each ring, a sector's rays are tested only against the walls in the wedge they sweep
  (the wall's bounding circle within the block's reach of it);
- a few rays left for a ring of many walls (a dense map's ray through a gap) are cast one by
  one through the walls' buckets instead (amr_common.world.raster_raycast.SegmentGrid); on a dense
  map, where every ray is short, every ray is (`march`: the sample times both ways).
R1 and the block size follow the walls' density: ~50 walls within R1, at most 1.5 m. A SLAM
map's specks are walls of zero length inside its occupied cells (map_raster.
likely_wall_segments): no ray ever hits them, so they are left out.
The kernels: table_kernels. Measured (scripts/bench_map_world.py --big-maps): a 20 x 20 m map at
2 cm with 1 % specks ~11 s of CPU (~28 min before), with 50 % specks ~17 s (~14 min before).

TableBuild does it in slices of blocks on up to MAX_THREADS threads (the kernels release the
GIL), and checks between slices (every ~0.1 s) whether to stop: a Ctrl-C or SIGTERM that a
script's StopFlag caught (amr_common.stop_flag.stop_requested) ends it with
TableBuildInterrupted; without a StopFlag, Ctrl-C raises KeyboardInterrupt between slices. It
first builds a random sample of the blocks (~SAMPLE_S of CPU) and estimates the whole build
from it (`estimate_s`), so a map whose table would take too long is refused before the rest
is built. No rclpy import.
"""
from __future__ import annotations

import concurrent.futures
import math
import os
import threading
import time
from typing import Callable

import numpy as np

from amr_common.jit import HAVE_NUMBA
from amr_common.stop_flag import stop_requested
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.raster_raycast import SegmentGrid
from amr_localization.table_kernels import fill_blocks, fill_blocks_numpy, scratch_arrays

MAX_THREADS = 4
SAMPLE_S = 0.3  # s of CPU spent on the sample that estimates the whole build
SLICE_S = 0.1  # s per slice: how soon a stop is seen
_NEAR_WALLS = 50.0  # walls within the first ring's radius R1 (on average) ...
_NEAR_M = 1.5  # ... which is at most this, and at least three cells
_RING_GROWTH = 3.0  # each ring's radius is this times the last one's
_SECTOR_DEG = 4.0  # directions cast together (at least _SECTOR_RAYS rays of a block)
_SECTOR_RAYS = 64


class TableBuildInterrupted(RuntimeError):
    """A stop was requested (Ctrl-C, SIGTERM) while the table was being built."""


_STOPPED = "building the expected-range table was stopped (Ctrl-C or SIGTERM)"


class TableBuild:
    """The expected ranges of `cells` of `grid` along `angles` directions, built in slices.

    `ranges` (1 + cells, angles) uint16 mm, row 0 all zeros, row rows[cell] for each cell, is
    filled by sample() (a random share of the blocks; sets `estimate_s`) and finish().
    """

    def __init__(self, grid: OccupancyGrid, walls: np.ndarray, angles: int,
                 cells: np.ndarray) -> None:
        walls = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
        lengths = np.hypot(walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1])
        walls = np.ascontiguousarray(walls[lengths > 0.0])  # zero length: never hit
        if len(walls) == 0:  # no wall: every ray reads "no return" (this one is never hit)
            walls = np.zeros((1, 4))
        self.grid, self.angles, self.walls_count = grid, angles, len(walls)
        self.rows = np.zeros(grid.width * grid.height, dtype=np.int32)
        self.rows[cells] = np.arange(1, cells.size + 1, dtype=np.int32)
        self.ranges = np.zeros((cells.size + 1, angles), dtype=np.uint16)
        (xmin, ymin), (xmax, ymax) = walls.reshape(-1, 2).min(axis=0), \
            walls.reshape(-1, 2).max(axis=0)
        area = max((xmax - xmin) * (ymax - ymin), grid.resolution ** 2)
        near = min(max(math.sqrt(_NEAR_WALLS * area / (math.pi * len(walls))),
                       3.0 * grid.resolution), _NEAR_M)
        side = max(1, int(round(0.5 * near / grid.resolution)))
        rings = [near]
        while rings[-1] < math.hypot(xmax - xmin, ymax - ymin):
            rings.append(rings[-1] * _RING_GROWTH)
        rings[-1] = np.inf  # the last ring: every wall
        # Buckets of ~2 walls (at least a cell): casting a ray through them costs ~10 tests.
        buckets = SegmentGrid.build(walls, max(grid.resolution, math.sqrt(
            2.0 * area / len(walls))))
        counts = np.diff(buckets.starts).reshape(buckets.ny, buckets.nx)
        sat = np.zeros((buckets.ny + 1, buckets.nx + 1), dtype=np.int64)
        sat[1:, 1:] = counts.cumsum(axis=0).cumsum(axis=1)
        cells, self.block_starts = _blocks(grid, cells, side)
        sector = max(1, int(round(_SECTOR_DEG / 360.0 * angles)),
                     -(-_SECTOR_RAYS // min(side * side, max(cells.size, 1))))
        self.sector = min(sector, angles)
        directions = np.arange(angles) * (2.0 * math.pi / angles)
        reach = (side - 1) / 2.0 * grid.resolution * math.sqrt(2.0) + 1e-9
        self._arguments = (
            walls, np.ascontiguousarray(0.5 * (walls[:, :2] + walls[:, 2:])),
            0.5 * np.hypot(walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1]),
            *buckets.arrays[1:], sat, cells, self.block_starts, grid.origin[0], grid.origin[1],
            grid.resolution, grid.width, reach, np.array(rings), self.sector,
            directions, np.cos(directions), np.sin(directions))
        self._scratch = threading.local()
        self._todo = np.random.default_rng(0).permutation(len(self.block_starts) - 1)
        self._done = 0  # blocks of _todo built
        self._seconds = 0.0  # CPU time spent on them
        self._cells_done = 0
        self.march = False  # cast every ray through the buckets (sample() decides)
        self.estimate_s: float | None = None

    @property
    def done(self) -> bool:
        """Every block built."""
        return self._done == len(self._todo)

    @property
    def cells(self) -> int:
        """Cells that get a row."""
        return int(self.ranges.shape[0] - 1)

    @property
    def threads(self) -> int:
        """Threads the build uses: the cores this process may run on, at most MAX_THREADS."""
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else \
            (os.cpu_count() or 1)
        return max(1, min(MAX_THREADS, cores))

    def _run(self, blocks: np.ndarray, march: bool | None = None,
             rows: np.ndarray | None = None, out: np.ndarray | None = None) -> None:
        """Build `blocks` into the table (or into `out` at `rows`), the chosen way or `march`."""
        own = self._scratch.__dict__  # this thread's scratch arrays and next stamp id
        if "arrays" not in own:
            own["arrays"], own["stamp"] = scratch_arrays(
                self.walls_count, int(np.max(np.diff(self.block_starts), initial=1)),
                self.sector), 1
        own["stamp"] = (fill_blocks if HAVE_NUMBA else fill_blocks_numpy)(
            *self._arguments, self.rows if rows is None else rows,
            self.march if march is None else march, blocks, *own["arrays"], own["stamp"],
            self.ranges if out is None else out)

    def _cells_in(self, blocks: np.ndarray) -> np.ndarray:
        cells = self._arguments[11]
        return np.concatenate([cells[self.block_starts[b]:self.block_starts[b + 1]]
                               for b in blocks]) if len(blocks) else np.zeros(0, np.int64)

    def sample(self) -> float:
        """Build random blocks for ~SAMPLE_S of CPU; the estimated seconds of the whole build.

        Each block of the sample is cast both ways (rings, or every ray through the buckets:
        `march`) and the faster is kept for the rest. The estimate assumes the rest runs at
        the sample's pace on `threads` cores. The sample is cast into arrays of its own, then
        copied: the pace of the casting alone (the table's memory is given to the process page
        by page as it is first written, slowly at first on some machines).
        """
        for march in (False, True):  # loads (or compiles) the kernels: not the build's pace
            self._run(self._todo[:0], march)
        rows = np.zeros_like(self.rows)
        seconds = {False: 0.0, True: 0.0}
        batch = 1
        while self._done < len(self._todo) and sum(seconds.values()) < SAMPLE_S:
            blocks = self._todo[self._done:self._done + batch]
            cells = self._cells_in(blocks)
            rows[cells] = np.arange(1, cells.size + 1)
            out = np.zeros((cells.size + 1, self.angles), dtype=np.uint16)
            for march in (False, True):
                began = time.thread_time()
                self._run(blocks, march, rows, out)
                seconds[march] += time.thread_time() - began
            self.ranges[self.rows[cells]] = out[1:]
            rows[cells] = 0
            self._done += len(blocks)
            self._cells_done += cells.size
            batch *= 2
        self.march = seconds[True] < seconds[False]
        self._seconds = seconds[self.march]
        per_cell = self._seconds / max(self._cells_done, 1)
        self.estimate_s = self._seconds + per_cell * (self.cells - self._cells_done) \
            / self.threads
        return self.estimate_s

    def finish(self, stop: Callable[[], bool] = stop_requested) -> np.ndarray:
        """Build the remaining blocks in slices on `threads` threads; returns `ranges`.

        TableBuildInterrupted as soon as `stop()` is true (checked at least every ~0.1 s).
        """
        if stop():  # stopped while the build was being prepared
            raise TableBuildInterrupted(_STOPPED)
        if self.estimate_s is None:
            self.sample()
        todo = self._todo[self._done:]
        per_cell = self._seconds / max(self._cells_done, 1)
        # Slices of about SLICE_S of CPU each, at the sample's pace.
        cost = np.cumsum(self.block_starts[todo + 1] - self.block_starts[todo]) * per_cell
        slices = np.split(todo, np.flatnonzero(np.diff(cost // SLICE_S)) + 1) if len(todo) \
            else []
        with concurrent.futures.ThreadPoolExecutor(self.threads) as pool:
            running: set = set()
            try:
                for blocks in slices:
                    while len(running) >= 2 * self.threads:
                        running = self._wait(running, stop)
                    running.add(pool.submit(self._run, blocks))
                while running:
                    running = self._wait(running, stop)
            finally:  # stopped (or Ctrl-C): the slices not started are dropped
                for future in running:
                    future.cancel()
        self._done = len(self._todo)
        return self.ranges

    @staticmethod
    def _wait(running: set, stop: Callable[[], bool]) -> set:
        done, running = concurrent.futures.wait(running, timeout=SLICE_S,
                                                return_when=concurrent.futures.FIRST_COMPLETED)
        for future in done:
            future.result()  # a kernel's error surfaces here
        if stop():
            raise TableBuildInterrupted(_STOPPED)
        return running


def _blocks(grid: OccupancyGrid, cells: np.ndarray, side: int) -> tuple[np.ndarray, np.ndarray]:
    """The cells grouped by square blocks of `side` cells: (cells, block starts)."""
    row, col = np.divmod(cells, grid.width)
    block = (row // side) * (grid.width // side + 1) + col // side
    order = np.argsort(block, kind="stable")
    cells, block = cells[order], block[order]
    starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1], True]).astype(np.int64)
    return np.ascontiguousarray(cells), starts
