"""Worlds for the simulator: walls as 2D line segments, named start poses and named goals.

Two file formats load with `World.load(name_or_path)`:

1. The project's own YAML world file (bundled ones live in amr_common/worlds/<name>.yaml and
   load by name, e.g. `World.load("lab02")`; any other file loads by path)::

       name: lab02               # optional, defaults to the file stem
       description: free text    # optional
       cell_size: 0.4            # m, > 0: grid used by coverage metrics (corridor pitch)
       grid_origin: [x, y]       # optional: a point the coverage grid lines pass through
                                 # (default: the boundary's lower-left corner)
       boundary: [[x, y], ...]   # REQUIRED closed polyline: the outer walls (>= 3 points)
       holes:                    # optional closed polylines: obstacles (>= 3 points each)
         - [[x, y], ...]
       walls:                    # optional open polylines: free-standing walls (>= 2 points)
         - [[x, y], ...]
       starts:                   # optional named start poses [x, y, theta]
         outer: [1.0, -1.0, pi/2]  # theta in rad: a number or "pi", "pi/2", "3*pi/2", "-pi/4"
       goals:                    # optional named goals [x, y] (navigation targets)
         far_corner: [-1.0, 1.0]
       goal: far_corner          # optional default goal: [x, y] or a name of `goals`;
                                 # without it the first named goal is the default

   Coordinates are metres in the world frame (REP 103: x east, y north, theta CCW from x).
   A closed polyline may repeat its first point at the end; it is closed either way.
   Numbers may be written 1e-6 (YAML 1.1 alone would read that as a string).

2. The course's map JSON, by path: `{"metric": {"boundary": [[x, y], ...], "holes": [[[x, y],
   ...], ...]}}` (boundary = outer closed polyline, each hole = a closed obstacle polyline).
   It has no starts; pass a start pose (x, y, theta) explicitly. Its coverage grid (0.4 m)
   starts at the boundary's lower-left corner.

Every problem (missing file, unknown name, bad YAML/JSON, missing keys, non-numeric or non-finite
coordinates, polylines with too few points, zero-length walls, start poses or goals outside the
boundary, inside an obstacle or closer to a wall than the robot radius) raises WorldError naming
the file.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .coverage_grid import CoverageGrid, build_coverage_grid, inside_polygon_points
from .raycast import clearances_into
from .robot import ROBOT_RADIUS

WORLDS_DIR = Path(__file__).resolve().parent / "worlds"

_PI_EXPR = re.compile(r"^\s*([+-]?)\s*(\d+(?:\.\d*)?)?\s*\*?\s*pi\s*(?:/\s*(\d+(?:\.\d*)?))?\s*$")


class _WorldYamlLoader(yaml.SafeLoader):
    """yaml.SafeLoader that also reads floats without a dot (1e-6, -2E3) as numbers.

    YAML 1.2 reads them as numbers, YAML 1.1 (PyYAML) as strings.
    """


_WorldYamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


class WorldError(ValueError):
    """A world file is missing or malformed, or a start pose is invalid.

    The message names the file.
    """


def bundled_worlds() -> list[str]:
    """Names of the worlds shipped with amr_sim (loadable with World.load(name))."""
    return sorted(p.stem for p in WORLDS_DIR.glob("*.yaml"))


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

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, name_or_path: str | Path) -> "World":
        """Load a bundled world by name ("lab02") or a .yaml/.yml/.json file by path."""
        text = str(name_or_path)
        path = Path(text).expanduser()
        looks_like_path = (path.suffix.lower() in (".yaml", ".yml", ".json") or "/" in text
                           or path.is_file())
        if not looks_like_path:
            bundled = WORLDS_DIR / f"{text}.yaml"
            if not bundled.is_file():
                raise WorldError(
                    f"unknown world '{text}': not a bundled world (bundled: "
                    f"{', '.join(bundled_worlds())}) and not a .yaml/.json file path")
            path = bundled
        if not path.is_file():
            raise WorldError(f"{path}: world file not found")
        try:
            raw = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise WorldError(f"{path}: cannot read world file: {exc}") from exc
        if path.suffix.lower() == ".json":
            return cls._from_course_json(raw, path)
        return cls._from_yaml(raw, path)

    @classmethod
    def _from_yaml(cls, raw: str, path: Path) -> "World":
        try:
            data = yaml.load(raw, Loader=_WorldYamlLoader)
        except yaml.YAMLError as exc:
            raise WorldError(f"{path}: invalid YAML: {exc}") from exc
        if not isinstance(data, dict):
            raise WorldError(f"{path}: expected a mapping with keys boundary, holes, walls, "
                             f"starts, ...")
        known = {"name", "description", "cell_size", "grid_origin", "boundary", "holes", "walls",
                 "starts", "goal", "goals"}
        unknown = set(data) - known
        if unknown:
            raise WorldError(f"{path}: unknown key(s) {sorted(unknown)}; allowed: {sorted(known)}")
        if "boundary" not in data:
            raise WorldError(f"{path}: missing key 'boundary' (the outer closed polyline)")
        boundary = _polyline(data["boundary"], path, "boundary", closed=True)
        holes = [_polyline(h, path, f"holes[{i}]", closed=True)
                 for i, h in enumerate(_as_list(data.get("holes", []), path, "holes"))]
        walls = [_polyline(w, path, f"walls[{i}]", closed=False)
                 for i, w in enumerate(_as_list(data.get("walls", []), path, "walls"))]
        cell_size = _positive_number(data.get("cell_size", 0.4), path, "cell_size")
        grid_origin = None
        if data.get("grid_origin") is not None:
            grid_origin = _point(data["grid_origin"], path, "grid_origin")
        starts_raw = data.get("starts", {}) or {}
        if not isinstance(starts_raw, dict):
            raise WorldError(f"{path}: 'starts' must be a mapping name: [x, y, theta]")
        starts = {str(k): _pose(v, path, f"starts.{k}") for k, v in starts_raw.items()}
        goals_raw = data.get("goals", {}) or {}
        if not isinstance(goals_raw, dict):
            raise WorldError(f"{path}: 'goals' must be a mapping name: [x, y]")
        goals = {str(k): _point(v, path, f"goals.{k}") for k, v in goals_raw.items()}
        goal = next(iter(goals.values()), None)
        if isinstance(data.get("goal"), str):
            if data["goal"] not in goals:
                raise WorldError(f"{path}: goal '{data['goal']}' is not a name of 'goals' "
                                 f"({', '.join(goals) or 'none'})")
            goal = goals[data["goal"]]
        elif data.get("goal") is not None:
            goal = _point(data["goal"], path, "goal")
        name = str(data.get("name") or path.stem)
        world = cls._build(name, path, boundary, holes, walls, starts, goal, cell_size,
                           str(data.get("description") or ""), goals)
        world.grid_origin = grid_origin
        return world

    @classmethod
    def _from_course_json(cls, raw: str, path: Path) -> "World":
        try:
            data = json.loads(raw)
        except json.JSONDecodeError as exc:
            raise WorldError(f"{path}: invalid JSON: {exc}") from exc
        if not isinstance(data, dict) or not isinstance(data.get("metric"), dict):
            raise WorldError(f"{path}: missing key 'metric' (expected "
                             f"{{\"metric\": {{\"boundary\": ..., \"holes\": ...}}}})")
        metric = data["metric"]
        if "boundary" not in metric:
            raise WorldError(f"{path}: missing key 'metric.boundary'")
        boundary = _polyline(metric["boundary"], path, "metric.boundary", closed=True)
        holes = [_polyline(h, path, f"metric.holes[{i}]", closed=True)
                 for i, h in enumerate(_as_list(metric.get("holes", []), path, "metric.holes"))]
        return cls._build(path.stem, path, boundary, holes, [], {}, None, 0.4, "course map JSON")

    @classmethod
    def _build(cls, name, path, boundary, holes, walls, starts, goal, cell_size,
               description, goals=None) -> "World":
        segs = [_closed_segments(boundary)] + [_closed_segments(h) for h in holes]
        segs += [np.hstack([w[:-1], w[1:]]) for w in walls]
        segments = np.ascontiguousarray(np.vstack(segs), dtype=np.float64)
        lengths = np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1])
        bad = np.flatnonzero(lengths < 1e-9)
        if bad.size:
            x1, y1 = segments[bad[0], :2]
            raise WorldError(f"{path}: zero-length wall at ({x1:g}, {y1:g}) (repeated point in "
                             f"a polyline)")
        world = cls(name=name, source=str(path), segments=segments, starts=starts, goal=goal,
                    cell_size=cell_size, description=description, boundary=boundary, holes=holes,
                    goals=dict(goals or {}))
        for start_name, pose in starts.items():
            world._check_pose(pose, f"start '{start_name}'")
        for goal_name, point in world.goals.items():
            world._check_pose((*point, 0.0), f"goal '{goal_name}'")
        if goal is not None:
            world._check_pose((*goal, 0.0), "goal")
        return world

    # ------------------------------------------------------------------ geometry
    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of all walls, metres."""
        s = self.segments
        return (float(min(s[:, 0].min(), s[:, 2].min())), float(min(s[:, 1].min(), s[:, 3].min())),
                float(max(s[:, 0].max(), s[:, 2].max())), float(max(s[:, 1].max(), s[:, 3].max())))

    def clearance(self, x: float, y: float) -> float:
        """Distance (m) from the point (x, y) to the nearest wall segment."""
        return float(np.sqrt(_squared_distances(self.segments, float(x), float(y)).min()))

    def clearances(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point of a (K, 2) array to the nearest wall."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        out = np.empty(len(pts))
        clearances_into(self.segments, pts, out)
        return out

    def contains(self, x: float, y: float) -> bool:
        """True if (x, y) is inside the boundary and outside every hole."""
        return bool(self.contains_points(np.array([[x, y]], dtype=np.float64))[0])

    def contains_points(self, points: np.ndarray) -> np.ndarray:
        """(K,) bool: which points of a (K, 2) array are in the free space (see contains).

        Each hole is tested only against the points within its bounding box.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
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

    def resolve_start(self, start: str | tuple | list | np.ndarray | None
                      ) -> tuple[float, float, float]:
        """A start pose from a name, an (x, y, theta) triple or None (= the first named start)."""
        if start is None:
            if not self.starts:
                raise WorldError(f"{self.source}: the world names no start pose; pass "
                                 f"(x, y, theta)")
            return next(iter(self.starts.values()))
        if isinstance(start, str):
            if start not in self.starts:
                raise WorldError(f"{self.source}: unknown start '{start}' (named starts: "
                                 f"{', '.join(self.starts) or 'none'})")
            return self.starts[start]
        pose = _pose(list(start) if not isinstance(start, list) else start, self.source, "start")
        self._check_pose(pose, "start")
        return pose

    def resolve_goal(self, goal: str | tuple | list | np.ndarray | None) -> tuple[float, float]:
        """A goal position from a name of `goals`, "x,y" text, an (x, y) pair or None.

        None is the world's default goal. Raises WorldError if the goal is unknown, malformed,
        outside the free space or closer to a wall than the robot radius.
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
        point = _point(list(goal), self.source, "goal")
        self._check_pose((*point, 0.0), "goal")
        return point

    def _check_pose(self, pose: tuple[float, float, float], what: str) -> None:
        x, y, _ = pose
        if self.boundary is not None and not _point_in_polygon(self.boundary, x, y):
            raise WorldError(f"{self.source}: {what} ({x:g}, {y:g}) is outside the boundary")
        if not self.contains(x, y):  # inside a hole: name it
            for i, hole in enumerate(self.holes):
                if _point_in_polygon(hole, x, y):
                    raise WorldError(f"{self.source}: {what} ({x:g}, {y:g}) is inside obstacle "
                                     f"holes[{i}]")
        c = self.clearance(x, y)
        if c < ROBOT_RADIUS:
            raise WorldError(f"{self.source}: {what} ({x:g}, {y:g}) touches a wall: clearance "
                             f"{c:.3f} m < robot radius {ROBOT_RADIUS} m")

    def coverage_grid(self, margin: float = ROBOT_RADIUS) -> CoverageGrid:
        """The cell_size grid behind the coverage metrics (amr_common.coverage_grid).

        Computed once per margin. Raises GridTooLargeError if it would have too many cells.
        """
        key = ("grid", float(margin))
        if key not in self._grids:
            self._grids[key] = build_coverage_grid(
                self.segments, self.boundary, self.holes, self.cell_size, self.grid_origin,
                float(margin), source=self.source)
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


def _squared_distances(seg: np.ndarray, px, py) -> np.ndarray:
    """Squared point-segment distances; px, py scalars or (K, 1) columns -> (N,) or (K, N)."""
    x1, y1, x2, y2 = seg[:, 0], seg[:, 1], seg[:, 2], seg[:, 3]
    ex, ey = x2 - x1, y2 - y1
    t = np.clip(((px - x1) * ex + (py - y1) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
    dx, dy = x1 + t * ex - px, y1 + t * ey - py
    return dx * dx + dy * dy


def _point_in_polygon(poly: np.ndarray, x: float, y: float) -> bool:
    """Even-odd ray crossing test."""
    return bool(inside_polygon_points(poly, np.array([[x, y]], dtype=np.float64))[0])


def _closed_segments(poly: np.ndarray) -> np.ndarray:
    return np.hstack([poly, np.roll(poly, -1, axis=0)])


def _as_list(value: Any, path, what: str) -> list:
    if value is None:
        return []
    if not isinstance(value, list):
        raise WorldError(f"{path}: '{what}' must be a list of polylines")
    return value


def _number(value: Any, path, what: str) -> float:
    if isinstance(value, bool):
        raise WorldError(f"{path}: {what} must be a number, got {value!r}")
    if isinstance(value, str):
        m = _PI_EXPR.match(value)
        if not m:
            raise WorldError(f"{path}: {what} must be a number, got {value!r}")
        sign, num, den = m.groups()
        out = (float(num) if num else 1.0) * math.pi / (float(den) if den else 1.0)
        return -out if sign == "-" else out
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise WorldError(f"{path}: {what} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise WorldError(f"{path}: {what} is not finite ({value!r})")
    return out


def _coordinate(value: Any, path, what: str) -> float:
    if isinstance(value, str):  # pi expressions are for angles only
        raise WorldError(f"{path}: {what} must be a number, got {value!r}")
    return _number(value, path, what)


def _positive_number(value: Any, path, what: str) -> float:
    out = _coordinate(value, path, what)
    if out <= 0:
        raise WorldError(f"{path}: {what} must be > 0, got {value!r}")
    return out


def _point(value: Any, path, what: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise WorldError(f"{path}: {what} must be [x, y], got {value!r}")
    return (_coordinate(value[0], path, f"{what} x"), _coordinate(value[1], path, f"{what} y"))


def _pose(value: Any, path, what: str) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise WorldError(f"{path}: {what} must be [x, y, theta], got {value!r}")
    return (_coordinate(value[0], path, f"{what} x"), _coordinate(value[1], path, f"{what} y"),
            _number(value[2], path, f"{what} theta"))


def _polyline(value: Any, path, what: str, closed: bool) -> np.ndarray:
    if not isinstance(value, list):
        raise WorldError(f"{path}: '{what}' must be a list of [x, y] points, got "
                         f"{type(value).__name__}")
    pts = [_point(p, path, f"{what}[{i}]") for i, p in enumerate(value)]
    if closed and len(pts) >= 2 and pts[0] == pts[-1]:
        pts = pts[:-1]  # explicitly closed: the closing segment is implied
    need = 3 if closed else 2
    if len(pts) < need:
        kind = "closed" if closed else "open"
        raise WorldError(f"{path}: '{what}' has {len(pts)} point(s); a {kind} polyline needs "
                         f"at least {need}")
    return np.array(pts, dtype=np.float64)
