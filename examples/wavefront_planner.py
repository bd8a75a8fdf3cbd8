"""A course-style wavefront planner: a breadth-first wave from the goal over the free cells.

A small, readable amr_common.plugins.interfaces.Planner: the project's Planner does more (A* with a
clearance cost that keeps to the middle of corridors, smoothing with rounded corners, compiled
searches). Run it in place of the project's:

    .venv/bin/python scripts/run_sim.py --world lab02 --goal inner_far \
        --planner examples.wavefront_planner:WavefrontPlanner
    .venv/bin/python scripts/evaluate.py --worlds lab02 --goals all --duration 200 \
        --planner examples.wavefront_planner:WavefrontPlanner --out out/wavefront

The map becomes a grid; a cell is free when its centre keeps `clearance_m` from every wall (the
walls "inflated" by the robot's radius and a margin). The wave starts at the goal cell with 0
and gives each free neighbour (8-connected) its distance in steps + 1; the path walks from the
start cell down the wave, always to the neighbour with the smallest number. The path hugs the
inflated walls (it is a shortest path in steps), so its clearance is about clearance_m: the
follower must not cut corners by much.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from amr_common.geometry import without_repeats
from amr_common.plugins.parameter_table import above, checked_values, ruled
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world import World

_PARAMETERS = ruled({
    "resolution_m": (0.02, "Grid cell size [m]"),
    "clearance_m": (0.15, "A cell is free when its centre keeps this from every wall [m]"),
    "snap_m": (0.1, "A start or goal in the inflated walls joins the nearest free cell this "
                    "close [m]"),
}, above(0.0))
_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


@dataclass
class WavefrontPath:
    """What plan() returns: the path's points (the interface's PlannedPath)."""

    points: np.ndarray  # (K, 2) from the start to the goal, metres


class WavefrontPlanner:
    """Breadth-first wavefront on the inflated grid (see the module docstring)."""

    @staticmethod
    def parameter_descriptions() -> dict[str, tuple[Any, str]]:
        """Each parameter: name -> (default, description); the node declares them."""
        return dict(_PARAMETERS)

    def __init__(self, map: World, **params: Any) -> None:
        self.p = checked_values(_PARAMETERS, params, "WavefrontPlanner")  # ValueError
        self.grid = OccupancyGrid.from_world(map, float(self.p["resolution_m"]))
        self.free = self.grid.clearance >= float(self.p["clearance_m"])

    def warm_up(self) -> None:
        """Nothing to compile: plain Python."""

    def describe(self) -> str:
        """One line for logs."""
        return (f"wavefront on {self.grid.width} x {self.grid.height} cells of "
                f"{self.grid.resolution} m, clearance {self.p['clearance_m']} m")

    def plan(self, start, goal) -> WavefrontPath:
        """A path from start (x, y) to goal (x, y); ValueError naming the problem if none."""
        start_cell = self._free_cell(start, "start")
        goal_cell = self._free_cell(goal, "goal")
        wave = self._wave(goal_cell)
        if wave[start_cell] < 0:
            raise ValueError(f"goal ({goal[0]:.3f}, {goal[1]:.3f}) is unreachable from start "
                             f"({start[0]:.3f}, {start[1]:.3f})")
        cells = [start_cell]
        while wave[cells[-1]] > 0:  # down the wave: each step one number lower
            row, col = cells[-1]
            cells.append(min(((row + dr, col + dc) for dr, dc in _NEIGHBOURS
                              if self._inside(row + dr, col + dc)
                              and wave[row + dr, col + dc] >= 0),
                             key=lambda cell: wave[cell]))
        rows, cols = np.array(cells).T
        centres = self.grid.cell_centres(rows, cols)
        points = np.vstack([[start[0], start[1]], centres, [goal[0], goal[1]]])
        return WavefrontPath(points=without_repeats(points))

    def _wave(self, goal_cell: tuple[int, int]) -> np.ndarray:
        """Steps from every free cell to the goal cell (-1: not reached)."""
        wave = np.full(self.free.shape, -1, dtype=np.int64)
        wave[goal_cell] = 0
        queue = deque([goal_cell])
        while queue:
            row, col = queue.popleft()
            for dr, dc in _NEIGHBOURS:
                r, c = row + dr, col + dc
                if self._inside(r, c) and self.free[r, c] and wave[r, c] < 0:
                    wave[r, c] = wave[row, col] + 1
                    queue.append((r, c))
        return wave

    def _inside(self, row: int, col: int) -> bool:
        return 0 <= row < self.free.shape[0] and 0 <= col < self.free.shape[1]

    def _free_cell(self, point, what: str) -> tuple[int, int]:
        """The point's cell if free, else the nearest free cell within snap_m."""
        x, y = (float(v) for v in point)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"{what} ({x}, {y}) is not finite")
        row, col = self.grid.cell_of(x, y)
        if not self._inside(row, col):
            raise ValueError(f"{what} ({x:.3f}, {y:.3f}) is outside the map")
        if self.free[row, col]:
            return row, col
        reach = int(math.ceil(float(self.p["snap_m"]) / self.grid.resolution))
        rows, cols = np.nonzero(self.free[max(row - reach, 0):row + reach + 1,
                                          max(col - reach, 0):col + reach + 1])
        if len(rows) == 0:
            raise ValueError(f"{what} ({x:.3f}, {y:.3f}) is in or too close to a wall: no "
                             f"free cell within {self.p['snap_m']} m")
        rows, cols = rows + max(row - reach, 0), cols + max(col - reach, 0)
        nearest = int(np.argmin((rows - row) ** 2 + (cols - col) ** 2))
        return int(rows[nearest]), int(cols[nearest])
