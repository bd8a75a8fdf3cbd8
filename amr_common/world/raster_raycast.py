"""Ray casting through a map's cells (grid ray marching), for maps with many wall segments.

A map world's walls are the edges between free and non-free cells (map_raster.boundary_segments).
A noisy map (what SLAM builds: speckles, ragged walls) has thousands of them, and the segment
kernel (amr_common.world.raycast) costs rays x segments. Marching each ray cell by cell
(Amanatides & Woo's traversal) costs rays x cells crossed instead, whatever the noise, and
returns the same ranges: the first cell edge where the ray passes between a free and a non-free
cell (cells beyond the map are non-free), at t > 0, as the segment kernel finds on those edges
(a ray through a cell corner, or within CORNER_EPS of it, hits when the four cells there are not
all alike, as it would hit a segment's end; a ray running exactly along a grid line is left to
rounding, in both kernels). Which one is faster depends on the map: scripts/bench_map_world.py
measures both, and World.march_grid holds the rule drawn from it.

The kernels take a MarchGrid's `cells`: the map's cells padded with one ring of BORDER cells,
flattened (so the loop needs no bounds checks), FREE_CELL = 1 for a free cell, 0 for the rest.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.jit import jit

FREE_CELL, BORDER = 1, 2
# A ray passing this close to a cell corner (in cells) goes through it: it hits the corner if
# an edge ends there, as the segment kernel's inclusive end test does (rounding decides
# otherwise which neighbour a grazing ray visits).
CORNER_EPS = 1e-9


@dataclass(frozen=True)
class MarchGrid:
    """A map's cells as the marching kernels take them (see the module docstring)."""

    cells: np.ndarray  # (rows + 2) * (cols + 2) uint8, row-major, the ring = BORDER
    width: int  # cols + 2
    x0: float  # lower-left corner of the padded grid (one cell left of / below the map's)
    y0: float
    resolution: float

    @classmethod
    def from_raster(cls, raster) -> "MarchGrid":
        """The march grid of an amr_common.world.map_raster.Raster (free: value 0)."""
        rows, cols = raster.values.shape
        padded = np.full((rows + 2, cols + 2), BORDER, dtype=np.uint8)
        padded[1:-1, 1:-1] = raster.free
        res = float(raster.resolution)
        return cls(np.ascontiguousarray(padded.ravel()), cols + 2,
                   float(raster.origin[0]) - res, float(raster.origin[1]) - res, res)


def clip_python(g, d, n, t_in, t_out):
    """(t_in, t_out) narrowed to where g + d t lies in [1, n + 1); t_in > t_out if nowhere."""
    if d != 0.0:
        a = (1.0 - g) / d
        b = (n + 1.0 - g) / d
        return max(t_in, min(a, b)), min(t_out, max(a, b))
    if 1.0 <= g < n + 1.0:
        return t_in, t_out
    return 1.0, 0.0


_clip = jit(clip_python)


def march_python(cells, width, gx, gy, dx, dy, limit):
    """Cells travelled from grid point (gx, gy) along the unit ray (dx, dy) to the first edge.

    The first edge between a free and a non-free cell; inf if there is none within `limit`
    cells.
    """
    cols = width - 2
    rows = cells.shape[0] // width - 2
    # Clip the ray to the map (grid coordinates 1 .. n + 1): beyond it nothing is free.
    t_in, t_out = _clip(gx, dx, cols, 0.0, limit)
    t_in, t_out = _clip(gy, dy, rows, t_in, t_out)
    if t_in > t_out:
        return np.inf
    col = min(max(int(math.floor(gx + dx * t_in)), 0), cols + 1)
    row = min(max(int(math.floor(gy + dy * t_in)), 0), rows + 1)
    if t_in > 0.0:  # starts off the map: the first map cell is where it enters
        col = min(max(col, 1), cols)
        row = min(max(row, 1), rows)
        if cells[row * width + col] == FREE_CELL:
            return t_in
    step_c = 1 if dx > 0.0 else -1
    step_r = width if dy > 0.0 else -width
    delta_c = abs(1.0 / dx) if dx != 0.0 else np.inf
    delta_r = abs(1.0 / dy) if dy != 0.0 else np.inf
    next_c = ((col + (1 if dx > 0.0 else 0) - gx) / dx) if dx != 0.0 else np.inf
    next_r = ((row + (1 if dy > 0.0 else 0) - gy) / dy) if dy != 0.0 else np.inf
    index = row * width + col
    inside = cells[index] == FREE_CELL
    while True:
        if next_c < next_r - CORNER_EPS:
            t = next_c
            index += step_c
            next_c += delta_c
            changed = (cells[index] == FREE_CELL) != inside
        elif next_r < next_c - CORNER_EPS:
            t = next_r
            index += step_r
            next_r += delta_r
            changed = (cells[index] == FREE_CELL) != inside
        else:  # through a corner: an edge ends here unless the four cells are alike
            t = next_c
            changed = (((cells[index + step_c] == FREE_CELL) != inside)
                       or ((cells[index + step_r] == FREE_CELL) != inside))
            index += step_c + step_r
            next_c += delta_c
            next_r += delta_r
            changed = changed or ((cells[index] == FREE_CELL) != inside)
        if t > t_out:
            return np.inf
        if changed and t > 0.0:
            return t
        if cells[index] == BORDER:  # left the map: nothing beyond it is free
            return np.inf
        inside = cells[index] == FREE_CELL


march = jit(march_python)


def scan_grid_python(cells, width, x0, y0, resolution, ox, oy, theta, base_cos, base_sin,
                     range_min, range_max, no_return, noise, out):
    """Ranges along rays at angles theta + a_i (base_cos/sin = cos/sin a_i), written into out.

    As raycast.scan_python: noise is added to the true ranges; readings outside
    [range_min, range_max] (and rays that hit nothing) become no_return.
    """
    cos_t = math.cos(theta)
    sin_t = math.sin(theta)
    gx = (ox - x0) / resolution
    gy = (oy - y0) / resolution
    for i in range(base_cos.shape[0]):
        dx = cos_t * base_cos[i] - sin_t * base_sin[i]
        dy = sin_t * base_cos[i] + cos_t * base_sin[i]
        # The farthest true range that can still read as valid with this ray's noise.
        limit = (range_max - noise[i]) / resolution
        r = march(cells, width, gx, gy, dx, dy, limit) * resolution + noise[i]
        out[i] = r if (r >= range_min) & (r <= range_max) else no_return


scan_grid_kernel = jit(scan_grid_python)


__all__ = ["BORDER", "FREE_CELL", "MarchGrid", "march", "march_python", "scan_grid_kernel",
           "scan_grid_python"]
