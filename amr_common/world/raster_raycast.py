"""Ray casting through grids, for maps with many wall segments: the one home of grid marching.

Two grids, one idea: a ray walks the grid cells it crosses, in order (Amanatides & Woo's
traversal), and stops at the first wall, so its cost grows with the cells it crosses, not with
the number of walls.

MarchGrid: a map's cells themselves. A map world's walls are the edges between free and non-free
cells (map_raster.boundary_segments). A noisy map (what SLAM builds: speckles, ragged walls) has
thousands of them, and the segment kernel (amr_common.world.raycast) costs rays x segments.
Marching each ray cell by cell returns the same ranges: the first cell edge where the ray passes
between a free and a non-free cell (cells beyond the map are non-free), at t > 0, as the segment
kernel finds on those edges (a ray through a cell corner, or within CORNER_EPS of it, hits when the
four cells there are not all alike, as it would hit a segment's end; a ray running exactly along a
grid line is left to rounding, in both kernels). Which one is faster depends on the map:
scripts/bench_map_world.py measures both, and World.march_grid holds the rule drawn from it.
The kernels take a MarchGrid's `cells`: the map's cells padded with one ring of BORDER cells,
flattened (so the loop needs no bounds checks), FREE_CELL = 1 for a free cell, 0 for the rest.

SegmentGrid: any wall segments, each listed in the square cells (buckets) its bounding box
touches. A ray walks the buckets it crosses and tests only their walls, with the segment
kernel's own arithmetic (raycast.segment_hit), so it finds exactly the range that testing every
wall finds; a disc query lists the walls near a point. For walls that are not a map's free-cell
edges (the particle filter's walls inside a map's occupied cells, map_raster.
likely_wall_segments) and for the simulator's contacts on big maps (the walls near the robot).

Long: both grids' kernels and their plain twins in one home, so that a ray walks a grid one way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.jit import jit
from amr_common.world.polygons import squared_segment_distances
from amr_common.world.raycast import segment_hit, segment_offset

FREE_CELL, BORDER = 1, 2
_LIST_EPS = 1e-9  # m: a wall is listed in every bucket within this of its bounding box
_WALLS_PER_BUCKET = 4.0  # SegmentGrid's default bucket size: about this many walls each
_MAX_BUCKETS = 4_000_000  # ... and at most this many buckets (32 MB of list starts)
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


@dataclass(frozen=True)
class SegmentGrid:
    """Wall segments listed by the square buckets they touch (see the module docstring).

    Bucket (row, col) covers x0 + [col, col + 1) * size, y0 + [row, row + 1) * size; its walls
    are items[starts[b]:starts[b + 1]] with b = row * nx + col: those whose bounding box,
    widened by _LIST_EPS, touches it. The buckets cover every wall with one bucket to spare.
    """

    segments: np.ndarray  # (N, 4) float64 [x1, y1, x2, y2]
    starts: np.ndarray  # (nx * ny + 1,) int64
    items: np.ndarray  # int32 wall indices
    x0: float
    y0: float
    size: float
    nx: int
    ny: int

    @classmethod
    def build(cls, segments: np.ndarray, size: float | None = None) -> "SegmentGrid":
        """The grid of these walls, buckets of `size` m (default: ~4 walls per bucket).

        Coarser if need be: at most _MAX_BUCKETS buckets, and listings within a few times the
        walls (long slanted walls touch many buckets with their bounding boxes).
        """
        walls = np.ascontiguousarray(np.asarray(segments, dtype=np.float64).reshape(-1, 4))
        lo = np.minimum(walls[:, :2], walls[:, 2:]) - _LIST_EPS
        hi = np.maximum(walls[:, :2], walls[:, 2:]) + _LIST_EPS
        (xmin, ymin), (xmax, ymax) = lo.min(axis=0), hi.max(axis=0)
        extent = max(xmax - xmin, ymax - ymin, 1e-3)
        if size is None:
            size = math.sqrt(max((xmax - xmin) * (ymax - ymin), 1e-6) * _WALLS_PER_BUCKET
                             / len(walls))
        size = max(float(size), extent / math.sqrt(_MAX_BUCKETS))
        while True:
            x0, y0 = float(xmin) - size, float(ymin) - size
            nx = int(math.ceil((xmax - x0) / size)) + 1
            ny = int(math.ceil((ymax - y0) / size)) + 1
            first = np.floor((lo - (x0, y0)) / size).astype(np.int64)
            span = np.floor((hi - (x0, y0)) / size).astype(np.int64) - first + 1
            counts = span[:, 0] * span[:, 1]  # buckets each wall's box touches
            if counts.sum() <= 8 * len(walls) + nx * ny:
                break
            size *= 2.0
        wall = np.repeat(np.arange(len(walls), dtype=np.int64), counts)
        k = np.arange(len(wall), dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
        bucket = (first[wall, 1] + k // span[wall, 0]) * nx + first[wall, 0] + k % span[wall, 0]
        order = np.argsort(bucket, kind="stable")
        starts = np.zeros(nx * ny + 1, dtype=np.int64)
        np.cumsum(np.bincount(bucket, minlength=nx * ny), out=starts[1:])
        return cls(walls, starts, wall[order].astype(np.int32), x0, y0, size, nx, ny)

    @property
    def arrays(self) -> tuple:
        """(segments, starts, items, x0, y0, size, nx, ny): what the kernels take."""
        return (self.segments, self.starts, self.items, self.x0, self.y0, self.size, self.nx,
                self.ny)

    def near(self, x: float, y: float, radius: float) -> np.ndarray:
        """Indices (ascending) of the walls within `radius` of (x, y).

        The buckets' listings (a slice of `items` per row of buckets), then exact distances.
        """
        c0, c1 = (min(max(int(math.floor((v - self.x0) / self.size)), 0), self.nx - 1)
                  for v in (x - radius, x + radius))
        r0, r1 = (min(max(int(math.floor((v - self.y0) / self.size)), 0), self.ny - 1)
                  for v in (y - radius, y + radius))
        rows = np.arange(r0, r1 + 1) * self.nx
        found = np.unique(np.concatenate([self.items[self.starts[b + c0]:self.starts[b + c1 + 1]]
                                          for b in rows]))
        with np.errstate(divide="ignore", invalid="ignore"):  # a point wall: NaN, never near
            distance = np.sqrt(squared_segment_distances(self.segments[found], float(x),
                                                         float(y)))
        return found[distance <= radius].astype(np.int64)

    def clearances(self, points: np.ndarray) -> np.ndarray:
        """Distance (m) from each point of a (K, 2) array to the nearest wall."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        out = np.empty(len(pts))
        clearances_through_buckets(*self.arrays, pts, out)
        return out

    def cast(self, ox: float, oy: float, dx: float, dy: float) -> tuple[float, int]:
        """(range, wall) of the first wall the ray from (ox, oy) along the unit (dx, dy) hits.

        (inf, -1) if it hits none. The range is raycast.scan_python's, exactly.
        """
        return cast_through_buckets(*self.arrays, float(ox), float(oy), float(dx), float(dy))


def walls_near_python(segments, starts, items, x0, y0, size, nx, ny, px, py, r_lo, r_hi,
                      stamp, stamp_id, out):
    """Walls whose distance to (px, py) is in (r_lo, r_hi], written into out; their count.

    r_hi may be inf (every wall). stamp: one int64 per wall, marked with stamp_id when looked at
    (a wall listed in several buckets is counted once); use a new stamp_id per query.
    """
    count = 0
    if r_hi == np.inf:
        for k in range(segments.shape[0]):
            if segment_offset(segments, k, px, py)[2] > r_lo:
                out[count] = k
                count += 1
        return count
    col_lo = max(int(math.floor((px - r_hi - x0) / size)), 0)
    col_hi = min(int(math.floor((px + r_hi - x0) / size)), nx - 1)
    row_lo = max(int(math.floor((py - r_hi - y0) / size)), 0)
    row_hi = min(int(math.floor((py + r_hi - y0) / size)), ny - 1)
    for row in range(row_lo, row_hi + 1):
        for col in range(col_lo, col_hi + 1):
            b = row * nx + col
            for j in range(starts[b], starts[b + 1]):
                k = items[j]
                if stamp[k] != stamp_id:
                    stamp[k] = stamp_id
                    d = segment_offset(segments, k, px, py)[2]
                    if d > r_lo and d <= r_hi:
                        out[count] = k
                        count += 1
    return count


walls_near = jit(walls_near_python)


def clearances_through_buckets_python(segments, starts, items, x0, y0, size, nx, ny, points,
                                      out):
    """Distance from each point of a (K, 2) array to the nearest wall, written into out.

    The buckets around a point's own are searched in growing square rings; a wall listed only in
    ring r or beyond is more than r - 1 buckets away (its nearest point lies in a bucket that
    lists it): the search ends once the nearest found is that close (clearances_python's
    distances, exactly). A point off the buckets starts from the nearest point of their box, d
    away: a wall more than D from that point is more than sqrt(D^2 + d^2) from the point.
    """
    for i in range(points.shape[0]):
        px = points[i, 0]
        py = points[i, 1]
        best = np.inf
        if not (math.isfinite(px) and math.isfinite(py)):
            for k in range(segments.shape[0]):  # as clearances_python: inf for NaN
                d = segment_offset(segments, k, px, py)[2]
                best = d if d < best else best
            out[i] = best
            continue
        col = min(max((px - x0) / size, 0.0), nx - 1e-9)
        row = min(max((py - y0) / size, 0.0), ny - 1e-9)
        off = (px - x0 - col * size) ** 2 + (py - y0 - row * size) ** 2
        c = int(col)
        r = int(row)
        ring = 0
        while ring == 0 or (best * best > ((ring - 1) * size) ** 2 + off
                            and ring <= max(nx, ny)):
            for rr in range(max(r - ring, 0), min(r + ring, ny - 1) + 1):
                edge = rr == r - ring or rr == r + ring  # the ring's whole row, else its ends
                for cc in range(c - ring, c + ring + 1, 1 if edge else max(2 * ring, 1)):
                    if 0 <= cc < nx:
                        b = rr * nx + cc
                        for j in range(starts[b], starts[b + 1]):
                            d = segment_offset(segments, items[j], px, py)[2]
                            best = d if d < best else best
            ring += 1
        out[i] = best


clearances_through_buckets = jit(clearances_through_buckets_python)


def cast_through_buckets_python(segments, starts, items, x0, y0, size, nx, ny, ox, oy, dx, dy):
    """(t, k): the first wall k the unit ray from (ox, oy) along (dx, dy) hits, at range t.

    (inf, -1) for none. The ray walks the buckets it crosses; it may stop once the nearest hit
    so far lies within the buckets walked (a nearer one would be listed in one of them: its
    hit point lies in it, and so within its bounding box).
    """
    # Clip the ray to the buckets (grid coordinates 1 .. n + 1 for clip_python).
    gx = (ox - x0) / size
    gy = (oy - y0) / size
    t_in, t_out = _clip(gx + 1.0, dx / size, nx, 0.0, np.inf)
    t_in, t_out = _clip(gy + 1.0, dy / size, ny, t_in, t_out)
    if t_in > t_out:
        return np.inf, -1
    col = min(max(int(math.floor(gx + dx / size * t_in)), 0), nx - 1)
    row = min(max(int(math.floor(gy + dy / size * t_in)), 0), ny - 1)
    step_c = 1 if dx > 0.0 else -1
    step_r = 1 if dy > 0.0 else -1
    delta_c = abs(size / dx) if dx != 0.0 else np.inf
    delta_r = abs(size / dy) if dy != 0.0 else np.inf
    next_c = (x0 + (col + (1 if dx > 0.0 else 0)) * size - ox) / dx if dx != 0.0 else np.inf
    next_r = (y0 + (row + (1 if dy > 0.0 else 0)) * size - oy) / dy if dy != 0.0 else np.inf
    best = np.inf
    hit = -1
    while True:
        b = row * nx + col
        for j in range(starts[b], starts[b + 1]):
            t = segment_hit(segments, items[j], ox, oy, dx, dy)
            if t < best:
                best = t
                hit = items[j]
        if next_c < next_r:
            if best <= next_c:
                return best, hit
            col += step_c
            next_c += delta_c
            if col < 0 or col >= nx:
                return best, hit
        else:
            if best <= next_r:
                return best, hit
            row += step_r
            next_r += delta_r
            if row < 0 or row >= ny:
                return best, hit


cast_through_buckets = jit(cast_through_buckets_python)


def cast_rays_through_buckets_python(segments, starts, items, x0, y0, size, nx, ny, ox, oy, dx,
                                     dy, out_range, out_cos):
    """raycast.cast_rays_python through the buckets: ray i from (ox[i], oy[i]) along dx, dy[i].

    Ranges (inf for none) and |cos| of the incidence (0 without a hit); the ranges by
    scan_python's arithmetic (cast_rays_python's differs in the last bits).
    """
    for i in range(ox.shape[0]):
        t, k = cast_through_buckets(segments, starts, items, x0, y0, size, nx, ny, ox[i], oy[i],
                                    dx[i], dy[i])
        out_range[i] = t
        out_cos[i] = 0.0
        if k >= 0:
            ex = segments[k, 2] - segments[k, 0]
            ey = segments[k, 3] - segments[k, 1]
            out_cos[i] = abs(dx[i] * ey - dy[i] * ex) * (1.0 / math.sqrt(ex * ex + ey * ey))


cast_rays_through_buckets = jit(cast_rays_through_buckets_python)


__all__ = ["BORDER", "FREE_CELL", "MarchGrid", "SegmentGrid", "cast_rays_through_buckets",
           "cast_rays_through_buckets_python", "cast_through_buckets",
           "cast_through_buckets_python", "clearances_through_buckets",
           "clearances_through_buckets_python", "march", "march_python", "scan_grid_kernel",
           "scan_grid_python", "walls_near", "walls_near_python"]
