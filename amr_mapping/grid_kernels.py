"""Compiled loops of the occupancy grid: ray tracing into log-odds counts, the smoothed field.

Each kernel is written once in plain Python (`*_python`, the twin the tests compare against)
and compiled through amr_common.jit (numba when installed). Grid coordinates are in cells:
x / resolution (trace_rays: global) or x / resolution - origin column (the others), so cell
(row, col) covers [col, col + 1) x [row, row + 1).

- `trace_rays`: exact grid traversal (Amanatides & Woo) from the sensor to each end point, in
  global cell units (the same cells whatever the array's offset). The cells a ray crosses
  completely before `miss_stop` cells short of its end get `miss`, the end cell gets `hit`
  (int32 log-odds units, so a scan added with +hit/+miss and later with -hit/-miss leaves the
  counts exactly as before: how keyframes move after a loop closure).
  Stopping the misses short of the end keeps grazing rays from eroding the wall they end on.
- `smear_window`: L[c] = max over occupied cells o of w_o times a Gaussian of the distance from
  c's centre to o's mean hit position: the smoothed field the scan matcher scores points on
  (Karto's "smear"). Peaks at the mean hit rather than at the cell centre (a wall on a cell
  boundary is not moved by half a cell); w_o, the share of the rays reaching o that ended in
  it, makes a cell that noise hit once and many rays crossed count little, so the ridge of a
  wall a few cells thick lies on its most-hit cells.
- `max_pool`: one level of the branch-and-bound pyramid: out[r, c] = max of src over the
  2^h x 2^h block starting at (r, c).
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit

SHIFT_BINS = 16  # sub-cell positions of the smoothed field's peaks, per axis


def _crossings_python(start, cell, d):
    """Along start + t d (t in [0, 1]): the t between cell borders and of the first border."""
    if d == 0.0:
        return math.inf, math.inf
    return 1.0 / abs(d), ((cell + (1 if d > 0.0 else 0)) - start) / d


_crossings = jit(_crossings_python)


def trace_rays_python(counts, row_off, col_off, sx, sy, ends, hit, miss, miss_stop, sign, hits,
                      sums):
    """Add `miss` along each ray from (sx, sy) to ends[k] and `hit` at its end cell.

    sx, sy and ends (K, 2) in GLOBAL cell units (x / resolution, y / resolution); global cell
    (r, c) is counts[r - row_off, c - col_off] (counts: (rows, cols) int32, changed in place);
    cells outside the array are skipped. The traversal is computed in global units, so a ray
    crosses exactly the same cells whatever the array's offset: a scan added before the grid
    grew is taken out exactly after. Each end cell also counts `sign` hits in `hits` (same
    shape as counts) and, if sums (5, rows, cols) float64 is not empty, adds sign * the moments
    of the end point's position (fx, fy) within the cell (cell units, 0..1): fx, fy, fx^2,
    fx fy, fy^2 - the mean and spread of a cell's hits, which place walls inside their cells.
    Returns the number of cells changed.
    Long: one compiled loop on purpose (~65 lines): the traversal's state stays in locals.
    """
    rows, cols = counts.shape
    changed = 0
    col0 = math.floor(sx)
    row0 = math.floor(sy)
    for k in range(ends.shape[0]):
        ex = ends[k, 0]
        ey = ends[k, 1]
        dx = ex - sx
        dy = ey - sy
        length = math.sqrt(dx * dx + dy * dy)
        end_col = math.floor(ex)
        end_row = math.floor(ey)
        if length > miss_stop:
            t_free = (length - miss_stop) / length  # misses only for cells left before this
            col = col0
            row = row0
            step_col = 1 if dx > 0.0 else -1
            step_row = 1 if dy > 0.0 else -1
            delta_x, t_x = _crossings(sx, col, dx)
            delta_y, t_y = _crossings(sy, row, dy)
            # Each step moves one cell closer in one axis: this many reach the end cell.
            steps = abs(end_col - col0) + abs(end_row - row0)
            for _ in range(steps):
                t_exit = t_x if t_x < t_y else t_y
                if t_exit > t_free:
                    break
                r = row - row_off
                c = col - col_off
                if 0 <= r < rows and 0 <= c < cols:
                    counts[r, c] += miss
                    changed += 1
                if t_x < t_y:
                    col += step_col
                    t_x += delta_x
                else:
                    row += step_row
                    t_y += delta_y
        r = end_row - row_off
        c = end_col - col_off
        if 0 <= r < rows and 0 <= c < cols:
            counts[r, c] += hit
            changed += 1
            hits[r, c] += sign
            if sums.shape[1]:
                fx = ex - end_col
                fy = ey - end_row
                sums[0, r, c] += sign * fx
                sums[1, r, c] += sign * fy
                sums[2, r, c] += sign * fx * fx
                sums[3, r, c] += sign * fx * fy
                sums[4, r, c] += sign * fy * fy
    return changed


def smear_window_python(counts, hits, sums, row_off, col_off, occupied_units, hit_units,
                        miss_units, kernels, out):
    """The smoothed field over a window of the grid, written into out (rows, cols), float32.

    Window cell (i, j) is grid cell (i + row_off, j + col_off). For every grid cell o within
    the kernel's reach of the window whose log-odds count exceeds occupied_units:
    out[c] = max(out[c], w_o * kernel) with w_o = hits / (hits + misses) (misses from the count,
    hit_units and miss_units > 0) and the kernel of kernels (bins, bins, 2r + 1, 2r + 1) for the
    sub-cell bin of o's mean hit position (shifted_gaussian_kernels).
    """
    grid_rows, grid_cols = counts.shape
    rows, cols = out.shape
    radius = kernels.shape[2] // 2
    bins = kernels.shape[0]
    for i in range(-radius, rows + radius):
        gi = i + row_off
        if gi < 0 or gi >= grid_rows:
            continue
        for j in range(-radius, cols + radius):
            gj = j + col_off
            if gj < 0 or gj >= grid_cols:
                continue
            h = hits[gi, gj]
            if counts[gi, gj] <= occupied_units or h <= 0:
                continue
            misses = (hit_units * h - counts[gi, gj]) / miss_units
            w = h / (h + misses) if misses > 0.0 else 1.0
            bx = min(max(int(math.floor(sums[0, gi, gj] / h * bins)), 0), bins - 1)
            by = min(max(int(math.floor(sums[1, gi, gj] / h * bins)), 0), bins - 1)
            kernel = kernels[by, bx]
            for di in range(-radius, radius + 1):
                ii = i + di
                if ii < 0 or ii >= rows:
                    continue
                for dj in range(-radius, radius + 1):
                    jj = j + dj
                    if jj < 0 or jj >= cols:
                        continue
                    value = w * kernel[di + radius, dj + radius]
                    if value > out[ii, jj]:
                        out[ii, jj] = value


def max_pool_python(src, shift, out):
    """out[r, c] = max(src[r, c], src[r + shift, c], src[r, c + shift], src[r + shift, c + shift]).

    Cells beyond the array count as 0 (the field is >= 0): applied to level h - 1 with shift
    2^(h-1) it gives level h, the maximum over each 2^h x 2^h block.
    """
    rows, cols = src.shape
    for r in range(rows):
        r2 = r + shift
        for c in range(cols):
            c2 = c + shift
            best = src[r, c]
            if r2 < rows:
                if src[r2, c] > best:
                    best = src[r2, c]
                if c2 < cols and src[r2, c2] > best:
                    best = src[r2, c2]
            if c2 < cols and src[r, c2] > best:
                best = src[r, c2]
            out[r, c] = best


trace_rays = jit(trace_rays_python)
smear_window = jit(smear_window_python)
max_pool = jit(max_pool_python)


def shifted_gaussian_kernels(sigma_cells: float, bins: int = SHIFT_BINS) -> np.ndarray:
    """(bins, bins, 2r + 1, 2r + 1) float32: exp(-d^2 / (2 sigma^2)) from a point in a cell.

    kernels[by, bx, r + di, r + dj] is the value at the centre of the cell (di, dj) away from a
    cell whose point sits at ((bx + 0.5) / bins, (by + 0.5) / bins) within it;
    r = ceil(3 sigma) + 1 cells.
    """
    radius = max(1, math.ceil(3.0 * sigma_cells) + 1)
    offsets = np.arange(-radius, radius + 1, dtype=np.float64) + 0.5
    centre = (np.arange(bins) + 0.5) / bins
    dx = offsets[None, None, None, :] - centre[None, :, None, None]
    dy = offsets[None, None, :, None] - centre[:, None, None, None]
    return np.exp(-(dx ** 2 + dy ** 2) / (2.0 * sigma_cells ** 2)).astype(np.float32)


__all__ = ["trace_rays", "trace_rays_python", "smear_window", "smear_window_python", "max_pool",
           "max_pool_python", "shifted_gaussian_kernels"]
