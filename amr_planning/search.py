"""Grid searches on a cost grid: A* (8-connected, no corner cutting) and the seeds' wavefront.

Plain Python functions, compiled with numba through amr_common.jit (the uncompiled functions are
the fallback and give the same paths: same arithmetic, same heap order). No rclpy.

The grid is flattened row-major: cell = row * width + col. `cost[cell]` is the traversal cost
per cell length (>= 1, inf = not traversable). A move between neighbouring cells a and b costs
step * (cost[a] + cost[b]) / 2 with step = 1 (side) or sqrt(2) (diagonal), in cell lengths.
A diagonal move needs both cells it squeezes between to be traversable (no corner cutting).
"""
from __future__ import annotations

import heapq
import math

import numpy as np

from amr_common.jit import jit

SQRT2 = math.sqrt(2.0)


def astar_python(cost, width, start, goal, heuristic_weight, came_from, g):
    """A* from cell `start` to cell `goal`; returns the number of cells expanded.

    heuristic_weight: 1 = A* with the octile distance (admissible: costs are >= 1, so the path is
    optimal), 0 = Dijkstra, w > 1 = weighted A* (cost within w times the optimum).
    Fills came_from (predecessor of each reached cell, -1 elsewhere) and g (cost from start, inf
    where not reached); g[goal] is inf if the goal is unreachable.
    """
    n = cost.shape[0]
    height = n // width
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
        row = cell // width
        col = cell % width
        g_cell = g[cell]
        cost_cell = cost[cell]
        for d_row in range(-1, 2):
            r = row + d_row
            if r < 0 or r >= height:
                continue
            for d_col in range(-1, 2):
                c = col + d_col
                if (d_row == 0 and d_col == 0) or c < 0 or c >= width:
                    continue
                nb = r * width + c
                if closed[nb] or cost[nb] == np.inf:
                    continue
                step = 1.0
                if d_row != 0 and d_col != 0:
                    if cost[row * width + c] == np.inf or cost[r * width + col] == np.inf:
                        continue  # no corner cutting
                    step = SQRT2
                g_new = g_cell + step * 0.5 * (cost_cell + cost[nb])
                if g_new < g[nb]:
                    g[nb] = g_new
                    came_from[nb] = cell
                    dr = abs(goal_row - r)
                    dc = abs(goal_col - c)
                    h = float(max(dr, dc) - min(dr, dc)) + SQRT2 * min(dr, dc)
                    heapq.heappush(heap, (g_new + heuristic_weight * h, nb))
    return expanded


def wavefront_python(cost, width, start, goal, came_from, g):
    """The seeds' wavefront: a breadth-first wave of integer steps from the goal over traversable
    cells (8-connected, no corner cutting), then steepest descent from the start (side moves
    preferred on ties). Ignores the cost values beyond traversability. Fills came_from as A* does
    (the path is read from goal back to start); returns the number of cells the wave reached."""
    n = cost.shape[0]
    height = n // width
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
        row = cell // width
        col = cell % width
        for d_row in range(-1, 2):
            r = row + d_row
            if r < 0 or r >= height:
                continue
            for d_col in range(-1, 2):
                c = col + d_col
                if (d_row == 0 and d_col == 0) or c < 0 or c >= width:
                    continue
                nb = r * width + c
                if wave[nb] >= 0 or cost[nb] == np.inf:
                    continue
                if d_row != 0 and d_col != 0 and (cost[row * width + c] == np.inf
                                                  or cost[r * width + col] == np.inf):
                    continue
                wave[nb] = wave[cell] + 1
                queue[tail] = nb
                tail += 1
    if wave[start] < 0:
        return tail
    # Descend from the start: each step to a neighbour one wave step closer to the goal.
    cell = start
    g[start] = 0.0
    while cell != goal:
        row = cell // width
        col = cell % width
        best = -1
        best_step = 0.0
        for diagonal in range(2):  # side moves first, so ties prefer them
            for d_row in range(-1, 2):
                for d_col in range(-1, 2):
                    if (d_row != 0 and d_col != 0) != (diagonal == 1) or (d_row == 0
                                                                          and d_col == 0):
                        continue
                    r = row + d_row
                    c = col + d_col
                    if r < 0 or r >= height or c < 0 or c >= width:
                        continue
                    nb = r * width + c
                    if wave[nb] != wave[cell] - 1 or wave[nb] < 0:
                        continue
                    if diagonal == 1 and (cost[row * width + c] == np.inf
                                          or cost[r * width + col] == np.inf):
                        continue
                    if best < 0:
                        best = nb
                        best_step = SQRT2 if diagonal == 1 else 1.0
        came_from[best] = cell  # predecessor links, as A* leaves them
        g[best] = g[cell] + best_step * 0.5 * (cost[cell] + cost[best])
        cell = best
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


__all__ = ["astar", "astar_python", "wavefront", "wavefront_python", "trace_back", "SQRT2"]
