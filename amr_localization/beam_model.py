"""The measurement model: a beam model reading the precomputed expected-range table.

For each particle and each used beam, the expected range is one table lookup (the LiDAR's cell,
the beam's world direction) and the beam's log-likelihood one lookup in a table of
log((1 - z_random) * exp(-d^2 / (2 sigma^2)) + z_random) over the integer difference d in mm, so a
beam costs a handful of integer operations. A perfect beam scores 0, a missed one log(z_random).
Readings without a return (NaN, 0.0, inf or outside [range_min, range_max]) score 0 where the
table also expects no return inside the sensor's limits, and log(z_random) otherwise.
A particle whose centre is not where the robot can be (outside the free space, or closer than
the robot radius to a wall, minus a slack for the grid) scores -inf: it gets no weight.

`log_likelihoods` is compiled with numba; `log_likelihoods_numpy` is the same model as numpy
array operations (the benchmarks' reference and the fallback without numba). No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import HAVE_NUMBA, jit

MAX_DIFFERENCE_MM = 1000  # differences beyond 1 m all score log(z_random)


def log_likelihood_table(sigma_m: float, z_random: float) -> np.ndarray:
    """Per-beam log-likelihood for a range difference of 0 .. MAX_DIFFERENCE_MM mm."""
    d = np.arange(MAX_DIFFERENCE_MM + 1) * 1e-3
    return np.log((1.0 - z_random) * np.exp(-0.5 * (d / sigma_m) ** 2) + z_random)


def _reading_to_mm(ranges, range_min, range_max, out):
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if r >= range_min and r <= range_max and r > 0.0 and r < 2.0e6:  # NaN, inf fail
            out[i] = np.int32(round(r * 1000.0))
        else:
            out[i] = -1


_reading_to_mm_kernel = jit(_reading_to_mm)


def reading_to_mm(ranges: np.ndarray, range_min: float, range_max: float) -> np.ndarray:
    """Ranges (m) as int32 mm, -1 for readings without a return.

    Ranges (m) as int32 mm, with -1 for readings without a return (NaN, inf, 0.0, outside
    [range_min, range_max]): the measured side of the model.
    """
    r = np.ascontiguousarray(ranges, dtype=np.float64)
    out = np.empty(r.shape, dtype=np.int32)
    _reading_to_mm_kernel(r, float(range_min), float(range_max), out)
    return out


def split_beams(beam_bins: np.ndarray, z_mm: np.ndarray):
    """Split the beams into those with a reading and those without one.

    (valid_bins, valid_z_mm, invalid_bins): the kernels loop over beams with a reading and
    beams without one separately (no branch in the inner loop).
    """
    valid = z_mm >= 0
    return (np.ascontiguousarray(beam_bins[valid]), np.ascontiguousarray(z_mm[valid]),
            np.ascontiguousarray(beam_bins[~valid]))


def log_likelihoods_python(particles, count, table, angles, x0, y0, resolution, nx, ny,
                           robot_ok, lidar_offset, valid_bins, valid_z, invalid_bins, lut,
                           range_min_mm, range_max_mm, out):
    """out[p] = sum over beams of the log-likelihood of particle p (p < count), or -inf.

    valid_bins / valid_z: table-angle offsets (from the heading) and readings (mm) of the beams
    with a return; invalid_bins: offsets of the beams without one (see split_beams).
    """
    inv_res = 1.0 / resolution
    bins_per_rad = angles / (2.0 * math.pi)
    last = lut.shape[0] - 1
    miss = lut[last]
    for p in range(count):
        x = particles[p, 0]
        y = particles[p, 1]
        theta = particles[p, 2]
        fi = (x - x0) * inv_res
        fj = (y - y0) * inv_res
        if not (fi >= 0.0 and fj >= 0.0 and fi < nx and fj < ny):  # NaN fails too
            out[p] = -np.inf
            continue
        cell = int(fj) * nx + int(fi)
        if robot_ok[cell] == 0:
            out[p] = -np.inf
            continue
        if lidar_offset != 0.0:
            fi += lidar_offset * math.cos(theta) * inv_res
            fj += lidar_offset * math.sin(theta) * inv_res
        row = int(fj) * nx + int(fi)  # the LiDAR is within |offset| of a valid centre
        t = theta * bins_per_rad
        t = t - math.floor(t / angles) * angles + 0.5  # + 0.5: truncation rounds to nearest
        total = 0.0
        for b in range(valid_bins.shape[0]):
            k = int(t + valid_bins[b])
            k = k - angles if k >= angles else k
            k = k - angles if k >= angles else k
            d = abs(valid_z[b] - np.int32(table[row, k]))
            total += lut[d if d < last else last]
        for b in range(invalid_bins.shape[0]):
            k = int(t + invalid_bins[b])
            k = k - angles if k >= angles else k
            k = k - angles if k >= angles else k
            r = np.int32(table[row, k])
            total += miss if (r >= range_min_mm) & (r <= range_max_mm) else 0.0
        out[p] = total


log_likelihoods_kernel = jit(log_likelihoods_python)


def log_likelihoods_numpy(particles, count, table, angles, x0, y0, resolution, nx, ny,
                          robot_ok, lidar_offset, valid_bins, valid_z, invalid_bins, lut,
                          range_min_mm, range_max_mm, out):
    """The same model with numpy array operations over particles x beams."""
    pts = particles[:count]
    x, y, theta = pts[:, 0], pts[:, 1], pts[:, 2]
    with np.errstate(invalid="ignore"):
        fi = (x - x0) / resolution
        fj = (y - y0) / resolution
        on_grid = (fi >= 0) & (fj >= 0) & (fi < nx) & (fj < ny)
    fi, fj = np.where(on_grid, fi, 0.0), np.where(on_grid, fj, 0.0)
    cell = fj.astype(np.int64) * nx + fi.astype(np.int64)
    ok = on_grid & (robot_ok[cell] != 0)
    theta = np.where(ok, theta, 0.0)
    li = (fi + lidar_offset * np.cos(theta) / resolution).astype(np.int64)
    lj = (fj + lidar_offset * np.sin(theta) / resolution).astype(np.int64)
    row = np.where(ok, lj * nx + li, 0)[:, None]
    t = theta * (angles / (2.0 * math.pi))
    t = (t - np.floor(t / angles) * angles + 0.5)[:, None]
    last = lut.shape[0] - 1
    r = table[row, (t + valid_bins[None, :]).astype(np.int64) % angles].astype(np.int32)
    total = lut[np.minimum(np.abs(valid_z[None, :] - r), last)].sum(axis=1)
    if invalid_bins.size:
        r = table[row, (t + invalid_bins[None, :]).astype(np.int64) % angles].astype(np.int32)
        total = total + np.where((r >= range_min_mm) & (r <= range_max_mm), lut[last],
                                 0.0).sum(axis=1)
    out[:count] = np.where(ok, total, -np.inf)


log_likelihoods = log_likelihoods_kernel if HAVE_NUMBA else log_likelihoods_numpy
