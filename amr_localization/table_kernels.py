"""The compiled kernels of the expected-range table's build (table_build has the method).

fill_blocks: the rows of the listed blocks of cells; fill_block: one block, its rays cast ring
by ring against the walls of their wedge (or through the buckets); the steps it chains are
kernels of their own. Each `*_python` function is the plain twin of its kernel (the kernels
call each other's compiled versions; tested equal); fill_blocks_numpy is the fallback without
numba (every ray against every wall). No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit
from amr_common.world.raster_raycast import cast_through_buckets, walls_near
from amr_common.world.raycast import scan_numpy

NO_RANGE_MM = 65535  # a ray that hits nothing (or beyond 65.5 m)
# A ray cast through the buckets costs about as much as sorting this many walls of a ring.
BUCKET_RAY_COST = 64
_WEDGE_EPS = 1e-9  # m, rad: rounding slack of the wedge test (it may keep a wall, never drop)


def _store_mm_python(ranges, out_row):
    for k in range(ranges.shape[0]):
        mm = ranges[k] * 1000.0
        out_row[k] = NO_RANGE_MM if not (mm < NO_RANGE_MM) else np.uint16(round(mm))


_store_mm = jit(_store_mm_python)


def _ring_angles_python(mids, radii, ring, n_ring, cx, cy, reach, angle, spread):
    """Where the walls of ring[:n_ring] lie as seen from (cx, cy), for the wedge test.

    angle[j]: the direction of wall ring[j]'s bounding circle's centre (mids, radii);
    spread[j]: the angle within which a ray from within `reach` of (cx, cy) can meet that
    circle (pi: any, when the circle comes within reach of the centre). A ray in direction a
    can hit the wall only if a is within spread[j] of angle[j]: the ray stays within reach of
    the ray from (cx, cy) in direction a, whose distance to the circle's centre is
    dist * sin(a - angle) (dist beyond 90 degrees).
    """
    for j in range(n_ring):
        k = ring[j]
        vx = mids[k, 0] - cx
        vy = mids[k, 1] - cy
        dist = math.sqrt(vx * vx + vy * vy)
        allow = reach + radii[k] + _WEDGE_EPS
        angle[j] = math.atan2(vy, vx)
        spread[j] = math.pi if dist <= allow else math.asin(allow / dist) + _WEDGE_EPS


_ring_angles = jit(_ring_angles_python)


def _wedge_python(ring, n_ring, angle, spread, mid, half, out):
    """The walls of ring[:n_ring] that rays within `half` of the direction `mid` can hit.

    Written into out; their count. angle, spread: _ring_angles' (a wall is kept when the
    sector's directions come within its spread of its angle).
    """
    count = 0
    for j in range(n_ring):
        off = angle[j] - mid
        off = abs(off - 2.0 * math.pi * math.floor(off / (2.0 * math.pi) + 0.5))
        if off <= half + spread[j]:
            out[count] = ring[j]
            count += 1
    return count


_wedge = jit(_wedge_python)


def _cast_pairs_python(segments, walls, n_walls, ox, oy, dx, dy, best, n_rays):
    """best[i] = min(best[i], range of ray i against walls[:n_walls]), rays with own origins.

    raycast.scan_python's arithmetic (the walls outside, the rays inside, branch-free).
    """
    for j in range(n_walls):
        k = walls[j]
        x1 = segments[k, 0]
        y1 = segments[k, 1]
        ex = segments[k, 2] - x1
        ey = segments[k, 3] - y1
        for i in range(n_rays):
            qx = x1 - ox[i]
            qy = y1 - oy[i]
            q_cross_e = qx * ey - qy * ex
            inv_den = 1.0 / (dx[i] * ey - dy[i] * ex)
            t = q_cross_e * inv_den
            u = (qx * dy[i] - qy * dx[i]) * inv_den
            r = t if (t > 0.0) & (u >= 0.0) & (u <= 1.0) else np.inf
            best[i] = r if r < best[i] else best[i]


_cast_pairs = jit(_cast_pairs_python)


def _walls_in_square_python(sat, x0, y0, size, nx, ny, cx, cy, radius):
    """Listings of the buckets within `radius` of (cx, cy) along x and y (sat: summed counts)."""
    c0 = min(max(int(math.floor((cx - radius - x0) / size)), 0), nx)
    c1 = min(max(int(math.floor((cx + radius - x0) / size)) + 1, 0), nx)
    r0 = min(max(int(math.floor((cy - radius - y0) / size)), 0), ny)
    r1 = min(max(int(math.floor((cy + radius - y0) / size)) + 1, 0), ny)
    return sat[r1, c1] - sat[r0, c1] - sat[r1, c0] + sat[r0, c0]


_walls_in_square = jit(_walls_in_square_python)


def fill_block_python(segments, mids, radii, starts, items, gx0, gy0, size, nx, ny, sat, xs,
                      ys, cx, cy, reach, rings, sector, angles_of, base_cos, base_sin, march,
                      scratch, stamp, stamp_id, best):
    """best[i, k] = the range from (xs[i], ys[i]) along direction k: one block (module doc).

    march: cast every ray through the buckets at once (faster on dense maps, where rays are
    short), without rings.
    scratch: (7, n) float64 and (3, n) int64 arrays, n >= len(segments) and >= len(xs) * sector
    (the walls of a ring and of a wedge; a sector's pending rays); stamp: one int64 per wall;
    stamp_id: an id not used before with it. Returns the next unused stamp_id.
    Long: one compiled kernel whose Python body is its own plain twin; the steps it chains
    (ring, wedge, cast) are kernels of their own.
    """
    floats, ints = scratch
    ring, chosen, pending = ints[0], ints[1], ints[2]
    ox, oy, dx, dy, pb = floats[0], floats[1], floats[2], floats[3], floats[4]
    angle, spread = floats[5], floats[6]
    n_cells = xs.shape[0]
    n_dirs = base_cos.shape[0]
    best[:n_cells] = np.inf
    left = n_cells * n_dirs
    inner = -1.0
    for level in range(rings.shape[0]):
        outer = rings[level]
        many = segments.shape[0] if outer == np.inf else \
            _walls_in_square(sat, gx0, gy0, size, nx, ny, cx, cy, outer)
        if march or (level > 0 and left * BUCKET_RAY_COST < many):  # rays one by one
            for i in range(n_cells):
                for k in range(n_dirs):
                    if best[i, k] > inner - reach:
                        best[i, k] = cast_through_buckets(segments, starts, items, gx0, gy0,
                                                          size, nx, ny, xs[i], ys[i],
                                                          base_cos[k], base_sin[k])[0]
            return stamp_id
        n_ring = walls_near(segments, starts, items, gx0, gy0, size, nx, ny, cx, cy, inner,
                            outer, stamp, stamp_id, ring)
        stamp_id += 1
        _ring_angles(mids, radii, ring, n_ring, cx, cy, reach, angle, spread)
        for k0 in range(0, n_dirs, sector):
            k1 = min(k0 + sector, n_dirs)
            n_rays = 0
            for i in range(n_cells):
                for k in range(k0, k1):
                    if best[i, k] > inner - reach:  # not done at the last ring
                        pending[n_rays] = i * n_dirs + k
                        ox[n_rays] = xs[i]
                        oy[n_rays] = ys[i]
                        dx[n_rays] = base_cos[k]
                        dy[n_rays] = base_sin[k]
                        pb[n_rays] = best[i, k]
                        n_rays += 1
            if n_rays == 0:
                continue
            half = 0.5 * (angles_of[k1 - 1] - angles_of[k0]) + _WEDGE_EPS
            n_chosen = _wedge(ring, n_ring, angle, spread,
                              0.5 * (angles_of[k0] + angles_of[k1 - 1]), half, chosen)
            _cast_pairs(segments, chosen, n_chosen, ox, oy, dx, dy, pb, n_rays)
            for j in range(n_rays):
                i = pending[j] // n_dirs
                best[i, pending[j] - i * n_dirs] = pb[j]
                left -= 1 if pb[j] <= outer - reach else 0
        inner = outer
        if left == 0:
            break
    return stamp_id


fill_block = jit(fill_block_python)


def fill_blocks_python(segments, mids, radii, starts, items, gx0, gy0, size, nx, ny, sat,
                       cells, block_starts, x0, y0, resolution, width, reach, rings, sector,
                       angles_of, base_cos, base_sin, rows, march, blocks, scratch, stamp,
                       stamp_id, out):
    """The table's rows of the cells of the listed blocks, written into out (see fill_block).

    cells: row-major cell indices grouped by block (block b: cells[block_starts[b]:
    block_starts[b + 1]]); rows: each cell's row of out; scratch, stamp, stamp_id: as
    fill_block takes them (scratch_arrays), the first stamp_id unused. Returns the next one.
    """
    most = 1
    for b in blocks:
        most = max(most, block_starts[b + 1] - block_starts[b])
    best = np.empty((most, base_cos.shape[0]))
    xs = np.empty(most)
    ys = np.empty(most)
    for b in blocks:
        first = block_starts[b]
        n_cells = block_starts[b + 1] - first
        lo = cells[first] % width
        hi = lo
        for i in range(n_cells):
            xs[i] = x0 + (cells[first + i] % width + 0.5) * resolution
            ys[i] = y0 + (cells[first + i] // width + 0.5) * resolution
            lo = min(lo, cells[first + i] % width)
            hi = max(hi, cells[first + i] % width)
        # The middle of the cells' bounding box (rows: the cells are in row-major order).
        cx = x0 + (0.5 * (lo + hi) + 0.5) * resolution
        cy = y0 + (0.5 * (cells[first] // width + cells[first + n_cells - 1] // width) + 0.5) \
            * resolution
        stamp_id = fill_block(segments, mids, radii, starts, items, gx0, gy0, size, nx, ny, sat,
                              xs[:n_cells], ys[:n_cells], cx, cy, reach, rings, sector, angles_of,
                              base_cos, base_sin, march, scratch, stamp, stamp_id, best)
        for i in range(n_cells):
            _store_mm(best[i], out[rows[cells[first + i]]])
    return stamp_id


def scratch_arrays(walls: int, block_cells: int, sector: int) -> tuple:
    """(scratch, stamp) for fill_block(s): one set per thread, reused from call to call."""
    n = max(walls, block_cells * sector)
    return (np.empty((7, n)), np.empty((3, n), dtype=np.int64)), np.zeros(walls, dtype=np.int64)


fill_blocks = jit(fill_blocks_python)


def fill_blocks_numpy(segments, mids, radii, starts, items, gx0, gy0, size, nx, ny, sat,
                      cells, block_starts, x0, y0, resolution, width, reach, rings, sector,
                      angles_of, base_cos, base_sin, rows, march, blocks, scratch, stamp, stamp_id,
                      out):
    """Every ray of the listed blocks' cells against every wall (the fallback without numba)."""
    ranges = np.empty(base_cos.shape[0])
    zeros = np.zeros_like(ranges)
    for b in blocks:
        for cell in cells[block_starts[b]:block_starts[b + 1]]:
            x, y = x0 + (cell % width + 0.5) * resolution, y0 + (cell // width + 0.5) * resolution
            scan_numpy(segments, x, y, 0.0, base_cos, base_sin, 0.0, np.inf, np.inf, zeros,
                       ranges)
            mm = np.where(ranges * 1000.0 < NO_RANGE_MM, np.round(ranges * 1000.0), NO_RANGE_MM)
            out[rows[cell]] = mm.astype(np.uint16)
    return stamp_id


__all__ = ["BUCKET_RAY_COST", "NO_RANGE_MM", "fill_block", "fill_block_python", "fill_blocks",
           "fill_blocks_numpy", "fill_blocks_python", "scratch_arrays"]
