"""Exact clearances of a map's free cells by a Euclidean distance transform.

The distance from each free cell's centre to the nearest non-free cell, without a loop over the
wall segments. A map world's walls are its non-free cells (amr_common.world.map_raster). The point
of a non-free cell nearest to a free cell's centre is a corner of that cell or the middle of one of
its edges (the foot of the perpendicular from the centre lies on the centre's own row or column
line), and centres, corners and edge middles all lie on the lattice of half cells. So the
squared distance transform of that lattice, with every lattice point inside a non-free cell as a
site (cells beyond the map are non-free), read at the free cells' centres, gives the exact
distances that World.clearances computes from the wall segments, in time linear in the cells
instead of cells x segments (a 15 x 12 m SLAM-like map at 5 cm, 4,400 segments: 0.7 s instead
of 4.4 s).

The transform is Felzenszwalb & Huttenlocher's: a 1D pass along each column, then along each
row, over the lower envelope of parabolas; compiled with numba (amr_common.jit), the plain
Python function its twin.
"""
from __future__ import annotations

import numpy as np

from amr_common.jit import jit


def squared_edt_1d_python(f, out, v, z):
    """out[q] = min_p (q - p)^2 + f[p] for one line (v: int64, z: float64 work arrays, n + 1)."""
    n = f.shape[0]
    k = 0
    v[0] = 0
    z[0] = -np.inf
    z[1] = np.inf
    for q in range(1, n):
        s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
        while s <= z[k]:
            k -= 1
            s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
        k += 1
        v[k] = q
        z[k] = s
        z[k + 1] = np.inf
    k = 0
    for q in range(n):
        while z[k + 1] < q:
            k += 1
        out[q] = (q - v[k]) * (q - v[k]) + f[v[k]]


squared_edt_1d = jit(squared_edt_1d_python)


def squared_edt_python(sites):
    """Squared distance (in lattice steps) from every point of a 2D bool array to a True one.

    Every column and row must hold a site (callers pad with a ring of them).
    """
    rows, cols = sites.shape
    far = float(rows * rows + cols * cols)  # beyond any distance on the lattice
    out = np.empty((rows, cols))
    n = max(rows, cols)
    v = np.empty(n + 1, dtype=np.int64)
    z = np.empty(n + 1)
    line = np.empty(n)
    result = np.empty(n)
    for c in range(cols):
        for r in range(rows):
            line[r] = 0.0 if sites[r, c] else far
        squared_edt_1d(line[:rows], result[:rows], v, z)
        for r in range(rows):
            out[r, c] = result[r]
    for r in range(rows):
        for c in range(cols):
            line[c] = out[r, c]
        squared_edt_1d(line[:cols], result[:cols], v, z)
        for c in range(cols):
            out[r, c] = result[c]
    return out


squared_edt = jit(squared_edt_python)


def free_cell_clearances(free: np.ndarray, resolution: float) -> np.ndarray:
    """(rows, cols) float64: each free cell's centre's distance to the nearest non-free cell (m).

    `free`: (rows, cols) bool, row 0 at the bottom; cells beyond it are non-free; 0 for the
    non-free cells themselves.
    """
    rows, cols = free.shape
    blocked = np.ones((rows + 2, cols + 2), dtype=bool)
    blocked[1:-1, 1:-1] = ~np.asarray(free, dtype=bool)
    sites = np.zeros((2 * rows + 5, 2 * cols + 5), dtype=np.bool_)
    for dr in range(3):  # every half-cell lattice point of a blocked cell's closed square
        for dc in range(3):
            sites[dr:dr + 2 * rows + 4:2, dc:dc + 2 * cols + 4:2] |= blocked
    squared = squared_edt(sites)
    # Padded cell (R, C) spans lattice points 2R .. 2R + 2; map cell (r, c) is padded
    # (r + 1, c + 1), its centre lattice point (2r + 3, 2c + 3).
    centres = squared[3:2 * rows + 3:2, 3:2 * cols + 3:2]
    return np.where(free, np.sqrt(centres) * (0.5 * resolution), 0.0)


__all__ = ["free_cell_clearances", "squared_edt", "squared_edt_1d", "squared_edt_1d_python",
           "squared_edt_python"]

