"""The simulator's wall contact: limit the robot's velocity so it never sinks into a wall.

Why (amr_sim.simulator): pymunk integrates positions before velocities, so a force-driven body
executes each command one step late, and setting the velocity blindly sinks ~42 mm into walls;
limiting the velocity towards every wall within reach this step avoids both. Movers (discs,
amr_sim.moving_obstacles) are walls that stand still during a step: the robot's velocity is
limited towards them alike.

A big map (World.wall_grid: thousands to millions of walls, a SLAM map's specks) keeps only the
walls near the robot in the pymunk space (WallWindow): pymunk spent ~35 us and ~1.7 KB per wall
(37 s and 1.7 GB for a 1,000 x 1,000-cell map at its noisiest), and the contact limit tested
every wall every step. The walls within WINDOW_M of a centre are in the space; when the robot
may reach beyond them this step, the window moves to it, adding the walls that came near and
removing those left behind. A wall the robot touches is within its radius, so it stays: pymunk
sees the same contacts (and calls the same begin/separate callbacks) as with every wall.
"""
from __future__ import annotations

import math

import numpy as np
import pymunk

from amr_common import robot
from amr_common.jit import jit
from amr_common.world.raster_raycast import SegmentGrid
from amr_common.world.raycast import nearest_wall, segment_offset

ALLOWED_PENETRATION = 0.0005  # m: resting contact depth, below collision_slop so it is stable
ROBOT_TYPE, WALL_TYPE = 1, 2  # pymunk collision types
WINDOW_M = 0.8  # a big map's walls within this of the window's centre are in the space
_MARGIN_M = 0.05  # the window moves before the robot's reach this step leaves it by less


def wall_space(segments: np.ndarray, pose: tuple[float, float, float],
               grid: SegmentGrid | None = None
               ) -> tuple[pymunk.Space, pymunk.Body, pymunk.Circle, "EveryWall | WallWindow"]:
    """A pymunk space of the walls (frictionless segments) and the robot's disc at `pose`.

    (space, body, shape, walls): keep all of them (pymunk's shapes hold weak references to
    bodies). `grid`: the walls in buckets (World.wall_grid, a big map): only those near the
    robot go into the space, `walls` (a WallWindow) keeps them there; else every wall does
    (`walls`: EveryWall).
    """
    space = pymunk.Space()
    space.collision_slop = 1e-3  # the default 0.1 assumes pixels; units here are metres
    space.damping = 1.0
    if grid is None:
        for wall in segments:
            space.add(_wall_shape(space, wall))
    body = pymunk.Body(robot.MASS, pymunk.moment_for_circle(robot.MASS, 0.0, robot.ROBOT_RADIUS))
    body.position = pose[:2]
    body.angle = pose[2]
    shape = pymunk.Circle(body, robot.ROBOT_RADIUS)
    shape.collision_type = ROBOT_TYPE
    shape.friction = 0.0
    shape.elasticity = 0.0
    space.add(body, shape)
    walls = EveryWall(segments) if grid is None else WallWindow(space, grid, *pose[:2])
    return space, body, shape, walls


def _wall_shape(space: pymunk.Space, wall) -> pymunk.Segment:
    x1, y1, x2, y2 = (float(v) for v in wall)
    shape = pymunk.Segment(space.static_body, (x1, y1), (x2, y2), 0.0)
    shape.collision_type = WALL_TYPE
    shape.friction = 0.0
    return shape


class EveryWall:
    """Every wall in the space for good (a world with few walls): WallWindow's interface."""

    def __init__(self, segments: np.ndarray) -> None:
        self.segments = segments

    def follow(self, x: float, y: float, reach: float) -> np.ndarray:
        """Every wall (what constrain_velocity tests)."""
        return self.segments

    def move_to(self, x: float, y: float) -> None:
        """Nothing to move."""

    def clearance(self, x: float, y: float) -> float:
        """Distance (m) from (x, y) to the nearest wall."""
        return nearest_wall(self.segments, x, y)[0]


class WallWindow:
    """The walls of a big map near the robot, kept in its pymunk space (module docstring).

    `segments`: the walls in the space now (what constrain_velocity tests).
    """

    def __init__(self, space: pymunk.Space, grid: SegmentGrid, x: float, y: float) -> None:
        self.space, self.grid = space, grid
        self._shapes: dict[int, pymunk.Segment] = {}
        self.segments = np.zeros((0, 4))
        self.centre = (math.nan, math.nan)
        self.radius = WINDOW_M
        self.move_to(x, y)

    def follow(self, x: float, y: float, reach: float) -> np.ndarray:
        """The walls within `reach` of (x, y) are in the space (the window moves if need be).

        Returns `segments`. reach: the robot radius plus how far it may move this step.
        """
        if math.hypot(x - self.centre[0], y - self.centre[1]) + reach + _MARGIN_M > self.radius:
            self.move_to(x, y, max(WINDOW_M, reach + _MARGIN_M))
        return self.segments

    def move_to(self, x: float, y: float, radius: float = WINDOW_M) -> None:
        """The walls within `radius` of (x, y) in the space, and no others."""
        wanted = self.grid.near(x, y, radius)
        for index in set(self._shapes) - set(wanted.tolist()):
            self.space.remove(self._shapes.pop(index))
        for index in wanted.tolist():
            if index not in self._shapes:
                self._shapes[index] = _wall_shape(self.space, self.grid.segments[index])
                self.space.add(self._shapes[index])
        self.segments = np.ascontiguousarray(self.grid.segments[wanted])
        self.centre, self.radius = (x, y), radius

    def clearance(self, x: float, y: float) -> float:
        """Distance (m) from (x, y) to the nearest wall of the map (not only the window's)."""
        near = nearest_wall(self.segments, x, y)[0] if len(self.segments) else math.inf
        if near <= self.radius - math.hypot(x - self.centre[0], y - self.centre[1]):
            return near  # no wall outside the window is that close
        return float(self.grid.clearances(np.array([[x, y]]))[0])


def constrain_velocity_python(segments, circles, px, py, vx, vy, h, radius, allowed_penetration):
    """Limit (vx, vy) so that after moving h seconds no wall is closer than radius - allowed.

    The distance to a segment (or a disc: circles rows [x, y, r]) along a straight motion is
    convex in time, so the linear bound d(t) >= d0 - (v . n) t is safe: v . n <= (d0 - radius +
    allowed) / h for the unit vector n towards each wall within reach. Several walls (corners):
    alternating projections.
    """
    reach = radius + math.sqrt(vx * vx + vy * vy) * h + 1e-3
    normals = np.empty((8, 3))
    count = 0
    for k in range(segments.shape[0] + circles.shape[0]):
        if k < segments.shape[0]:
            cx, cy, d = segment_offset(segments, k, px, py)
        else:  # to the disc's edge: along the line between the centres
            cx = circles[k - segments.shape[0], 0] - px
            cy = circles[k - segments.shape[0], 1] - py
            centre = math.sqrt(cx * cx + cy * cy)
            d = centre - circles[k - segments.shape[0], 2]
            cx = cx * (d / centre) if centre > 0.0 else 0.0
            cy = cy * (d / centre) if centre > 0.0 else 0.0
        if d < reach and d > 0.0 and count < 8:
            normals[count, 0] = cx / d
            normals[count, 1] = cy / d
            normals[count, 2] = max(d - radius + allowed_penetration, 0.0) / h
            count += 1
    if count == 0:
        return vx, vy
    for _ in range(16):  # converges in 1-3 passes for 1-3 walls
        worst = 0.0
        for j in range(count):
            excess = vx * normals[j, 0] + vy * normals[j, 1] - normals[j, 2]
            if excess > 0.0:
                vx -= excess * normals[j, 0]
                vy -= excess * normals[j, 1]
                worst = max(worst, excess)
        if worst < 1e-12:
            return vx, vy
    return 0.0, 0.0  # not converged (a narrow wedge): stopping is always safe


constrain_velocity = jit(constrain_velocity_python)
