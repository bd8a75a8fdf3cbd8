"""Polygons of a world file: edges, distances to them, inside tests, and the file's checks.

check_polygons refuses a world file whose boundary or holes cross themselves, or whose holes
lie outside or across the boundary (WorldError naming the file and the point); check_movers one
whose movers' paths leave the boundary (with their radius).
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.world.coverage_grid import inside_polygon_points
from amr_common.world.world_file import WorldError, WorldFile


def squared_segment_distances(seg: np.ndarray, px, py) -> np.ndarray:
    """Squared point-segment distances; px, py scalars or (K, 1) columns -> (N,) or (K, N)."""
    x1, y1, x2, y2 = seg[:, 0], seg[:, 1], seg[:, 2], seg[:, 3]
    ex, ey = x2 - x1, y2 - y1
    t = np.clip(((px - x1) * ex + (py - y1) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
    dx, dy = x1 + t * ex - px, y1 + t * ey - py
    return dx * dx + dy * dy


def segment_distances(a: np.ndarray, b: np.ndarray) -> tuple[float, tuple[float, float]]:
    """Smallest distance between the segments `a` (N, 4) and `b` (M, 4, none of zero length).

    Also a point of `a` where it is reached (where they cross, if they do). `a` may hold
    zero-length segments (points).
    """
    crossing = _first_crossing(a, b)
    if crossing is not None:
        return 0.0, (float(crossing[0]), float(crossing[1]))
    ends = np.vstack([a[:, 0:2], a[:, 2:4]])  # a's ends to b's segments
    to_b = squared_segment_distances(b, ends[:, 0:1], ends[:, 1:2]).min(axis=1)
    i = int(np.argmin(to_b))
    best, point = float(to_b[i]), (float(ends[i, 0]), float(ends[i, 1]))
    a = a[(a[:, 2] - a[:, 0]) ** 2 + (a[:, 3] - a[:, 1]) ** 2 > 0.0]
    for px, py in np.vstack([b[:, 0:2], b[:, 2:4]]):  # b's ends to a's segments
        if len(a) == 0:
            break
        squared = squared_segment_distances(a, px, py)
        k = int(np.argmin(squared))
        if squared[k] < best:
            x1, y1, x2, y2 = a[k]
            ex, ey = x2 - x1, y2 - y1
            t = min(max(((px - x1) * ex + (py - y1) * ey) / (ex * ex + ey * ey), 0.0), 1.0)
            best, point = float(squared[k]), (float(x1 + t * ex), float(y1 + t * ey))
    return math.sqrt(best), point


def point_in_polygon(poly: np.ndarray, x: float, y: float) -> bool:
    """Even-odd ray crossing test."""
    return bool(inside_polygon_points(poly, np.array([[x, y]], dtype=np.float64))[0])


def closed_segments(poly: np.ndarray) -> np.ndarray:
    """A closed polygon's (N, 2) vertices as its N edges [x1, y1, x2, y2] (the last closes it)."""
    return np.hstack([poly, np.roll(poly, -1, axis=0)])


def check_polygons(spec: WorldFile) -> None:
    """WorldError for a self-crossing boundary or hole, or a hole outside or across the boundary.

    Touching is fine (a hole flush with the outer wall); free-standing walls may cross anything.
    """
    polygons = [("boundary", spec.boundary)] + [(f"holes[{i}]", h) for i, h in
                                                 enumerate(spec.holes)]
    for what, poly in polygons:
        edges = closed_segments(poly)
        n = len(edges)
        # Edges i < j that are not neighbours (neighbours share a point).
        point = _first_crossing(edges, edges,
                                lambda i, j: (j > i + 1) & ~((i == 0) & (j == n - 1)))
        if point is not None:
            raise WorldError(f"{spec.path}: '{what}' crosses itself at ({point[0]:g}, "
                             f"{point[1]:g}): a polygon's edges may not cross")
    boundary_edges = closed_segments(spec.boundary)
    for what, hole in polygons[1:]:
        point = _first_crossing(closed_segments(hole), boundary_edges)
        if point is not None:
            raise WorldError(f"{spec.path}: '{what}' crosses the boundary at ({point[0]:g}, "
                             f"{point[1]:g}): holes are obstacles inside it")
        outside = ~inside_polygon_points(spec.boundary, hole)
        if outside.any():
            gaps = np.sqrt(squared_segment_distances(boundary_edges, hole[outside, 0:1],
                                              hole[outside, 1:2]).min(axis=1))
            if (gaps > 1e-9).any():  # on the boundary is touching, not outside
                raise WorldError(f"{spec.path}: '{what}' lies outside the boundary: holes are "
                                 f"obstacles inside it")


def check_movers(spec: WorldFile) -> None:
    """WorldError for a mover whose path leaves the boundary or comes closer to it than its radius.

    Naming the mover and the point.
    """
    boundary_edges = closed_segments(spec.boundary)
    for mover in spec.movers:
        what = mover.label or mover.name
        outside = ~inside_polygon_points(spec.boundary, mover.path)
        if outside.any():
            x, y = mover.path[np.argmax(outside)]
            raise WorldError(f"{spec.path}: {what}: path point ({x:g}, {y:g}) is outside the "
                             f"boundary")
        gap, (x, y) = segment_distances(mover.path_segments(), boundary_edges)
        if gap < mover.radius:
            raise WorldError(f"{spec.path}: {what}: its path comes {gap:.3f} m from the boundary "
                             f"near ({x:g}, {y:g}), closer than its radius {mover.radius:g} m")


def _first_crossing(a: np.ndarray, b: np.ndarray, pairs=None, chunk: int = 256):
    """Where a segment of `a` properly crosses one of `b` (not touching), or None.

    `pairs(i, j)` (index arrays) selects the pairs to test; rows of `a` go in chunks to bound
    the memory of long polylines.
    """
    def orient(p, q, r):  # sign of the turn p -> q -> r, 0 within rounding
        value = (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - \
                (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
        return np.where(np.abs(value) < 1e-12, 0.0, np.sign(value))

    q1, q2 = b[None, :, 0:2], b[None, :, 2:4]
    for start in range(0, len(a), chunk):
        rows = a[start:start + chunk]
        p1, p2 = rows[:, None, 0:2], rows[:, None, 2:4]
        crossing = ((orient(p1, p2, q1) * orient(p1, p2, q2) < 0)
                    & (orient(q1, q2, p1) * orient(q1, q2, p2) < 0))
        if pairs is not None:
            i, j = np.meshgrid(np.arange(start, start + len(rows)), np.arange(len(b)),
                               indexing="ij")
            crossing &= pairs(i, j)
        if crossing.any():
            i, j = np.argwhere(crossing)[0]
            (x1, y1, x2, y2), (x3, y3, x4, y4) = rows[i], b[j]
            t = ((x3 - x1) * (y4 - y3) - (y3 - y1) * (x4 - x3)) / \
                ((x2 - x1) * (y4 - y3) - (y2 - y1) * (x4 - x3))
            return x1 + t * (x2 - x1), y1 + t * (y2 - y1)
    return None
