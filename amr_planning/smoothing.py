"""Turning a grid path into a path a robot drives well, without losing clearance.

1. simplify(): greedy line-of-sight shortcuts over the grid path's points. A shortcut from point a
   to point j replaces the points between them only if the straight segment's clearance stays at
   least `required(c)`, where c is the smallest clearance of the replaced points (so a path kept
   in the middle of a corridor by the planner's cost stays there).
2. fillet(): each remaining corner becomes a circular arc tangent to both segments, the largest
   radius (up to max_radius, tangents up to half of each segment) whose arc keeps required(c) for
   the c of the corner's replaced part; a corner where no radius of at least min_radius
   qualifies stays sharp (the pursuit turns in place there).
3. The result is sampled every `spacing` metres (arcs finer, so neighbouring samples turn by at
   most 0.25 rad).

required(c) = max(min(c, cap) - tolerance, min(c, floor)): the path may lose at most `tolerance`
of clearance below min(c, cap), and never goes below `floor` (the inflation radius) where the
grid path did not. Clearances are exact distances to the world's wall segments.
Kernels compile with numba through amr_common.jit; the Python functions are the fallback.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit
from amr_common.world.raycast import clearances_into, nearest_wall_kernel

_MAX_ARC_STEP_RAD = 0.25


def _segment_clearance_python(segments, ax, ay, bx, by, ds):
    """Smallest distance to a wall of points every <= ds along the segment a-b (ends included)."""
    length = math.hypot(bx - ax, by - ay)
    n = int(math.ceil(length / ds)) + 1
    best = np.inf
    for i in range(n):
        t = i / (n - 1) if n > 1 else 0.0
        d = nearest_wall_kernel(segments, ax + t * (bx - ax), ay + t * (by - ay))[0]
        if d < best:
            best = d
    return best


_segment_clearance = jit(_segment_clearance_python)


def _required_python(c, cap, floor, tolerance):
    return max(min(c, cap) - tolerance, min(c, floor))


_required = jit(_required_python)


def _simplify_python(segments, points, clearances, cap, floor, tolerance, ds, keep):
    """Mark in `keep` the points the greedy shortcuts keep; returns how many."""
    n = points.shape[0]
    for i in range(n):
        keep[i] = False
    keep[0] = True
    keep[n - 1] = True
    count = 2 if n > 1 else 1
    anchor = 0
    while anchor < n - 1:
        best = anchor + 1
        lowest = min(clearances[anchor], clearances[anchor + 1])
        j = anchor + 2
        while j < n:
            lowest = min(lowest, clearances[j])
            need = _required(lowest, cap, floor, tolerance)
            if _segment_clearance(segments, points[anchor, 0], points[anchor, 1],
                                  points[j, 0], points[j, 1], ds) < need:
                break
            best = j
            j += 1
        if best < n - 1:
            keep[best] = True
            count += 1
        anchor = best
    return count


_simplify = jit(_simplify_python)


def _arc_clearance_python(segments, cx, cy, radius, angle0, sweep, ds):
    """Smallest wall distance of points every <= ds along an arc (centre, radius, angles)."""
    n = int(math.ceil(abs(sweep) * radius / ds)) + 1
    best = np.inf
    for i in range(n):
        a = angle0 + sweep * i / (n - 1)
        d = nearest_wall_kernel(segments, cx + radius * math.cos(a), cy + radius * math.sin(a))[0]
        if d < best:
            best = d
    return best


_arc_clearance = jit(_arc_clearance_python)


def _fillet_python(segments, p0, p1, p2, t_in_max, t_out_max, min_radius, max_radius, cap, floor,
                   tolerance, ds):
    """Largest radius of an arc rounding corner p1 of p0-p1-p2 that keeps the clearance rule.

    0 if none of at least min_radius does (the corner stays sharp).
    """
    ux, uy = p1[0] - p0[0], p1[1] - p0[1]
    vx, vy = p2[0] - p1[0], p2[1] - p1[1]
    lu, lv = math.hypot(ux, uy), math.hypot(vx, vy)
    ux, uy, vx, vy = ux / lu, uy / lu, vx / lv, vy / lv
    turn = math.atan2(ux * vy - uy * vx, ux * vx + uy * vy)
    if abs(turn) < 1e-6 or abs(turn) > math.pi - 1e-3:
        return 0.0  # straight (nothing to round) or a reversal (no arc fits)
    half_tan = math.tan(0.5 * abs(turn))
    radius = min(max_radius, min(t_in_max, t_out_max) / half_tan)
    while radius >= min_radius:
        t = radius * half_tan
        ax, ay = p1[0] - t * ux, p1[1] - t * uy
        bx, by = p1[0] + t * vx, p1[1] + t * vy
        replaced = min(_segment_clearance(segments, ax, ay, p1[0], p1[1], ds),
                       _segment_clearance(segments, p1[0], p1[1], bx, by, ds))
        side = 1.0 if turn > 0 else -1.0  # centre on the inside of the turn
        cx, cy = ax - side * uy * radius, ay + side * ux * radius
        angle0 = math.atan2(ay - cy, ax - cx)
        if _arc_clearance(segments, cx, cy, radius, angle0, turn, ds) >= \
                _required(replaced, cap, floor, tolerance):
            return radius
        radius *= 0.85
    return 0.0


_fillet = jit(_fillet_python)


def simplify(segments: np.ndarray, points: np.ndarray, cap: float, floor: float,
             tolerance: float, ds: float) -> np.ndarray:
    """The points kept by line-of-sight shortcuts (see the module docstring), (M, 2)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if len(points) <= 2:
        return points.copy()
    keep = np.zeros(len(points), dtype=np.bool_)
    clearances = np.empty(len(points))
    clearances_into(segments, points, clearances)
    _simplify(segments, points, clearances, cap, floor, tolerance, ds, keep)
    return points[keep]


def fillet_and_sample(segments: np.ndarray, corners: np.ndarray, spacing: float,
                      min_radius: float, max_radius: float, cap: float, floor: float,
                      tolerance: float, ds: float) -> np.ndarray:
    """Round the corners of a polyline with arcs and sample it every `spacing` metres.

    See the module docstring. Returns (K, 2) with the first and last corner as the ends.
    """
    corners = np.ascontiguousarray(corners, dtype=np.float64)
    n = len(corners)
    if n < 2:
        return corners.copy()
    lengths = np.hypot(*np.diff(corners, axis=0).T)
    # Per corner: (tangent point before, arc centre, radius, start angle, sweep) or sharp.
    pieces: list[np.ndarray] = [corners[:1]]
    cursor = corners[0]
    for i in range(1, n - 1):
        # Inner segments are shared by two corners (half each); the end ones belong to one.
        t_in = lengths[i - 1] * (1.0 if i == 1 else 0.5)
        t_out = lengths[i] * (1.0 if i == n - 2 else 0.5)
        radius = _fillet(segments, corners[i - 1], corners[i], corners[i + 1], t_in, t_out,
                         min_radius, max_radius, cap, floor, tolerance, ds)
        if radius <= 0.0:
            pieces.append(_sample_line(cursor, corners[i], spacing))
            cursor = corners[i]
            continue
        u = (corners[i] - corners[i - 1]) / lengths[i - 1]
        v = (corners[i + 1] - corners[i]) / lengths[i]
        turn = math.atan2(u[0] * v[1] - u[1] * v[0], float(u @ v))
        t = radius * math.tan(0.5 * abs(turn))
        a, b = corners[i] - t * u, corners[i] + t * v
        pieces.append(_sample_line(cursor, a, spacing))
        pieces.append(_sample_arc(a, u, turn, radius, spacing))
        cursor = b
    pieces.append(_sample_line(cursor, corners[-1], spacing))
    path = np.vstack(pieces)
    steps = np.hypot(*np.diff(path, axis=0).T)
    return path[np.concatenate([[True], steps > 1e-9])]  # drop repeated points


def _sample_line(a: np.ndarray, b: np.ndarray, spacing: float) -> np.ndarray:
    """Points after a up to b inclusive, evenly, at most `spacing` apart."""
    length = float(np.hypot(*(b - a)))
    n = max(1, math.ceil(length / spacing))
    t = np.arange(1, n + 1)[:, None] / n
    return a + t * (b - a)


def _sample_arc(a: np.ndarray, u: np.ndarray, turn: float, radius: float,
                spacing: float) -> np.ndarray:
    """Points after a along the arc starting at a with tangent u, turning `turn` rad."""
    side = 1.0 if turn > 0 else -1.0
    centre = a + side * radius * np.array([-u[1], u[0]])
    angle0 = math.atan2(a[1] - centre[1], a[0] - centre[0])
    step = min(spacing / radius, _MAX_ARC_STEP_RAD)
    n = max(1, math.ceil(abs(turn) / step))
    angles = angle0 + turn * np.arange(1, n + 1) / n
    return centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])


__all__ = ["simplify", "fillet_and_sample"]
