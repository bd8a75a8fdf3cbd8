"""World files: the project's YAML worlds and the course's map JSON, read into a WorldFile.

Three file formats load with `World.load(name_or_path)` (through `read_world_file`); the third,
a Nav2 map_server map YAML (it has `image`, `resolution`, ...), is recognised here and handed on
as parsed YAML (a MapYaml): its keys and image are read by amr_common.world.map_file.

1. The project's own YAML world file (bundled ones live in amr_common/world/worlds/<name>.yaml and
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
       goals:                    # optional named goals [x, y] (navigation targets, >= 0.135 m
                                 # from every wall: amr_common.world.world.GOAL_CLEARANCE)
         far_corner: [-1.0, 1.0]
       goal: far_corner          # optional default goal: [x, y] or a name of `goals`;
                                 # without it the first named goal is the default
       movers:                   # optional round obstacles that walk
       (amr_common.world.movers):
         - {radius: 0.2, path: [[x, y], ...], speed: 0.4}  # back and forth along the path
         - {radius: 0.2, path: [[x, y], ...], speed: 0.3, loop: true, start_s: 5}

   Coordinates are metres in the world frame (REP 103: x east, y north, theta CCW from x).
   A closed polyline may repeat its first point at the end; it is closed either way.
   Numbers may be written 1e-6 (YAML 1.1 alone would read that as a string).
   Movers are the simulated world only: walls, /map, the planner and the filter never see
   them, and a world file given as a map (--map) has them dropped.

2. The course's map JSON, by path: `{"metric": {"boundary": [[x, y], ...], "holes": [[[x, y],
   ...], ...]}}` (boundary = outer closed polyline, each hole = a closed obstacle polyline).
   It has no starts; pass a start pose (x, y, theta) explicitly. Its coverage grid (0.4 m)
   starts at the boundary's lower-left corner.

3. A Nav2 map_server map YAML (`image`, `resolution`, `origin`, ...: what SLAM and map_saver
   write), by path: its free cells are the free space, every other cell is wall. It may carry
   the keys name, description, cell_size, grid_origin, starts, goals and goal as above (Nav2
   ignores them); scripts/world_to_map.py writes any world as one.

Every problem (missing file, unknown name, bad YAML/JSON, missing keys, non-numeric or non-finite
coordinates, polylines with too few points, zero-length walls, a boundary or hole that crosses
itself, a hole outside or across the boundary, start poses or goals outside the boundary, inside
an obstacle or too close to a wall, a mover with a bad radius, path, speed, loop or start_s, or
whose path leaves the boundary) raises WorldError naming the file (and the mover); the checks
against the
walls (polygons, starts within the robot radius, goals within the planner's inflation
GOAL_CLEARANCE = 0.135 m, no zero-length wall, movers' paths) are World's (amr_common.world.world).
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

from amr_common.world.movers import MAX_RADIUS, MAX_SPEED, MOVER_KEYS, Mover

WORLDS_DIR = Path(__file__).resolve().parent / "worlds"

_PI_EXPR = re.compile(r"^\s*([+-]?)\s*(\d+(?:\.\d*)?)?\s*\*?\s*pi\s*(?:/\s*(\d+(?:\.\d*)?))?\s*$")


class _WorldYamlLoader(yaml.SafeLoader):
    """yaml.SafeLoader that also reads floats without a dot (1e-6, -2E3) as numbers.

    YAML 1.2 reads them as numbers, YAML 1.1 (PyYAML) as strings.
    """


_WorldYamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


# The keys of a Nav2 map YAML (amr_common.world.map_file); a world YAML has none of them.
NAV2_MAP_KEYS = ("image", "mode", "resolution", "origin", "negate", "occupied_thresh",
                 "free_thresh")
# Keys a world YAML shares with a map YAML (a map's extras: amr_common.world.map_file).
PROJECT_KEYS = frozenset({"name", "description", "cell_size", "grid_origin", "starts", "goals",
                          "goal"})


class WorldError(ValueError):
    """A world file is missing or malformed, or a start pose is invalid.

    The message names the file.
    """


def bundled_worlds() -> list[str]:
    """Names of the worlds shipped with amr_sim (loadable with World.load(name))."""
    return sorted(p.stem for p in WORLDS_DIR.glob("*.yaml"))


@dataclass
class WorldFile:
    """What a world file says, each value parsed and checked on its own."""

    name: str
    path: Path
    boundary: np.ndarray  # (K, 2) outer closed polyline
    holes: list[np.ndarray] = field(default_factory=list)  # closed obstacle polylines
    walls: list[np.ndarray] = field(default_factory=list)  # open polylines
    starts: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    goals: dict[str, tuple[float, float]] = field(default_factory=dict)
    goal: tuple[float, float] | None = None  # the `goal` key, else the first named goal
    cell_size: float = 0.4
    description: str = ""
    grid_origin: tuple[float, float] | None = None
    movers: tuple[Mover, ...] = ()  # round obstacles that walk (amr_common.world.movers)


@dataclass(frozen=True)
class MapYaml:
    """A YAML with Nav2 map keys: a map parsed as YAML only (read by amr_common.world.map_file)."""

    path: Path
    data: dict[str, Any]


def read_world_file(name_or_path: str | Path) -> WorldFile | MapYaml:
    """Read a bundled world by name ("lab02") or a .yaml/.yml/.json file by path.

    A YAML with Nav2 map keys (`image`, `resolution`, ...) is a map: its MapYaml, whose keys
    and image amr_common.world.map_file reads (map_from_yaml).
    """
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
        return _from_course_json(raw, path)
    return _from_yaml(raw, path)


def _from_yaml(raw: str, path: Path) -> WorldFile | MapYaml:
    try:
        data = yaml.load(raw, Loader=_WorldYamlLoader)
    except yaml.YAMLError as exc:
        raise WorldError(f"{path}: invalid YAML: {' '.join(str(exc).split())}") from exc
    if isinstance(data, dict) and set(data) & set(NAV2_MAP_KEYS):  # a Nav2 map_server map
        return MapYaml(path, data)
    if not isinstance(data, dict):
        raise WorldError(f"{path}: expected a mapping with keys boundary, holes, walls, "
                         f"starts, ... (or a Nav2 map YAML with 'image')")
    known = {"boundary", "holes", "walls", "movers"} | PROJECT_KEYS
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
    return WorldFile(path=path, boundary=boundary, holes=holes, walls=walls,
                     movers=_movers(data.get("movers"), path),
                     **project_values(data, path))


def project_values(data: dict, path: Path) -> dict[str, Any]:
    """The keys a world YAML and a map YAML share (PROJECT_KEYS), parsed and checked.

    Returns name, description, cell_size, grid_origin, starts, goals and goal (the `goal` key,
    else the first named goal).
    """
    cell_size = positive_number(data.get("cell_size", 0.4), path, "cell_size")
    grid_origin = None
    if data.get("grid_origin") is not None:
        grid_origin = point_value(data["grid_origin"], path, "grid_origin")
    starts_raw = data.get("starts", {}) or {}
    if not isinstance(starts_raw, dict):
        raise WorldError(f"{path}: 'starts' must be a mapping name: [x, y, theta]")
    starts = {str(k): pose_value(v, path, f"starts.{k}") for k, v in starts_raw.items()}
    goals_raw = data.get("goals", {}) or {}
    if not isinstance(goals_raw, dict):
        raise WorldError(f"{path}: 'goals' must be a mapping name: [x, y]")
    goals = {str(k): point_value(v, path, f"goals.{k}") for k, v in goals_raw.items()}
    goal = next(iter(goals.values()), None)
    if isinstance(data.get("goal"), str):
        if data["goal"] not in goals:
            raise WorldError(f"{path}: goal '{data['goal']}' is not a name of 'goals' "
                             f"({', '.join(goals) or 'none'})")
        goal = goals[data["goal"]]
    elif data.get("goal") is not None:
        goal = point_value(data["goal"], path, "goal")
    return dict(name=str(data.get("name") or path.stem), starts=starts, goals=goals, goal=goal,
                cell_size=cell_size, description=str(data.get("description") or ""),
                grid_origin=grid_origin)


def _from_course_json(raw: str, path: Path) -> WorldFile:
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
    return WorldFile(name=path.stem, path=path, boundary=boundary, holes=holes,
                     description="course map JSON")


def _mover(value: Any, path: Path | str, index: int) -> Mover:
    """One entry of a world file's `movers`, checked on its own (WorldError naming it).

    Checks: a mapping with known keys; radius in (0, MAX_RADIUS]; a path of >= 1 finite
    [x, y] points; speed in [0, MAX_SPEED]; loop true/false; start_s finite and >= 0. Where it
    walks (inside the boundary): amr_common.world.polygons.check_movers.
    """
    what = f"movers[{index}]"
    if not isinstance(value, dict):
        raise WorldError(f"{path}: {what} must be a mapping with keys radius, path, speed "
                         f"(optional loop, start_s, name), got {value!r}")
    if isinstance(value.get("name"), str) and value["name"].strip():
        what = f"{what} ({value['name'].strip()})"
    unknown = sorted(set(map(str, value)) - set(MOVER_KEYS))
    if unknown:
        raise WorldError(f"{path}: {what}: unknown key(s) {unknown}; allowed: "
                         f"{list(MOVER_KEYS)}")
    for key in ("radius", "path", "speed"):
        if key not in value:
            raise WorldError(f"{path}: {what}: missing key '{key}'")
    radius = number_value(value["radius"], path, f"{what} radius")
    if not 0.0 < radius <= MAX_RADIUS:
        raise WorldError(f"{path}: {what}: radius must be in (0, {MAX_RADIUS:g}] m, got "
                         f"{value['radius']!r}")
    speed = number_value(value["speed"], path, f"{what} speed")
    if not 0.0 <= speed <= MAX_SPEED:
        raise WorldError(f"{path}: {what}: speed must be in [0, {MAX_SPEED:g}] m/s, got "
                         f"{value['speed']!r}")
    raw_path = value["path"]
    if not isinstance(raw_path, list) or not raw_path:
        raise WorldError(f"{path}: {what}: path must be a list of at least one [x, y] point, "
                         f"got {raw_path!r}")
    points = np.array([point_value(p, path, f"{what} path[{i}]") for i, p in
                       enumerate(raw_path)], dtype=np.float64)
    loop = value.get("loop", False)
    if not isinstance(loop, bool):
        raise WorldError(f"{path}: {what}: loop must be true or false, got {loop!r}")
    start_s = number_value(value.get("start_s", 0.0), path, f"{what} start_s")
    if start_s < 0.0:
        raise WorldError(f"{path}: {what}: start_s must be >= 0 s, got {value['start_s']!r}")
    name = str(value.get("name") or "").strip() or f"movers[{index}]"
    return Mover(name=name, radius=radius, path=points, speed=speed, loop=loop,
                 start_s=start_s, label=what)


def _movers(value: Any, path: Path | str) -> tuple[Mover, ...]:
    """A world file's `movers` list (None: none), each entry checked (_mover)."""
    if value is None:
        return ()
    if not isinstance(value, list):
        raise WorldError(f"{path}: 'movers' must be a list of {{radius, path, speed}} mappings")
    movers = tuple(_mover(v, path, i) for i, v in enumerate(value))
    names = [m.name for m in movers]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise WorldError(f"{path}: mover name(s) {twice} given twice: names must be unique")
    return movers


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


def number_value(value: Any, path, what: str) -> float:
    """A finite number (no pi expression); WorldError naming `path` and `what` if it is not."""
    if isinstance(value, str):  # pi expressions are for angles only
        raise WorldError(f"{path}: {what} must be a number, got {value!r}")
    return _number(value, path, what)


def positive_number(value: Any, path, what: str) -> float:
    """A finite number > 0; WorldError naming `path` and `what` if it is not."""
    out = number_value(value, path, what)
    if out <= 0:
        raise WorldError(f"{path}: {what} must be > 0, got {value!r}")
    return out


def point_value(value: Any, path, what: str) -> tuple[float, float]:
    """[x, y] as two finite floats; WorldError naming `path` and `what` if it is not."""
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise WorldError(f"{path}: {what} must be [x, y], got {value!r}")
    return (number_value(value[0], path, f"{what} x"), number_value(value[1], path, f"{what} y"))


def pose_value(value: Any, path, what: str) -> tuple[float, float, float]:
    """[x, y, theta] as three finite floats (theta may be "pi/2" etc.); WorldError if not."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise WorldError(f"{path}: {what} must be [x, y, theta], got {value!r}")
    return (number_value(value[0], path, f"{what} x"), number_value(value[1], path, f"{what} y"),
            _number(value[2], path, f"{what} theta"))


def _polyline(value: Any, path, what: str, closed: bool) -> np.ndarray:
    if not isinstance(value, list):
        raise WorldError(f"{path}: '{what}' must be a list of [x, y] points, got "
                         f"{type(value).__name__}")
    pts = [point_value(p, path, f"{what}[{i}]") for i, p in enumerate(value)]
    if closed and len(pts) >= 2 and pts[0] == pts[-1]:
        pts = pts[:-1]  # explicitly closed: the closing segment is implied
    need = 3 if closed else 2
    if len(pts) < need:
        kind = "closed" if closed else "open"
        raise WorldError(f"{path}: '{what}' has {len(pts)} point(s); a {kind} polyline needs "
                         f"at least {need}")
    return np.array(pts, dtype=np.float64)
