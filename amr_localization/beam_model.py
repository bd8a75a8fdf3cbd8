"""The measurement model: a beam model reading the precomputed expected-range table.

For each particle and each weighed beam, the expected range is one table lookup (the LiDAR's
cell, the beam's world direction) and the beam's log-likelihood one lookup in a table of
log((1 - z_random) * exp(-d^2 / (2 sigma^2)) + z_random) over the integer difference d in mm, so a
beam costs a handful of integer operations. A perfect beam scores 0, a missed one log(z_random).
A beam whose sigma is wider than sigma_hit (range_sensor: a real LiDAR's error grows with the
range) reads the same table at d times sigma_hit / its sigma (a fixed-point scale per beam: 1
for every beam of the exact model, whose numbers stay what they were).
Readings without a return (NaN, 0.0, inf or outside [range_min, range_max]) score 0 where the
table also expects no return inside the sensor's limits, and log(z_random) otherwise.
A particle whose centre is not where the robot can be (outside the free space, or closer than
the robot radius to a wall, minus a slack for the grid) scores -inf: it gets no weight.
Sub-cell correction (tables with cells coarser than 2 cm: big maps, see table_memory): the
table holds the ranges from the centre of the LiDAR's cell; the LiDAR is up to half a cell away
from it, and along a beam that offset changes the range one for one, so the expected range is
the table's minus the offset's component along the beam (exact for a wall square to the beam;
the sideways part is left). It keeps 4 cm cells as accurate in the course's mazes as 2 cm cells
without it (and would nearly halve the tracking error with 2 cm cells, at ~35 % of the
measurement update's speed: off there).

Made fast (scripts/bench_localization.py) by:
- integers: log-likelihoods summed as int64 micro-nats (a float sum is one long chain of
  dependent additions), beam directions as whole table bins plus a fraction (0 for the LDS-01's
  and the course's scans, whose beams fall on whole degrees), no division;
- the LiDAR's offset from the robot centre read per heading bin (the heading rounded to the
  table's 1 degree moves the LiDAR by at most 0.3 mm), not a cosine and a sine per particle;
- prefetching: with particles spread over the map (a global search) each particle reads its own
  720-byte table row, a cache miss that stalls the loop; the kernel first finds every
  particle's row, then asks for the row two particles ahead while it weighs the current one.

`log_likelihoods_kernel` is compiled with numba; `log_likelihoods_numpy` is the same model as
numpy array operations (the benchmarks' reference and the fallback without numba), with the same
integer sums, so both give the same numbers. No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import HAVE_NUMBA, jit, prefetch
from amr_localization.expected_ranges import ExpectedRangeTable

MAX_DIFFERENCE_MM = 1000  # differences beyond 1 m all score log(z_random)
UNITS_PER_NAT = 1_000_000  # log-likelihoods are summed as integer micro-nats
_AHEAD = 2  # particles ahead whose table row is prefetched
_LINE = 32  # uint16 ranges per 64-byte cache line
SUB_CELL_FROM_M = 0.025  # tables with coarser cells get the sub-cell correction
_SHIFT = 16  # a beam's difference times its sigma scale (range_sensor.SCALE_ONE = 1 << 16)


def log_likelihood_table(sigma_m: float, z_random: float) -> np.ndarray:
    """Per-beam log-likelihood (int64 micro-nats) for a difference of 0 .. MAX_DIFFERENCE_MM mm."""
    d = np.arange(MAX_DIFFERENCE_MM + 1) * 1e-3
    nats = np.log((1.0 - z_random) * np.exp(-0.5 * (d / sigma_m) ** 2) + z_random)
    return np.round(nats * UNITS_PER_NAT).astype(np.int64)


def lidar_offsets(offset_m: float, angles: int, resolution: float) -> tuple[np.ndarray, ...]:
    """(dx, dy): the LiDAR's offset from the robot centre in cells, per heading bin."""
    headings = np.arange(angles) * (2.0 * math.pi / angles)
    return (offset_m * np.cos(headings) / resolution, offset_m * np.sin(headings) / resolution)


def log_likelihoods_python(particles, count, table, rows, angles, x0, y0, resolution, nx, ny,
                           robot_ok, lidar_dx, lidar_dy, bin_cos, bin_sin, beams, lut,
                           range_min_mm, range_max_mm, starts, headings, phases, offsets, out):
    """out[p] = sum over beams of the log-likelihood (nats) of particle p < count, or -inf.

    table: the expected ranges flattened (row-major: row * angles + direction), rows: each grid
    cell's row; bin_cos, bin_sin: the table's directions for the sub-cell correction, or empty
    arrays for none (a separate loop: the correction costs ~35 % here); beams: a
    scan_beams.BeamReadings; starts, headings (int64), phases (float64) and offsets ((N, 2)
    float64): scratch of at least `count` entries (each particle's table row start, heading
    bin and its fraction, the LiDAR's offset from its cell's centre in mm).

    Long: the measurement update's hot loop, one compiled kernel: its second pass prefetches
    the table rows its first pass found, two particles ahead (module docstring); and this body is
    the plain-Python twin of that kernel (tested equal), so helpers would need twins of their own.
    """
    inv_res = 1.0 / resolution
    bins_per_rad = angles / (2.0 * math.pi)
    inv_angles = 1.0 / angles
    for p in range(count):
        fi = (particles[p, 0] - x0) * inv_res
        fj = (particles[p, 1] - y0) * inv_res
        starts[p] = -1
        if not (fi >= 0.0 and fj >= 0.0 and fi < nx and fj < ny):  # NaN fails too
            continue
        if robot_ok[int(fj) * nx + int(fi)] == 0:
            continue
        t = particles[p, 2] * bins_per_rad
        t = t - math.floor(t * inv_angles) * angles + 0.5  # + 0.5: truncation rounds to nearest
        k = int(t)
        phases[p] = t - k
        k = k - angles if k >= angles else k
        headings[p] = k
        # The LiDAR is within |offset| of a valid centre: on the grid.
        li = fi + lidar_dx[k]
        lj = fj + lidar_dy[k]
        starts[p] = rows[int(lj) * nx + int(li)] * angles
        offsets[p, 0] = (li - int(li) - 0.5) * resolution * 1000.0
        offsets[p, 1] = (lj - int(lj) - 0.5) * resolution * 1000.0
    valid_whole, valid_fraction, valid_mm, invalid_whole, invalid_fraction, valid_scale = beams
    last = lut.shape[0] - 1
    miss = lut[last]
    for p in range(count):
        if p + _AHEAD < count and starts[p + _AHEAD] >= 0:
            for offset in range(0, angles, _LINE):
                prefetch(table, starts[p + _AHEAD] + offset)
        start = starts[p]
        if start < 0:
            out[p] = -np.inf
            continue
        k0 = headings[p]
        carry = 1.0 - phases[p]  # a beam's fraction at least this far rounds up one bin
        total = 0
        if bin_cos.shape[0] == 0:
            for b in range(valid_whole.shape[0]):
                k = k0 + valid_whole[b] + (1 if valid_fraction[b] >= carry else 0)
                k = k - angles if k >= angles else k
                d = (abs(valid_mm[b] - np.int32(table[start + k])) * valid_scale[b]) >> _SHIFT
                total += lut[d if d < last else last]
            for b in range(invalid_whole.shape[0]):
                k = k0 + invalid_whole[b] + (1 if invalid_fraction[b] >= carry else 0)
                k = k - angles if k >= angles else k
                r = np.int32(table[start + k])
                total += miss if (r >= range_min_mm) & (r <= range_max_mm) else 0
        else:
            ox = offsets[p, 0]
            oy = offsets[p, 1]
            for b in range(valid_whole.shape[0]):
                k = k0 + valid_whole[b] + (1 if valid_fraction[b] >= carry else 0)
                k = k - angles if k >= angles else k
                r = np.int32(table[start + k]) - np.int32(round(ox * bin_cos[k]
                                                                + oy * bin_sin[k]))
                d = (abs(valid_mm[b] - r) * valid_scale[b]) >> _SHIFT
                total += lut[d if d < last else last]
            for b in range(invalid_whole.shape[0]):
                k = k0 + invalid_whole[b] + (1 if invalid_fraction[b] >= carry else 0)
                k = k - angles if k >= angles else k
                r = np.int32(table[start + k]) - np.int32(round(ox * bin_cos[k]
                                                                + oy * bin_sin[k]))
                total += miss if (r >= range_min_mm) & (r <= range_max_mm) else 0
        out[p] = total / UNITS_PER_NAT


log_likelihoods_kernel = jit(log_likelihoods_python)


def log_likelihoods_numpy(particles, count, table, rows, angles, x0, y0, resolution, nx, ny,
                          robot_ok, lidar_dx, lidar_dy, bin_cos, bin_sin, beams, lut,
                          range_min_mm, range_max_mm, starts, headings, phases, offsets, out):
    """The same model with numpy array operations over particles x beams (scratch unused)."""
    pts = particles[:count]
    inv_res = 1.0 / resolution
    with np.errstate(invalid="ignore"):
        fi = (pts[:, 0] - x0) * inv_res
        fj = (pts[:, 1] - y0) * inv_res
        on_grid = (fi >= 0) & (fj >= 0) & (fi < nx) & (fj < ny)
    fi, fj = np.where(on_grid, fi, 0.0), np.where(on_grid, fj, 0.0)
    ok = on_grid & (robot_ok[fj.astype(np.int64) * nx + fi.astype(np.int64)] != 0)
    t = np.where(ok, pts[:, 2], 0.0) * (angles / (2.0 * math.pi))
    t = t - np.floor(t * (1.0 / angles)) * angles + 0.5
    k0 = t.astype(np.int64)
    carry = (1.0 - (t - k0))[:, None]
    k0 = np.where(k0 >= angles, k0 - angles, k0)
    li, lj = fi + lidar_dx[k0], fj + lidar_dy[k0]
    cell = lj.astype(np.int64) * nx + li.astype(np.int64)
    start = (rows[np.where(ok, cell, 0)].astype(np.int64) * angles)[:, None]
    ox = ((li - li.astype(np.int64) - 0.5) * resolution * 1000.0)[:, None]
    oy = ((lj - lj.astype(np.int64) - 0.5) * resolution * 1000.0)[:, None]

    def expected(whole, fraction):
        k = (k0[:, None] + whole[None, :] + (fraction[None, :] >= carry)) % angles
        r = table[np.where(ok[:, None], start + k, 0)].astype(np.int32)
        if bin_cos.size == 0:
            return r
        return r - np.round(ox * bin_cos[k] + oy * bin_sin[k]).astype(np.int32)

    valid_whole, valid_fraction, valid_mm, invalid_whole, invalid_fraction, valid_scale = beams
    d = (np.abs(valid_mm[None, :] - expected(valid_whole, valid_fraction)).astype(np.int64)
         * valid_scale[None, :]) >> _SHIFT
    total = lut[np.minimum(d, lut.shape[0] - 1)].sum(axis=1)
    if invalid_whole.size:
        r = expected(invalid_whole, invalid_fraction)
        total = total + np.where((r >= range_min_mm) & (r <= range_max_mm), lut[-1],
                                 0).sum(axis=1)
    out[:count] = np.where(ok, total / UNITS_PER_NAT, -np.inf)


log_likelihoods = log_likelihoods_kernel if HAVE_NUMBA else log_likelihoods_numpy


class BeamModel:
    """The beam model of one filter: table, where the robot may be, LiDAR position, noise.

    The sub-cell correction is on for tables coarser than SUB_CELL_FROM_M (big maps): with 2 cm
    cells the filter is as accurate as before without it, and faster.
    """

    def __init__(self, table: ExpectedRangeTable, robot_ok: np.ndarray, lidar_offset_m: float,
                 sigma_hit_m: float, z_random: float,
                 sub_cell: bool | None = None) -> None:
        self.table = table
        self.robot_ok = np.ascontiguousarray(robot_ok, dtype=np.uint8)
        self.lidar_dx, self.lidar_dy = lidar_offsets(lidar_offset_m, table.angles,
                                                     table.resolution)
        self.lut = log_likelihood_table(sigma_hit_m, z_random)
        self._flat = table.ranges.reshape(-1)
        self.sub_cell = table.resolution > SUB_CELL_FROM_M if sub_cell is None else sub_cell
        directions = np.arange(table.angles if self.sub_cell else 0) * (2.0 * math.pi
                                                                        / table.angles)
        self.bin_cos, self.bin_sin = np.cos(directions), np.sin(directions)
        self._starts = self._headings = np.zeros(0, dtype=np.int64)
        self._phases = np.zeros(0)
        self._offsets = np.zeros((0, 2))

    def scores(self, particles: np.ndarray, readings, limits_mm: tuple[int, int],
               kernel=None) -> np.ndarray:
        """Log-likelihood (nats) of each particle for one scan's readings; -inf in walls.

        readings: scan_beams.BeamReadings; limits_mm: the valid range limits in mm; kernel:
        one of the implementations above (default: the compiled one when numba is there).
        """
        count = len(particles)
        if self._starts.size < count:
            self._starts = np.empty(count, dtype=np.int64)
            self._headings = np.empty(count, dtype=np.int64)
            self._phases = np.empty(count)
            self._offsets = np.empty((count, 2))
        out = np.empty(count)
        t = self.table
        (kernel or log_likelihoods)(
            particles, count, self._flat, t.rows, t.angles, t.x0, t.y0, t.resolution, t.nx,
            t.ny, self.robot_ok, self.lidar_dx, self.lidar_dy, self.bin_cos, self.bin_sin,
            readings, self.lut, limits_mm[0], limits_mm[1], self._starts, self._headings,
            self._phases, self._offsets, out)
        return out
