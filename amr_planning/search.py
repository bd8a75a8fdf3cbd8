"""Grid searches on a cost grid: A* (8-connected, no corner cutting) and the seeds' wavefront.

Plain Python functions, compiled with numba through amr_common.jit (the uncompiled functions are
the fallback and the plain-Python reference of scripts/bench_planning.py; they give the same
paths: same arithmetic, same heap order). No rclpy.

The grid is flattened row-major: cell = row * width + col. `cost[cell]` is the traversal cost
per cell length (>= 1, inf = not traversable). A move between neighbouring cells a and b costs
step * (cost[a] + cost[b]) / 2 with step = 1 (side) or sqrt(2) (diagonal), in cell lengths.
`allowed_moves()` precomputes, per cell, which of the 8 moves stay on the grid and on
traversable cells; a diagonal move also needs both cells it squeezes between (no corner cutting).
"""
from __future__ import annotations

import heapq
import math

import numpy as np

from amr_common.jit import jit

SQRT2 = math.sqrt(2.0)
# Moves: the 4 side moves first (so the wavefront's descent prefers them on ties), then diagonals.
MOVE_ROWS = np.array([0, 1, 0, -1, 1, 1, -1, -1], dtype=np.int64)
MOVE_COLS = np.array([1, 0, -1, 0, 1, -1, -1, 1], dtype=np.int64)
MOVE_STEPS = (1.0, 1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2, SQRT2)  # a tuple: fast in both


def allowed_moves(traversable: np.ndarray) -> np.ndarray:
    """(height * width,) uint8: bit k set where move k is allowed.

    Allowed: from a traversable cell to a traversable cell of the grid (for a diagonal, also
    through two traversable side cells).
    """
    height, width = traversable.shape
    padded = np.zeros((height + 2, width + 2), dtype=bool)
    padded[1:-1, 1:-1] = traversable

    def shifted(d_row: int, d_col: int) -> np.ndarray:
        return padded[1 + d_row:1 + d_row + height, 1 + d_col:1 + d_col + width]

    moves = np.zeros((height, width), dtype=np.uint8)
    for k, (d_row, d_col) in enumerate(zip(MOVE_ROWS, MOVE_COLS)):
        ok = traversable & shifted(d_row, d_col)
        if d_row != 0 and d_col != 0:
            ok &= shifted(d_row, 0) & shifted(0, d_col)
        moves |= ok.astype(np.uint8) << k
    return moves.ravel()


def move_offsets(width: int) -> np.ndarray:
    """Flat index difference of each move on a grid `width` cells wide."""
    return MOVE_ROWS * width + MOVE_COLS


def astar_python(cost, moves, offsets, width, start, goal, heuristic_weight, came_from, g):
    """A* from cell `start` to cell `goal`; returns the number of cells expanded.

    heuristic_weight: 1 = A* with the octile distance (admissible: costs are >= 1, so the path is
    optimal), 0 = Dijkstra, w > 1 = weighted A* (cost within w times the optimum).
    Fills came_from (predecessor of each reached cell, -1 elsewhere) and g (cost from start, inf
    where not reached); g[goal] is inf if the goal is unreachable.
    """
    n = len(cost)
    for i in range(n):
        came_from[i] = -1
        g[i] = np.inf
    closed = np.zeros(n, dtype=np.bool_)
    goal_col = goal % width
    goal_row = goal // width
    g[start] = 0.0
    heap = [(0.0, start)]
    expanded = 0
    while len(heap) > 0:
        _, cell = heapq.heappop(heap)
        if closed[cell]:
            continue  # a stale heap entry: the cell was reached cheaper before
        closed[cell] = True
        expanded += 1
        if cell == goal:
            break
        for k in range(8):
            if not (moves[cell] >> k) & 1:
                continue
            nb = cell + offsets[k]
            if closed[nb]:
                continue
            g_new = g[cell] + MOVE_STEPS[k] * 0.5 * (cost[cell] + cost[nb])
            if g_new < g[nb]:
                g[nb] = g_new
                came_from[nb] = cell
                dr = abs(goal_row - nb // width)
                dc = abs(goal_col - nb % width)
                h = float(max(dr, dc) - min(dr, dc)) + SQRT2 * min(dr, dc)
                heapq.heappush(heap, (g_new + heuristic_weight * h, nb))
    return expanded


def wavefront_python(cost, moves, offsets, start, goal, came_from, g):
    """The seeds' wavefront: a breadth-first wave from the goal, then descent from the start.

    The wave counts integer steps over the allowed moves; the descent takes side moves on ties.
    Ignores the cost values beyond traversability. Fills came_from and g as A* does; returns the
    number of cells the wave reached.
    """
    n = len(cost)
    wave = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        came_from[i] = -1
        g[i] = np.inf
    queue = np.empty(n, dtype=np.int64)
    head = 0
    tail = 1
    queue[0] = goal
    wave[goal] = 0
    while head < tail:
        cell = queue[head]
        head += 1
        if cell == start:
            break
        for k in range(8):  # moves are symmetric: a move out of cell is one into it
            nb = cell + offsets[k]
            if (moves[cell] >> k) & 1 and wave[nb] < 0:
                wave[nb] = wave[cell] + 1
                queue[tail] = nb
                tail += 1
    if wave[start] < 0:
        return tail
    cell = start
    g[start] = 0.0
    while cell != goal:
        for k in range(8):
            nb = cell + offsets[k]
            if (moves[cell] >> k) & 1 and wave[nb] == wave[cell] - 1:
                came_from[nb] = cell  # predecessor links, as A* leaves them
                g[nb] = g[cell] + MOVE_STEPS[k] * 0.5 * (cost[cell] + cost[nb])
                cell = nb
                break
    return tail


astar = jit(astar_python)
wavefront = jit(wavefront_python)


def trace_back(came_from: np.ndarray, start: int, goal: int) -> np.ndarray:
    """Cells from start to goal, following the predecessors in came_from back from the goal."""
    cells = [goal]
    guard = came_from.shape[0]
    while cells[-1] != start and guard > 0:
        cells.append(int(came_from[cells[-1]]))
        guard -= 1
    if cells[-1] != start:
        raise RuntimeError("broken predecessor chain")  # a bug, not a user error
    return np.array(cells[::-1], dtype=np.int64)


__all__ = ["astar", "astar_python", "wavefront", "wavefront_python", "trace_back",
           "allowed_moves", "move_offsets", "SQRT2"]
