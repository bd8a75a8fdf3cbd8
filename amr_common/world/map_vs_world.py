"""A map that is not the world: what the robot believes beside where it really drives.

The particle filter, the planner and /map use the MAP (`--map`, default the world); the
simulator drives in the WORLD. This is how a map SLAM built is tested, and what an unmapped box
or a moved wall does to localization and navigation shows. Both share one frame: the map's
coordinates are the world's (a map converted from the world, or built by SLAM from the start
pose given in world coordinates).

The rules the run scripts and the headless episodes share:
- a start is where the robot really is: checked against the world (an error there); a start
  the map does not have free is only a warning (the filter will not find the robot there);
- a goal is where the planner plans: a name of the map or else of the world, or x,y, checked
  against the map (an error there: no plan could reach it); a goal the world blocks (free in
  the map, inside a wall of the world) is allowed - that is the experiment - with a warning.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from amr_common.world.world import World

UNMAPPED_SPACING = 0.02  # m between the points of a world wall tested against the map


def load_map(source: str | Path | World | None, world: World) -> World:
    """The map the filter and the planner use: `source` loaded, or `world` when None.

    A source naming the world's own file is the world itself (one object, nothing differs).
    A map has no movers: a world file's are dropped (they walk in the world, never on a map).
    Raises WorldError (naming the file) for a map that does not load.
    """
    if source is None:
        return world
    map_world = source if isinstance(source, World) else World.load(source)
    if same_source(map_world, world):
        return world
    return replace(map_world, movers=()) if map_world.movers else map_world


def same_source(a: World, b: World) -> bool:
    """True if two worlds were loaded from the same file."""
    if a is b:
        return True
    try:
        return Path(a.source).resolve() == Path(b.source).resolve() and \
            Path(a.source).is_file()
    except OSError:
        return False


def resolve_goal_on_map(goal: str | Sequence[float] | None, map_world: World,
                        world: World) -> tuple[tuple[float, float], str | None]:
    """(goal point, warning or None) for a goal given to the planner on `map_world`.

    `goal`: a named goal of the map, else of the world; "x,y"; (x, y); None (the map's default
    goal, else the world's). Raises WorldError when the map refuses the goal (outside its free
    space or within GOAL_CLEARANCE of its walls). The warning says the world blocks it.
    """
    if map_world is world:
        return world.resolve_goal(goal), None
    if isinstance(goal, str) and goal not in map_world.goals and goal in world.goals:
        goal = world.goals[goal]
    elif goal is None and map_world.goal is None:
        goal = world.goal  # None too: the map's resolve_goal says neither has one
    point = map_world.resolve_goal(goal)
    problem = world.goal_problem(*point)
    if problem is None:
        return point, None
    return point, (f"{problem} in the world {world.source}, which the map {map_world.source} "
                   f"has free: the robot may not reach it")


def start_warning(pose: Sequence[float], map_world: World, world: World,
                  what: str = "start") -> str | None:
    """A warning when the robot's pose (free in the world) is not free on the map, else None."""
    if map_world is world:
        return None
    problem = map_world.pose_problem(float(pose[0]), float(pose[1]), what)
    if problem is None:
        return None
    return (f"{problem} on the map {map_world.source} (it is free in the world): the filter "
            f"will not find the robot there")


def unmapped_walls(world: World, map_world: World, tolerance: float = 0.05) -> np.ndarray:
    """The pieces of the world's walls the map lacks, as (N, 4) segments [x1, y1, x2, y2].

    Each wall is tested at points UNMAPPED_SPACING apart: a run of points farther than
    `tolerance` from every wall of the map is a piece the map lacks (an unmapped box, a moved
    wall). None for the world itself.
    """
    if map_world is world or len(world.segments) == 0:
        return np.zeros((0, 4))
    pieces = []
    for x1, y1, x2, y2 in world.segments:
        n = max(2, math.ceil(math.hypot(x2 - x1, y2 - y1) / UNMAPPED_SPACING) + 1)
        u = np.linspace(0.0, 1.0, n)
        points = np.column_stack([x1 + u * (x2 - x1), y1 + u * (y2 - y1)])
        lacked = np.concatenate([[False], map_world.clearances(points) > tolerance, [False]])
        edges = np.flatnonzero(np.diff(lacked.astype(np.int8)))  # run starts and ends
        for first, end in zip(edges[::2], edges[1::2]):
            if end - first >= 2:  # a run of >= 2 points: a piece with a length
                pieces.append([*points[first], *points[end - 1]])
    return np.array(pieces, dtype=np.float64).reshape(-1, 4)


__all__ = ["load_map", "same_source", "resolve_goal_on_map", "start_warning", "unmapped_walls"]
