"""A log-odds occupancy grid that grows as the robot explores, up to a cap.

Cells lie on multiples of the resolution: global cell (i, j) covers x in [j, j + 1) * res and
y in [i, i + 1) * res, so grids of one resolution share their cells and a map's origin is a
multiple of the resolution. The array holds int32 log-odds in hundredths (0.9 -> 90): adding a
scan with +hit / -miss and removing it with -hit / +miss is exact, which lets a keyframe that
a loop closure moved be taken out at its old pose and drawn at its new one.

The array grows in blocks of GROWTH_CELLS when a scan reaches beyond it; a grid that would
exceed `max_cells` is not grown and the rays beyond are dropped (`add_scan` returns False; the
Mapper logs it). Nothing is clamped: counts of a static world only grow in magnitude (int32
holds 2e7 hits of 0.9).
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from amr_common.world.map_raster import FREE, OCCUPIED, UNKNOWN, Raster
from amr_mapping.grid_kernels import trace_rays

GROWTH_CELLS = 64  # cells added at a time on a side that needs them
UNITS = 100.0  # log-odds units per 1.0
_SERIALS = itertools.count()


class LogOddsGrid:
    """Int32 log-odds counts on global cells, grown on demand (see the module docstring)."""

    def __init__(self, resolution: float, max_cells: int, hit: float, miss: float,
                 miss_stop: float = 0.0, hit_moments: bool = False) -> None:
        self.resolution = float(resolution)
        self.max_cells = int(max_cells)
        self.hit_units = int(round(hit * UNITS))
        self.miss_units = -int(round(miss * UNITS))
        self.miss_stop_cells = float(miss_stop) / self.resolution
        self.counts = np.zeros((0, 0), dtype=np.int32)
        # Hits per cell, and with hit_moments the moments of their positions within the cell
        # (grid_kernels.trace_rays) for a matcher (empty otherwise).
        self.hit_moments = bool(hit_moments)
        self.hits = np.zeros((0, 0), dtype=np.int32)
        self.sums = np.zeros((5, 0, 0), dtype=np.float64)
        self.row0 = 0  # global index of counts[0, 0]
        self.col0 = 0
        self.version = 0  # changes with every change of the counts (caches compare it)
        self.serial = next(_SERIALS)  # tells grids apart (caches compare it)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the array."""
        return self.counts.shape

    def clear(self) -> None:
        """Every cell back to 0 (unknown); the array keeps its size."""
        self.counts[:, :] = 0
        self.hits[:, :] = 0
        self.sums[:, :, :] = 0
        self.version += 1

    def cell_bounds(self, xmin: float, ymin: float, xmax: float,
                    ymax: float) -> tuple[int, int, int, int]:
        """Global (row_lo, col_lo, row_hi, col_hi) of the cells a box touches (hi exclusive)."""
        res = self.resolution
        return (math.floor(ymin / res), math.floor(xmin / res), math.floor(ymax / res) + 1,
                math.floor(xmax / res) + 1)

    def ensure(self, xmin: float, ymin: float, xmax: float, ymax: float) -> bool:
        """Grow to hold the box; False (and no growth) if that would exceed max_cells."""
        row_lo, col_lo, row_hi, col_hi = self.cell_bounds(xmin, ymin, xmax, ymax)
        rows, cols = self.counts.shape
        if rows and cols and row_lo >= self.row0 and col_lo >= self.col0 and \
                row_hi <= self.row0 + rows and col_hi <= self.col0 + cols:
            return True
        if rows and cols:
            new_row0 = min(self.row0, row_lo - GROWTH_CELLS) if row_lo < self.row0 else self.row0
            new_col0 = min(self.col0, col_lo - GROWTH_CELLS) if col_lo < self.col0 else self.col0
            end_row = max(self.row0 + rows, row_hi + GROWTH_CELLS) \
                if row_hi > self.row0 + rows else self.row0 + rows
            end_col = max(self.col0 + cols, col_hi + GROWTH_CELLS) \
                if col_hi > self.col0 + cols else self.col0 + cols
        else:
            new_row0, new_col0 = row_lo - GROWTH_CELLS, col_lo - GROWTH_CELLS
            end_row, end_col = row_hi + GROWTH_CELLS, col_hi + GROWTH_CELLS
        new_rows, new_cols = end_row - new_row0, end_col - new_col0
        if new_rows * new_cols > self.max_cells:
            return False
        r, c = self.row0 - new_row0, self.col0 - new_col0
        self.counts = _grown(self.counts, (new_rows, new_cols), r, c)
        self.hits = _grown(self.hits, (new_rows, new_cols), r, c)
        if self.hit_moments:
            self.sums = _grown(self.sums, (5, new_rows, new_cols), r, c)
        self.row0, self.col0 = new_row0, new_col0
        return True

    def add_scan(self, sensor_xy: tuple[float, float], points: np.ndarray,
                 sign: int = 1) -> bool:
        """Trace rays from sensor_xy to each (K, 2) world point: sign +1 adds, -1 removes.

        Returns False if the grid could not grow to hold them all (those beyond are dropped).
        """
        if len(points) == 0:
            return True
        xs = np.append(points[:, 0], sensor_xy[0])
        ys = np.append(points[:, 1], sensor_xy[1])
        fits = self.ensure(float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max()))
        # In global cell units: the cells a ray crosses do not depend on where the array
        # starts, so a scan drawn before the grid grew is taken out exactly after.
        inv = 1.0 / self.resolution
        ends = np.ascontiguousarray(points, dtype=np.float64) * inv
        trace_rays(self.counts, self.row0, self.col0, sensor_xy[0] * inv, sensor_xy[1] * inv,
                   ends, sign * self.hit_units, sign * self.miss_units, self.miss_stop_cells,
                   sign, self.hits, self.sums)
        self.version += 1
        return fits

    def window(self, row_lo: int, col_lo: int, row_hi: int, col_hi: int,
               array: np.ndarray | None = None) -> np.ndarray:
        """Counts (or `array`: hits, sums) of global cells [row_lo, row_hi) x [col_lo, col_hi).

        Zeros outside the grid.
        """
        array = self.counts if array is None else array
        out = np.zeros(array.shape[:-2] + (max(row_hi - row_lo, 0), max(col_hi - col_lo, 0)),
                       dtype=array.dtype)
        rows, cols = self.counts.shape
        r0, r1 = max(row_lo, self.row0), min(row_hi, self.row0 + rows)
        c0, c1 = max(col_lo, self.col0), min(col_hi, self.col0 + cols)
        if r0 < r1 and c0 < c1 and array.size:
            out[..., r0 - row_lo:r1 - row_lo, c0 - col_lo:c1 - col_lo] = \
                array[..., r0 - self.row0:r1 - self.row0, c0 - self.col0:c1 - self.col0]
        return out

    def raster(self, occupied_log_odds: float, free_log_odds: float,
               min_hit_share: float = 0.0, peak_cells: int = 1, min_hits: int = 1) -> Raster:
        """The map as a Raster (FREE / OCCUPIED / UNKNOWN), cropped to the observed cells + 1.

        OCCUPIED: log-odds above occupied_log_odds and at least min_hit_share of the hits of
        the most-hit cell within peak_cells cells of it (range noise puts a few hits in the
        cells beside a wall, behind it too, where no ray ever clears them: this keeps them out);
        FREE: log-odds below free_log_odds; else UNKNOWN.
        """
        counts = self.counts
        seen_rows = np.flatnonzero(counts.any(axis=1))
        seen_cols = np.flatnonzero(counts.any(axis=0))
        if seen_rows.size == 0:
            return Raster(np.full((1, 1), UNKNOWN, dtype=np.int8), self.resolution,
                          (self.col0 * self.resolution, self.row0 * self.resolution))
        r0, r1 = max(seen_rows[0] - 1, 0), min(seen_rows[-1] + 2, counts.shape[0])
        c0, c1 = max(seen_cols[0] - 1, 0), min(seen_cols[-1] + 2, counts.shape[1])
        block = counts[r0:r1, c0:c1]
        values = np.full(block.shape, UNKNOWN, dtype=np.int8)
        hits = self.hits[r0:r1, c0:c1]
        most = _square_maximum(hits, peak_cells)
        values[(block > occupied_log_odds * UNITS) & (hits >= min_hit_share * most)
               & (hits >= min_hits)] = OCCUPIED
        values[block < free_log_odds * UNITS] = FREE
        res = self.resolution
        return Raster(values, res, ((self.col0 + c0) * res, (self.row0 + r0) * res))


def _square_maximum(array: np.ndarray, radius: int) -> np.ndarray:
    """Each cell's maximum over the (2 radius + 1)^2 square around it (rows, then columns)."""
    rows, cols = array.shape
    most = array.copy()
    padded = np.pad(array, ((radius, radius), (0, 0)))
    for dr in range(2 * radius + 1):
        np.maximum(most, padded[dr:dr + rows], out=most)
    padded = np.pad(most, ((0, 0), (radius, radius)))
    for dc in range(2 * radius + 1):
        np.maximum(most, padded[:, dc:dc + cols], out=most)
    return most


def _grown(array: np.ndarray, shape: tuple[int, ...], row: int, col: int) -> np.ndarray:
    """A zero array of `shape` with `array` copied in at (row, col) of its last two axes."""
    grown = np.zeros(shape, dtype=array.dtype)
    if array.size:
        rows, cols = array.shape[-2:]
        grown[..., row:row + rows, col:col + cols] = array
    return grown


__all__ = ["LogOddsGrid", "GROWTH_CELLS", "UNITS"]
