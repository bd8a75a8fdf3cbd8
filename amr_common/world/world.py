"""Worlds for the simulator: walls as 2D line segments, named start poses and named goals.

`World.load(name_or_path)` reads a bundled world by name ("lab02") or a world YAML / the
course's map JSON / a Nav2 map YAML by path (the formats: amr_common/world/world_file.py), then
checks it against its walls: no zero-length wall; a boundary and holes that do not cross
themselves, holes inside the boundary (they may touch it); every start pose inside the boundary,
outside every obstacle and at least the robot radius from the walls; every goal at least
GOAL_CLEARANCE from them.

A map world (a Nav2 map YAML, or `World.from_raster` on a map SLAM built) keeps its cells in
`raster`: its free space is its free cells, its walls (`segments`) are the edges between free
and non-free cells (amr_common.world.map_raster.boundary_segments), and the occupancy grid of the
planner, the particle filter and /map is the map's own cells.

A world file's movers (amr_common.world.movers: round obstacles that walk) are in `movers`,
apart from the walls: the simulator moves them; the planner, the particle filter and /map never
see them.

A World answers the geometric questions of the simulator, the planner, the filter and the
metrics: clearances, free space, start and goal poses, the coverage grid.

The one clearance rule for goals (the run scripts, evaluate's worlds and the planner use it):
a goal keeps the robot radius plus SAFETY_MARGIN from every wall, the planner's inflated walls,
so a path to it never leaves the planner's free space. A start only needs the robot to fit.

Every problem (missing file, unknown name, bad YAML/JSON, missing keys, non-numeric or non-finite
coordinates, polylines with too few points, zero-length walls, self-crossing polygons, holes
outside or across the boundary, start poses or goals outside the boundary, inside an obstacle
or too close to a wall, a mover's bad values or a path leaving the boundary) raises WorldError
naming the file.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from amr_common.robot import ROBOT_RADIUS
from amr_common.world.coverage_grid import CoverageGrid, build_coverage_grid, inside_polygon_points
from amr_common.world.map_file import map_from_yaml
from amr_common.world.map_raster import OCCUPIED, UNKNOWN, Raster, boundary_segments
from amr_common.world.movers import Mover
from amr_common.world.polygons import (
    check_movers,
    check_polygons,
    closed_segments,
    point_in_polygon,
    squared_segment_distances,
)
from amr_common.world.raster_raycast import MarchGrid, SegmentGrid
from amr_common.world.raycast import clearances_into
from amr_common.world.world_file import (
    WORLDS_DIR,
    WorldError,
    WorldFile,
    bundled_worlds,
    point_value,
    pose_value,
    read_world_file,
)

MARCH_ABOVE_SEGMENTS = 300  # map worlds with more wall segments are ray-marched (march_grid)
# Worlds with more wall segments answer clearances, and the simulator's contacts, from their
# walls in buckets (wall_grid) instead of testing every wall.
BUCKETS_ABOVE_SEGMENTS = 1000
# Paths and goals keep the robot radius plus this margin from every wall: the planner's
# inflated walls (its safety_margin_m default) and the goals the run scripts accept.
SAFETY_MARGIN = 0.03  # m
GOAL_CLEARANCE = ROBOT_RADIUS + SAFETY_MARGIN  # 0.135 m


@dataclass
class World:
    """Walls as (N, 4) segments, named starts, an optional goal, and geometric queries."""

    name: str
    source: str
    segments: np.ndarray  # (N, 4) float64 rows [x1, y1, x2, y2], metres
    starts: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    goal: tuple[float, float] | None = None  # the default goal (the `goal` key or the first named)
    cell_size: float = 0.4
    description: str = ""
    boundary: np.ndarray | None = None  # (K, 2) outer closed polyline
    holes: list[np.ndarray] = field(default_factory=list)  # closed obstacle polylines
    grid_origin: tuple[float, float] | None = None  # None: the boundary's lower-left corner
    _grids: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    goals: dict[str, tuple[float, float]] = field(default_factory=dict)  # named goals
    raster: Raster | None = None  # a map world's cells (free: value 0), else None
    movers: tuple[Mover, ...] = ()  # round obstacles that walk: the simulated world only

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, name_or_path: str | Path) -> "World":
        """Load a bundled world by name ("lab02") or a .yaml/.yml/.json file by path."""
        spec = read_world_file(name_or_path)
        if isinstance(spec, WorldFile):
            return cls._from_file(spec)
        spec = map_from_yaml(spec.data, spec.path)  # a Nav2 map YAML: its keys and image
        return cls.from_raster(spec.raster, name=spec.name, source=str(spec.path),
                               starts=spec.starts, goals=spec.goals, goal=spec.goal,
                               cell_size=spec.cell_size, description=spec.description,
                               grid_origin=spec.grid_origin)

    @classmethod
    def from_raster(cls, raster: Raster, name: str = "map", source: str = "map",
                    starts: dict | None = None, goals: dict | None = None,
                    goal: tuple[float, float] | None = None, **extras) -> "World":
        """The world of a map: free cells (value 0) are free space, every other cell is wall.

        `extras`: cell_size, description, grid_origin. Raises WorldError (naming `source`) for
        a map without a free cell and for named goals off the free space. A map's named starts
        (this project's keys, written by SLAM or world_to_map.py) are checked when one is used
        (resolve_start): a start the map's cells cannot take leaves the map readable, and
        another start pose overrides it.
        """
        if not (raster.values == 0).any():
            raise WorldError(f"{source}: the map has no free cell")
        world = cls(name=name, source=source, segments=boundary_segments(raster),
                    starts=dict(starts or {}), goal=goal, goals=dict(goals or {}),
                    raster=raster, **extras)
        world._check_named_poses(starts=False)
        return world

    @classmethod
    def _from_file(cls, spec: WorldFile) -> "World":
        """The World of a parsed world file, checked against its walls (WorldError if not)."""
        path = spec.path
        segs = [closed_segments(spec.boundary)] + [closed_segments(h) for h in spec.holes]
        segs += [np.hstack([w[:-1], w[1:]]) for w in spec.walls]
        segments = np.ascontiguousarray(np.vstack(segs), dtype=np.float64)
        lengths = np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1])
        bad = np.flatnonzero(lengths < 1e-9)
        if bad.size:
            x1, y1 = segments[bad[0], :2]
            raise WorldError(f"{path}: zero-length wall at ({x1:g}, {y1:g}) (repeated point in "
                             f"a polyline)")
        check_polygons(spec)
        check_movers(spec)
        world = cls(name=spec.name, source=str(path), segments=segments, starts=spec.starts,
                    goal=spec.goal, cell_size=spec.cell_size, description=spec.description,
                    boundary=spec.boundary, holes=spec.holes, goals=dict(spec.goals),
                    grid_origin=spec.grid_origin, movers=spec.movers)
        world._check_named_poses()
        return world

    def _check_named_poses(self, starts: bool = True) -> None:
        for start_name, pose in self.starts.items() if starts else ():
            self._check_pose(pose, f"start '{start_name}'")
        for goal_name, point in self.goals.items():
            self._check_goal(point, f"goal '{goal_name}'")
        if self.goal is not None:
            self._check_goal(self.goal, "goal")

    # ------------------------------------------------------------------ geometry
    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of all walls, metres."""
        s = self.segments
        return (float(min(s[:, 0].min(), s[:, 2].min())), float(min(s[:, 1].min(), s[:, 3].min())),
                float(max(s[:, 0].max(), s[:, 2].max())), float(max(s[:, 1].max(), s[:, 3].max())))

    @property
    def march_grid(self) -> MarchGrid | None:
        """A map world's cells for grid ray marching when that beats its segments, else None.

        Marching a 360-ray scan through 2 cm cells costs about as much as casting it against
        ~180 segments in lab02, ~300 in roomier worlds (scripts/bench_map_world.py); a converted
        world has tens of segments, a SLAM map thousands.
        """
        if self.raster is None or len(self.segments) <= MARCH_ABOVE_SEGMENTS:
            return None
        if "march" not in self._grids:
            self._grids["march"] = MarchGrid.from_raster(self.raster)
        return self._grids["march"]

    @property
    def wall_grid(self) -> SegmentGrid | None:
        """The walls listed by buckets (raster_raycast.SegmentGrid) when there are many, else None.

        More than BUCKETS_ABOVE_SEGMENTS: a SLAM map's specks and ragged walls (a noisy 20 x 20 m
        map at 2 cm: ~40,000, the largest map allowed up to ~2 million).
        """
        if len(self.segments) <= BUCKETS_ABOVE_SEGMENTS:
            return None
        if "buckets" not in self._grids:
            self._grids["buckets"] = SegmentGrid.build(self.segments)
        return self._grids["buckets"]

    def clearance(self, x: float, y: float) -> float:
        """Distance (m) from the point (x, y) to the nearest wall segment."""
        return float(np.sqrt(squared_segment_distances(self.segments, float(x), float(y)).min()))

    def clearances(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point of a (K, 2) array to the nearest wall."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        if self.wall_grid is not None:  # the same distances, from the walls near each point
            return self.wall_grid.clearances(pts)
        out = np.empty(len(pts))
        clearances_into(self.segments, pts, out)
        return out

    def contains(self, x: float, y: float) -> bool:
        """True if (x, y) is inside the boundary and outside every hole."""
        return bool(self.contains_points(np.array([[x, y]], dtype=np.float64))[0])

    def contains_points(self, points: np.ndarray) -> np.ndarray:
        """(K,) bool: which points of a (K, 2) array are in the free space (see contains).

        Each hole is tested only against the points within its bounding box. A map world: the
        points in free cells.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if self.raster is not None:
            return self.raster.free_at(pts)
        inside = inside_polygon_points(self.boundary, pts) if self.boundary is not None else \
            np.ones(len(pts), dtype=bool)
        if not self.holes:
            return inside
        if "hole_boxes" not in self._grids:
            self._grids["hole_boxes"] = np.array(
                [[*h.min(axis=0), *h.max(axis=0)] for h in self.holes])
        boxes = self._grids["hole_boxes"]
        x, y = pts[:, 0:1], pts[:, 1:2]
        candidates = ((x >= boxes[:, 0]) & (x <= boxes[:, 2]) & (y >= boxes[:, 1])
                      & (y <= boxes[:, 3]) & inside[:, None])
        for hole_index in np.flatnonzero(candidates.any(axis=0)):
            rows = np.flatnonzero(candidates[:, hole_index])
            inside[rows] &= ~inside_polygon_points(self.holes[hole_index], pts[rows])
        return inside

    def resolve_start(self, start: str | tuple | list | np.ndarray | None,
                      what: str = "start") -> tuple[float, float, float]:
        """A start pose from a name, an (x, y, theta) triple or None (= the first named start).

        `what` names the pose in errors (e.g. "kidnap pose"): the robot must fit there.
        """
        if start is None:
            if not self.starts:
                raise WorldError(f"{self.source}: the world names no start pose; pass "
                                 f"(x, y, theta)")
            start = next(iter(self.starts))
        if isinstance(start, str):
            if start not in self.starts:
                raise WorldError(f"{self.source}: unknown start '{start}' (named starts: "
                                 f"{', '.join(self.starts) or 'none'})")
            if self.raster is not None:  # a map's start is checked when used (from_raster)
                problem = self.pose_problem(*self.starts[start][:2], what=f"start '{start}'")
                if problem is not None:
                    raise WorldError(f"{self.source}: {problem}: give a start pose (x, y, "
                                     "theta) where the robot fits on this map instead")
            return self.starts[start]
        pose = pose_value(list(start) if not isinstance(start, list) else start, self.source,
                          what)
        self._check_pose(pose, what)
        return pose

    def resolve_goal(self, goal: str | tuple | list | np.ndarray | None) -> tuple[float, float]:
        """A goal position from a name of `goals`, "x,y" text, an (x, y) pair or None.

        None is the world's default goal. Raises WorldError if the goal is unknown, malformed,
        outside the free space or closer to a wall than GOAL_CLEARANCE.
        """
        if goal is None:
            if self.goal is None:
                raise WorldError(f"{self.source}: the world has no goal; pass x,y or a name")
            return self.goal
        if isinstance(goal, str):
            if goal in self.goals:
                return self.goals[goal]
            parts = goal.split(",")
            try:
                goal = [float(p) for p in parts] if len(parts) == 2 else None
            except ValueError:
                goal = None
            if goal is None:
                raise WorldError(f"{self.source}: goal is neither a named goal ("
                                 f"{', '.join(self.goals) or 'none'}) nor 'x,y'")
        point = point_value(list(goal), self.source, "goal")
        self._check_goal(point, "goal")
        return point

    def goal_problem(self, x: float, y: float, what: str = "goal",
                     min_clearance: float = GOAL_CLEARANCE) -> str | None:
        """Why (x, y) cannot be a goal, or None.

        Outside the free space or within `min_clearance` of a wall (the planner passes its own
        inflation radius).
        """
        problem = self.pose_problem(x, y, what)
        if problem is None and (c := self.clearance(x, y)) < min_clearance:
            problem = (f"{what} ({x:g}, {y:g}) is too close to a wall: clearance {c:.3f} m < "
                       f"{min_clearance:.3f} m (robot radius + safety margin: a path there "
                       f"would leave the planner's free space)")
        return problem

    def _check_goal(self, point: tuple[float, float], what: str) -> None:
        problem = self.goal_problem(*point, what=what)
        if problem is not None:
            raise WorldError(f"{self.source}: {problem}")

    def _check_pose(self, pose: tuple[float, float, float], what: str) -> None:
        problem = self.pose_problem(pose[0], pose[1], what)
        if problem is not None:
            raise WorldError(f"{self.source}: {problem}")

    def pose_problem(self, x: float, y: float, what: str = "pose") -> str | None:
        """Why the robot cannot stand at (x, y), or None."""
        if self.raster is not None and not self.contains(x, y):
            return f"{what} ({x:g}, {y:g}) is {self._cell_problem(x, y)}"
        xmin, ymin, xmax, ymax = self.bounds
        # Beyond every wall first: the polygon tests would overflow on huge coordinates.
        beyond = not (xmin <= x <= xmax and ymin <= y <= ymax)
        if self.boundary is not None and (beyond or not point_in_polygon(self.boundary, x, y)):
            return f"{what} ({x:g}, {y:g}) is outside the boundary"
        if beyond:
            return f"{what} ({x:g}, {y:g}) is outside the map"
        if not self.contains(x, y):  # inside a hole: name it
            for i, hole in enumerate(self.holes):
                if point_in_polygon(hole, x, y):
                    return f"{what} ({x:g}, {y:g}) is inside obstacle holes[{i}]"
        c = self.clearance(x, y)
        if c < ROBOT_RADIUS:
            return (f"{what} ({x:g}, {y:g}) touches a wall: clearance {c:.3f} m < robot radius "
                    f"{ROBOT_RADIUS} m")
        return None

    def _cell_problem(self, x: float, y: float) -> str:
        """Where a point off a map world's free cells is: off the map, or in which wall cell."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return "outside the map"
        row, col = self.raster.cell_of(x, y)
        if not self.raster.contains_cell(row, col):
            return "outside the map"
        value = int(self.raster.values[row, col])
        kind = {OCCUPIED: "an occupied cell", UNKNOWN: "an unknown cell"}.get(
            value, f"a cell of value {value}")
        return f"inside a wall of the map ({kind}: every cell that is not free is a wall)"

    def coverage_grid(self, margin: float = ROBOT_RADIUS) -> CoverageGrid:
        """The cell_size grid behind the coverage metrics (amr_common.world.coverage_grid).

        Computed once per margin. Raises GridTooLargeError if it would have too many cells.
        """
        key = ("grid", float(margin))
        if key not in self._grids:
            grid = build_coverage_grid(
                self.segments, self.boundary, self.holes, self.cell_size, self.grid_origin,
                float(margin), source=self.source,
                clearances=None if self.wall_grid is None else self.wall_grid.clearances)
            if self.raster is not None:  # no boundary: the free cells say what is inside
                gx, gy = np.meshgrid(grid.x_centres, grid.y_centres)
                inside = self.raster.free_at(np.column_stack([gx.ravel(), gy.ravel()]))
                grid = replace(grid, free=grid.free & inside.reshape(grid.free.shape))
            self._grids[key] = grid
        return self._grids[key]

    def free_cells(self, margin: float = ROBOT_RADIUS) -> np.ndarray:
        """Centres (K, 2) of the cell_size grid cells in the free space with clearance > margin.

        Row by row. The grid lines pass through `grid_origin` (default: the boundary's
        lower-left corner), so corridors that start at the boundary have their cells centred
        in them.
        """
        return self.coverage_grid(margin).free_centres()

    def free_space_centroid(self) -> tuple[float, float]:
        """Mean of the free cells (the bounds' centre if there are none)."""
        cells = self.free_cells()
        if len(cells) == 0:
            xmin, ymin, xmax, ymax = self.bounds
            return (0.5 * (xmin + xmax), 0.5 * (ymin + ymax))
        c = cells.mean(axis=0)
        return (float(c[0]), float(c[1]))


# ---------------------------------------------------------------------- helpers
def parse_start(text: str) -> str | tuple[float, float, float] | None:
    """A start as a user types it: a name, 'x,y,theta' or '' (the world's first start).

    'name' -> name, 'x,y,theta' -> three floats (m, m, rad), '' -> None. ValueError for a
    malformed pose.
    """
    text = text.strip()
    if not text:
        return None
    if "," not in text:
        return text
    try:
        values = tuple(float(part) for part in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"start '{text}' is neither a start name nor 'x,y,theta' "
                         "with three finite numbers")
    return values


def start_label(start: str | tuple | list | None) -> str:
    """How a start is named in reports and file names: 'outer', or '1,-1,1.57' for a pose."""
    if start is None or isinstance(start, str):
        return start or ""
    return ",".join(f"{float(v):g}" for v in start)


def map_label(name: str, source: str) -> str:
    """A world's or map's name for titles and legends: its name, or its folder and file.

    The folder and file ('lab02/map.yaml') for a map named 'map': a saved map's DIR/map.yaml
    (map_saver's habit), which would read 'map map'.
    """
    path = Path(source)
    if name != "map" or path.suffix.lower() not in (".yaml", ".yml"):
        return name
    return f"{path.parent.name}/{path.name}" if path.parent.name else path.name


# WorldError, bundled_worlds and WORLDS_DIR live in world_file.py; they are imported from here.
__all__ = ["GOAL_CLEARANCE", "SAFETY_MARGIN", "WORLDS_DIR", "World", "WorldError",
           "bundled_worlds", "map_label", "parse_start", "start_label"]
