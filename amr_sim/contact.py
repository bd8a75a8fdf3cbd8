"""The simulator's wall contact: limit the robot's velocity so it never sinks into a wall.

Why (amr_sim.simulator): pymunk integrates positions before velocities, so a force-driven body
executes each command one step late, and setting the velocity blindly sinks ~42 mm into walls;
limiting the velocity towards every wall within reach this step avoids both. Movers (discs,
amr_sim.moving_obstacles) are walls that stand still during a step: the robot's velocity is
limited towards them alike.
"""
from __future__ import annotations

import math

import numpy as np
import pymunk

from amr_common import robot
from amr_common.jit import jit
from amr_common.world.raycast import segment_offset

ALLOWED_PENETRATION = 0.0005  # m: resting contact depth, below collision_slop so it is stable
ROBOT_TYPE, WALL_TYPE = 1, 2  # pymunk collision types


def wall_space(segments: np.ndarray, pose: tuple[float, float, float]
               ) -> tuple[pymunk.Space, pymunk.Body, pymunk.Circle]:
    """A pymunk space of the walls (frictionless segments) and the robot's disc at `pose`.

    (space, body, shape): keep all three (pymunk's shapes hold weak references to bodies).
    """
    space = pymunk.Space()
    space.collision_slop = 1e-3  # the default 0.1 assumes pixels; units here are metres
    space.damping = 1.0
    for x1, y1, x2, y2 in segments:
        wall = pymunk.Segment(space.static_body, (x1, y1), (x2, y2), 0.0)
        wall.collision_type = WALL_TYPE
        wall.friction = 0.0
        space.add(wall)
    body = pymunk.Body(robot.MASS, pymunk.moment_for_circle(robot.MASS, 0.0, robot.ROBOT_RADIUS))
    body.position = pose[:2]
    body.angle = pose[2]
    shape = pymunk.Circle(body, robot.ROBOT_RADIUS)
    shape.collision_type = ROBOT_TYPE
    shape.friction = 0.0
    shape.elasticity = 0.0
    space.add(body, shape)
    return space, body, shape


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
