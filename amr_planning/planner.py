"""Path planning on a world's occupancy grid, keeping clearance from the walls.

Inflated walls, a clearance cost, A* or wavefront, and a smoothed path that keeps its
clearance. No rclpy (the `planner` node wraps it).

    planner = Planner(World.load("lab02"))               # 2 cm grid, A*
    plan = planner.plan((1.0, -1.0), (0.6, -0.6))       # PlanningError if impossible
    plan.points, plan.length_m, plan.min_clearance_m

Grid and costs (amr_common.world.occupancy_grid gives each cell's exact distance c to the nearest
wall):
- a cell is not traversable when c < robot_radius_m + safety_margin_m (the inflated walls);
- otherwise it costs 1 + clearance_weight * ((c_pref - c) / (c_pref - c_infl))^2 per cell length
  for c < c_pref = preferred_clearance_m, else 1: paths keep to the middle of corridors narrower
  than 2 c_pref and keep c_pref from obstacles elsewhere (a distance-transform cost, like Nav2's
  inflation layer, but from exact distances).
- A* (8-connected, no corner cutting, octile heuristic: optimal for heuristic_weight 1, within
  that factor of the optimal cost above 1) or the seeds' wavefront (`algorithm`).
- Paths never leave the inflated free space, except where the robot already is: a start inside
  the inflation (it may even touch a wall) is connected by a straight piece to the nearest
  traversable cell that does not bring it closer to the walls. A goal must keep the inflation
  radius from every wall (amr_common.world.world's goal rule, the one the run scripts check): one
  closer is a PlanningError, never a straight piece through the inflation.
The grid path is then simplified and its corners rounded (amr_planning.smoothing).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from amr_common.geometry import polyline_length, without_repeats
from amr_common.plugins.parameter_table import (
    Param,
    above,
    at_least,
    checked_values,
    one_of,
    ruled,
)
from amr_common.robot import ROBOT_RADIUS
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.raycast import nearest_wall_kernel
from amr_common.world.world import SAFETY_MARGIN, World
from amr_planning import search, smoothing

ALGORITHMS = ("astar", "wavefront")

# name: (default, description with units). The planner node declares each as a ROS parameter.
_TABLE: dict[str, tuple[Any, str]] = {
    "algorithm": ("astar", "Grid search: 'astar' (8-connected A* with the clearance cost) or "
                           "'wavefront' (the seeds' breadth-first wave from the goal)."),
    "resolution_m": (0.02, "Grid cell size [m]."),
    "robot_radius_m": (ROBOT_RADIUS, "Robot footprint radius [m]."),
    "safety_margin_m": (SAFETY_MARGIN, "Added to the radius: cells closer to a wall than radius "
                                       "+ margin are not traversable, and goals closer are "
                                       "refused [m]."),
    "preferred_clearance_m": (0.25, "Clearance from which a cell costs no extra; also the "
                                    "clearance smoothing keeps where the grid path had it [m]."),
    "clearance_weight": (4.0, "Extra cost of a cell at the inflation edge relative to a free "
                              "cell (quadratic in the missing clearance) [-]."),
    "heuristic_weight": (1.0, "A* heuristic weight: 1 = optimal; w > 1 = faster, path cost "
                              "within w times the optimum [-]."),
    "smooth": (True, "Simplify the grid path and round its corners with arcs."),
    "clearance_tolerance_m": (0.01, "Smoothing may bring the path this much closer to walls "
                                    "than the grid path locally was (never into the inflation) "
                                    "[m]."),
    "min_turn_radius_m": (0.05, "Smallest arc radius of a rounded corner; tighter corners stay "
                                "sharp (the pursuit turns in place there) [m]."),
    "max_turn_radius_m": (0.5, "Largest arc radius of a rounded corner [m]."),
    "path_spacing_m": (0.02, "Distance between the points of the returned path [m]."),
}
# Numbers >= 0 but for these (heuristic_weight: 0 or >= 1, checked in check_parameters).
PARAMETERS: dict[str, Param] = ruled(
    _TABLE, at_least(0.0), algorithm=one_of(*ALGORITHMS),
    **{name: above(0.0) for name in ("resolution_m", "robot_radius_m", "path_spacing_m",
                                     "min_turn_radius_m")})


class PlanningError(ValueError):
    """No path: the start or goal is outside the map, in or too close to a wall, or unreachable.

    The message says which, with coordinates.
    """


@dataclass
class Plan:
    """A planned path and its figures."""

    points: np.ndarray  # (K, 2) from the start to the goal, metres
    length_m: float
    min_clearance_m: float  # smallest distance of a path point to a wall
    cost: float  # grid path cost (metres weighted by the clearance cost)
    grid_path: np.ndarray  # (M, 2) cell centres of the grid search's path
    expanded: int  # cells the search expanded (the wavefront: cells its wave reached)
    search_time_s: float
    total_time_s: float
    algorithm: str


def check_parameters(overrides: dict[str, Any]) -> dict[str, Any]:
    """All parameter values (defaults updated with `overrides`), checked.

    Each against its rule in PARAMETERS, then together. ValueError names every problem
    (unknown names, non-numbers, out-of-range values).
    """
    checked = checked_values(PARAMETERS, overrides, "Planner")
    if checked["heuristic_weight"] < 1.0 and checked["heuristic_weight"] != 0.0:
        raise ValueError("Planner: heuristic_weight must be 0 (Dijkstra) or >= 1, got "
                         f"{checked['heuristic_weight']!r}")
    inflation = checked["robot_radius_m"] + checked["safety_margin_m"]
    if checked["preferred_clearance_m"] <= inflation:
        raise ValueError(f"Planner: preferred_clearance_m ({checked['preferred_clearance_m']}) "
                         f"must exceed robot_radius_m + safety_margin_m ({inflation:.3f})")
    return checked


class Planner:
    """Plans paths on one world; the grid and its costs are built once, in the constructor.

    Implements amr_common.plugins.interfaces.Planner (plan() returns a Plan: its points and
    figures).
    """

    def __init__(self, world: World, grid: OccupancyGrid | None = None, **params: Any) -> None:
        """Build the grid costs of `world`.

        grid: a prebuilt OccupancyGrid of it at resolution_m (else built); params: names of
        `parameter_descriptions()`.
        """
        p = check_parameters(params)
        self.params = p
        self.world = world
        self.segments = world.segments
        if grid is None or abs(grid.resolution - p["resolution_m"]) > 1e-12:
            grid = OccupancyGrid.from_world(world, p["resolution_m"])
        self.grid = grid
        self.inflation_radius = p["robot_radius_m"] + p["safety_margin_m"]
        clearance = grid.clearance
        missing = np.clip((p["preferred_clearance_m"] - clearance)
                          / (p["preferred_clearance_m"] - self.inflation_radius), 0.0, None)
        cost = 1.0 + p["clearance_weight"] * missing ** 2
        cost[clearance < self.inflation_radius] = np.inf
        self.cost = np.ascontiguousarray(cost.ravel())
        self._moves = search.allowed_moves(np.isfinite(cost))
        self._offsets = search.move_offsets(grid.width)
        n = self.cost.shape[0]
        self._came_from = np.empty(n, dtype=np.int64)
        self._g = np.empty(n, dtype=np.float64)
        self._lists = None  # the grid as Python lists, for the plain-Python reference search

    @staticmethod
    def parameter_descriptions() -> dict[str, tuple[Any, str]]:
        """Each tuning parameter: name -> (default, description with units)."""
        return dict(PARAMETERS)

    def describe(self) -> str:
        """One line for logs: the grid, the search and the inflation."""
        grid = self.grid
        return (f"{grid.width} x {grid.height} cells of {grid.resolution} m, "
                f"{self.params['algorithm']}, walls inflated by {self.inflation_radius:.3f} m")

    def warm_up(self) -> None:
        """Run every compiled kernel once on tiny inputs.

        numba compiles (or loads from its cache) on the first call, which must not happen inside
        a lockstep loop.
        """
        cell = int(np.argmax(self.cost < np.inf))
        for algorithm in ALGORITHMS:
            self.search(cell, cell, algorithm=algorithm)
        x, y = self.grid.cell_centre(*divmod(cell, self.grid.width))
        bend = np.array([[x, y], [x + 0.01, y], [x + 0.01, y + 0.01]])
        smoothing.simplify(self.segments, bend, 0.2, 0.1, 0.01, 0.01)
        smoothing.fillet_and_sample(self.segments, bend, 0.02, 0.05, 0.5, 0.2, 0.1, 0.01, 0.01)

    # --- planning ------------------------------------------------------------------------
    def plan(self, start: tuple[float, float], goal: tuple[float, float]) -> Plan:
        """A path from start (x, y) to goal (x, y); PlanningError if there is none."""
        began = time.perf_counter()
        p = self.params
        start = self._check_point(start, "start", may_touch=True)
        goal = self._check_point(goal, "goal", may_touch=False)
        start_cell = self._entry_cell(start, "start")
        goal_cell = self._entry_cell(goal, "goal")
        searched = time.perf_counter()
        cells, cost, expanded = self.search(start_cell, goal_cell)
        search_time = time.perf_counter() - searched
        if cells is None:
            raise PlanningError(
                f"goal ({goal[0]:.3f}, {goal[1]:.3f}) is unreachable from start "
                f"({start[0]:.3f}, {start[1]:.3f}): no traversable connection (walls inflated "
                f"by {self.inflation_radius:.3f} m); {expanded} cells searched")
        width = self.grid.width
        grid_path = self.grid.cell_centres(cells // width, cells % width)
        points = np.vstack([start, grid_path, goal])
        points = without_repeats(points)
        ds = 0.5 * self.grid.resolution
        if p["smooth"]:
            cap, floor, tol = (p["preferred_clearance_m"], self.inflation_radius,
                               p["clearance_tolerance_m"])
            corners = smoothing.simplify(self.segments, points, cap, floor, tol, ds)
            points = smoothing.fillet_and_sample(
                self.segments, corners, p["path_spacing_m"], p["min_turn_radius_m"],
                p["max_turn_radius_m"], cap, floor, tol, ds)
        clearance = self.world.clearances(points)
        length = polyline_length(points)
        return Plan(points=points, length_m=length, min_clearance_m=float(clearance.min()),
                    cost=cost, grid_path=grid_path, expanded=expanded,
                    search_time_s=search_time, total_time_s=time.perf_counter() - began,
                    algorithm=p["algorithm"])

    def search(self, start_cell: int, goal_cell: int, algorithm: str | None = None,
               heuristic_weight: float | None = None, compiled: bool = True):
        """Grid search between two traversable cells (flat indices).

        Returns (cells from start to goal or None if unreachable, path cost in metres, cells
        expanded). `compiled=False` runs the plain-Python functions (the reference).
        """
        algorithm = algorithm or self.params["algorithm"]
        weight = self.params["heuristic_weight"] if heuristic_weight is None else heuristic_weight
        width = self.grid.width
        if compiled:
            grid, came_from, g = (self.cost, self._moves, self._offsets), self._came_from, self._g
        else:  # plain Python on lists, its natural data (indexing numpy arrays is 3x slower)
            if self._lists is None:
                n = len(self.cost)
                self._lists = ((self.cost.tolist(), self._moves.tolist(), self._offsets.tolist()),
                               [-1] * n, [0.0] * n)
            grid, came_from, g = self._lists
        if algorithm == "astar":
            kernel = search.astar if compiled else search.astar_python
            expanded = kernel(*grid, width, int(start_cell), int(goal_cell), float(weight),
                              came_from, g)
        else:
            kernel = search.wavefront if compiled else search.wavefront_python
            expanded = kernel(*grid, int(start_cell), int(goal_cell), came_from, g)
        if not compiled:
            self._came_from[:], self._g[:] = came_from, g
        if not math.isfinite(self._g[goal_cell]):
            return None, math.inf, int(expanded)
        cells = search.trace_back(self._came_from, int(start_cell), int(goal_cell))
        return cells, float(self._g[goal_cell]) * self.grid.resolution, int(expanded)

    def cell_index(self, x: float, y: float) -> int:
        """Flat index of the cell containing (x, y) (PlanningError outside the grid)."""
        row, col = self.grid.cell_of(x, y)
        if not self.grid.contains_cell(row, col):
            raise PlanningError(f"({x:.3f}, {y:.3f}) is outside the map")
        return row * self.grid.width + col

    # --- start and goal ------------------------------------------------------------------
    def _check_point(self, point, what: str, may_touch: bool) -> tuple[float, float]:
        try:
            x, y = (float(v) for v in point)
        except (TypeError, ValueError):
            raise PlanningError(f"{what} must be (x, y), got {point!r}") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise PlanningError(f"{what} ({x}, {y}) is not finite")
        if not self.world.contains(x, y):
            raise PlanningError(f"{what} ({x:.3f}, {y:.3f}) is inside a wall or outside the "
                                f"map of world '{self.world.name}'")
        clearance = nearest_wall_kernel(self.segments, x, y)[0]
        if clearance < 1e-9:
            raise PlanningError(f"{what} ({x:.3f}, {y:.3f}) is on a wall")
        if not may_touch:  # a goal: the world's rule with this planner's inflation radius
            problem = self.world.goal_problem(x, y, what, min_clearance=self.inflation_radius)
            if problem is not None:
                raise PlanningError(problem)
        return x, y

    def _entry_cell(self, point: tuple[float, float], what: str) -> int:
        """The point's own cell if traversable, else the nearest traversable cell in reach.

        In reach: within the inflation radius, by a straight piece that keeps the point's own
        clearance up to the inflation radius (a start in the inflation gets out without coming
        closer to a wall; a goal, outside it, stays out).
        """
        x, y = point
        cell = self.cell_index(x, y)
        if math.isfinite(self.cost[cell]):
            return cell
        grid, reach = self.grid, self.inflation_radius + 2.0 * self.grid.resolution
        row, col = divmod(cell, grid.width)
        span = int(math.ceil(reach / grid.resolution))
        rows, cols = np.mgrid[max(row - span, 0):min(row + span + 1, grid.height),
                              max(col - span, 0):min(col + span + 1, grid.width)]
        rows, cols = rows.ravel(), cols.ravel()
        finite = np.isfinite(self.cost[rows * grid.width + cols])
        centres = grid.cell_centres(rows[finite], cols[finite])
        distance = np.hypot(centres[:, 0] - x, centres[:, 1] - y)
        need = min(self.inflation_radius, nearest_wall_kernel(self.segments, x, y)[0])
        for k in np.argsort(distance, kind="stable"):
            if distance[k] > reach:
                break
            cx, cy = centres[k]
            if smoothing._segment_clearance(self.segments, x, y, cx, cy,
                                            0.5 * grid.resolution) >= need - 1e-9:
                return int(rows[finite][k] * grid.width + cols[finite][k])
        raise PlanningError(f"{what} ({x:.3f}, {y:.3f}) is too close to a wall: no free cell "
                            f"within {reach:.3f} m reachable in a straight line")


__all__ = ["Planner", "Plan", "PlanningError", "PARAMETERS", "ALGORITHMS", "check_parameters"]
