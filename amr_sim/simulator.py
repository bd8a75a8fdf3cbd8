"""The headless simulator core: a TurtleBot3 Burger in a world of walls (no ROS).

    sim = Simulator("lab02", start="outer", dt=0.05, profile="ideal", seed=0)
    z_scan, z_v, z_w = sim.measure()          # first measurement, without moving
    z_scan, z_v, z_w = sim.step(v, w)         # advance one dt with the command (v m/s, w rad/s)

Each step: the command is cleaned (NaN/inf -> 0 with a rate-limited warning), quantised and
clipped as the profile's robot does (the turtlebot3 profiles only), and saturated by the
wheel-speed limit (robot.py: both wheels scaled by one factor, which keeps the curvature). The
executed twist becomes the velocity of a pymunk dynamic body (the chord of the exact unicycle arc
along the mid-step heading, so free motion equals the exact unicycle solution with no lag).
Walls stop the robot through a speculative contact constraint (amr_sim.contact): the robot ends
at most 0.5 mm inside a wall. Pymunk detects the contacts (begin/separate callbacks count
collisions) and its solver pushes out any deeper overlap. On a big map (World.wall_grid) the
space holds only the walls near the robot (contact.WallWindow): the same contacts.

The world's movers (amr_common.world.movers; amr_sim.moving_obstacles) walk first in each
step, each waiting while its next position would touch the robot; then they stand like walls for
the robot's motion (its velocity is limited towards them too; their contacts are counted by
amr_sim.moving_obstacles, not pymunk) and are seen by the LiDAR. `collisions` counts every
contact the robot starts, with walls and movers; `collisions_with_movers` the part with movers.

Sensors come from the body's actual motion: encoder increments (so z_v/z_w reflect collisions and
saturation), a dead-reckoned odometry pose, and the LiDAR at the robot centre (lidar.py).

A profile with reality-gap effects (turtlebot3, turtlebot3_lds02; amr_sim.reality) replaces
the command path by the real drivetrain (latency, firmware clamps, motors, wheel errors, slip),
the odometry by encoders + a drifting IMU heading, and the LiDAR by the real scanner (skew,
range error by band, dropouts, the LDS-02's changing rays). Without effects, nothing changes.
"""
from __future__ import annotations

import logging
import math
import time as _time

import numpy as np
import pymunk

from amr_common import robot
from amr_common.geometry import wrap_angle
from amr_common.robot import COMMAND_CLIP  # |v|, |w| beyond this are absurd
from amr_common.world.world import World, WorldError
from amr_sim.contact import (
    ALLOWED_PENETRATION,
    ROBOT_TYPE,
    WALL_TYPE,
    constrain_velocity,
    wall_space,
)
from amr_sim.lidar import Lidar
from amr_sim.moving_obstacles import MovingObstacles
from amr_sim.profiles import SensorProfile, get_profile
from amr_sim.reality import RealRobot

log = logging.getLogger("amr_sim.simulator")

_ROBOT_RADIUS = robot.ROBOT_RADIUS
_WARN_INTERVAL = 5.0  # s of wall time between repeated bad-command warnings


class Simulator:
    """A TurtleBot3 Burger in `world`; `step(v, w)` advances dt and returns (z_scan, z_v, z_w)."""

    def __init__(self, world: World | str, start=None, dt: float = 0.05,
                 profile: str | SensorProfile = "ideal", seed: int = 0) -> None:
        self._world = world if isinstance(world, World) else World.load(world)
        x, y, theta = self._world.resolve_start(start)
        dt = float(dt)
        if not (math.isfinite(dt) and 0.0 < dt <= 1.0):
            raise ValueError(f"dt must be in (0, 1] s, got {dt}")
        self._dt = dt
        self._profile = get_profile(profile)
        self._rng = np.random.default_rng(seed)
        self._start = (x, y, theta)
        self._segments = self._world.segments

        grid = self._world.wall_grid  # a big map: only the walls near the robot in the space
        space, body, shape, self._walls = wall_space(self._segments, (x, y, theta), grid)
        space.on_collision(ROBOT_TYPE, WALL_TYPE, begin=self._on_begin,
                           separate=self._on_separate)
        self._space, self._body, self._shape = space, body, shape  # shapes hold weak body refs
        self._movers = MovingObstacles(self._world.movers)
        self._has_movers = len(self._movers) > 0
        self._check_clear_of_movers(x, y, "start")

        p = self._profile
        # The reality gap (profiles with effects): drivetrain, scanner and their random streams.
        self._real = None if p.effects is None else RealRobot(p, self._segments, seed,
                                                              (x, y, theta), dt, grid)
        self._lidar = self._real.lidar if self._real else Lidar(
            self._segments, p.scan_rays, p.angle_min, p.angle_increment, p.range_min,
            p.range_max, p.no_return, grid=self._world.march_grid)
        self._lidar.circles = self._movers.circles  # the same array: the movers update it
        self._scan_geometry = (p.angle_min, p.angle_increment, p.scan_rays, p.range_min,
                               p.range_max)
        self._x, self._y, self._theta = x, y, theta  # theta continuous (not wrapped)
        self._steps = 0
        self._distance = 0.0
        self._collisions = 0
        self._mover_collisions = 0
        self._first_collision_time: float | None = None
        self._collision_points: list[tuple[float, float]] = []
        self._active_contacts = 0
        self._min_clearance = self._walls.clearance(x, y) - robot.ROBOT_RADIUS
        # odom frame = the start pose, like a robot's /odom at boot (the drivetrain's, if real)
        self._odom = [0.0, 0.0, 0.0] if self._real is None else self._real.drive.odom
        self._wheel_angles = [0.0, 0.0]
        self._z_v = 0.0
        self._z_w = 0.0
        self._command = (0.0, 0.0)  # twist executed in the last step (after limits)
        self._bad_commands = 0
        self._quantum = round(1.0 / p.command_resolution) if p.command_resolution else 0
        self._last_warning = -math.inf
        self._scan = self._new_scan()
        self._scan_time = 0.0
        self._next_scan_time = p.scan_period if p.scan_period else 0.0

    # ------------------------------------------------------------------ stepping
    @property
    def last_scan(self) -> np.ndarray:
        """The newest scan (as step() and measure() returned it), without measuring again."""
        return self._scan

    def measure(self) -> tuple[np.ndarray, float, float]:
        """The current sensor readings (z_scan, z_v, z_w) without advancing time."""
        return self._scan, self._z_v, self._z_w

    def step(self, v: float, w: float) -> tuple[np.ndarray, float, float]:
        """Advance one dt with the command (v m/s, w rad/s); return (z_scan, z_v, z_w)."""
        v, w = self._command = self._executed(v, w)
        p, dt = self._profile, self._dt
        x0, y0, th0 = self._x, self._y, self._theta
        chord_v = robot.arc_displacement(th0, v * robot.sinc_half(w * dt), w * dt)  # exact arc
        walls = self._walls.follow(x0, y0, _ROBOT_RADIUS + math.hypot(*chord_v) * dt)
        movers = self._movers
        if self._has_movers:  # they walk first (or wait for the robot), then stand this step
            movers.advance(self._steps * dt, x0, y0, dt)
        vx, vy = constrain_velocity(walls, movers.circles, x0, y0, *chord_v, dt, _ROBOT_RADIUS,
                                    ALLOWED_PENETRATION)
        body = self._body
        body.velocity = (vx, vy)
        body.angular_velocity = w
        self._space.step(dt)
        x1, y1 = body.position
        th1 = body.angle
        self._x, self._y, self._theta = x1, y1, th1
        self._steps += 1
        now = self._steps * dt
        if self._has_movers and (count := movers.new_contacts(x1, y1)):
            self._collisions += count  # the robot's: movers never start one
            self._mover_collisions += count
            self._collision_points += [(float(cx), float(cy))
                                       for cx, cy in movers.contact_points[:count]]
        if self._first_collision_time is None and self._collisions:
            self._first_collision_time = now

        # Encoders from the actual motion: arc length along the mid heading -> wheel angle
        # increments -> forward kinematics (z_v = ds / dt, z_w = dtheta / dt).
        dth = th1 - th0
        chord = robot.step_chord(x1 - x0, y1 - y0, th0, dth)
        ds = chord / robot.sinc_half(dth)
        wheels = self._wheel_angles
        if self._real is not None:  # encoders, odometry with the IMU heading (it drifts)
            dphi_l, dphi_r, self._z_v, self._z_w = self._real.drive.sense(ds, dth, dt)
            self._lidar.record(now, x1, y1, th1)
            wheels[0] += dphi_l
            wheels[1] += dphi_r
        else:
            dphi_l, dphi_r = robot.encoder_increments(ds, dth)
            wheels[0] += dphi_l
            wheels[1] += dphi_r
            self._z_v, self._z_w = robot.twist_from_increments(dphi_l, dphi_r, dt)
            # Dead reckoning (the encoders do not see sideways sliding along a wall).
            odom = self._odom
            odom[0], odom[1], odom[2] = robot.arc_step(odom[0], odom[1], odom[2], chord, dth)
        self._distance += math.hypot(x1 - x0, y1 - y0)

        clearance = self._walls.clearance(x1, y1) - _ROBOT_RADIUS
        if clearance < self._min_clearance:
            self._min_clearance = clearance

        if p.scan_period is None:
            self._scan = self._new_scan()
            self._scan_time = now
        elif now >= self._next_scan_time - 1e-9:
            self._scan = self._new_scan()
            self._scan_time = now
            while self._next_scan_time <= now + 1e-9:
                self._next_scan_time += p.scan_period
        return self._scan, self._z_v, self._z_w

    def _executed(self, v: float, w: float) -> tuple[float, float]:
        """The twist the robot executes this step for the command (v, w)."""
        if not (type(v) is float and type(w) is float and -COMMAND_CLIP < v < COMMAND_CLIP
                and -COMMAND_CLIP < w < COMMAND_CLIP):  # NaN fails the comparisons
            v, w = self._clean_command(v, w)
        p, dt = self._profile, self._dt
        if self._quantum:  # turtlebot3_node sends int(v * 100): truncation toward zero
            v = math.trunc(v * self._quantum) / self._quantum
            w = math.trunc(w * self._quantum) / self._quantum
        if self._real is not None:  # latency, firmware clamps, motors, wheel errors, slip
            ds, dth = self._real.drive.step(v, w, self._steps * dt, dt)
            return ds / dt, dth / dt
        if p.clamp_commands:
            v = min(max(v, -p.max_linear), p.max_linear)
            w = min(max(w, -p.max_angular), p.max_angular)
        return robot.saturate(v, w)  # wheel-speed limit: one factor on both wheels

    def teleport(self, pose) -> None:
        """Teleport the robot to `pose` (x, y, theta), as if kidnapped.

        Move the robot to `pose` (x, y, theta) at once, as if kidnapped: no time passes, the
        encoders and the dead-reckoned odometry see no motion, the distance does not grow, and
        the LiDAR reads the new place from its next scan on (every step with `ideal`, the next
        0.2 s slot with the turtlebot3 profiles). Raises WorldError for a pose inside or touching
        a wall. A mover where the robot lands (they walk, so a kidnap pose cannot be checked
        against them before the run) is no collision: it waits until the robot has left, and the
        robot may only drive out of it.
        """
        x, y, theta = self._world.resolve_start(tuple(float(v) for v in pose))
        if self._has_movers:
            self._movers.new_contacts(x, y)  # what it touches now is no contact it started
        body = self._body
        body.position = (x, y)
        body.angle = theta
        body.velocity = (0.0, 0.0)
        body.angular_velocity = 0.0
        self._walls.move_to(x, y)
        self._space.reindex_shapes_for_body(body)
        self._x, self._y, self._theta = x, y, theta
        if self._real is not None:  # the scan's pose history starts again here
            self._lidar.reset(self.time, x, y, theta)

    def _check_clear_of_movers(self, x: float, y: float, what: str) -> None:
        mover = self._movers.touching(x, y)
        if mover is not None:
            mx, my = self._movers.positions[self._movers.movers.index(mover)]
            raise WorldError(f"{self._world.source}: {what} ({x:g}, {y:g}) touches {mover.name} "
                             f"(radius {mover.radius:g} m, now at ({mx:.2f}, {my:.2f}))")

    def _new_scan(self) -> np.ndarray:
        if self._real is not None:  # the revolution ends now (the driver's stamp)
            scan = self._lidar.scan(self._steps * self._dt)
            if self._lidar.geometry != self._scan_geometry[:3]:  # LDS-02: every scan
                self._scan_geometry = (*self._lidar.geometry, *self._scan_geometry[3:])
            return scan
        p = self._profile
        noise = (self._rng.standard_normal(p.scan_rays) * p.range_noise_sigma
                 if p.range_noise_sigma > 0 else None)
        x, y = self.lidar_position
        return self._lidar.scan(x, y, self._theta, noise)

    @property
    def lidar_position(self) -> tuple[float, float]:
        """World position (x, y) of the LiDAR, the origin of the scan's rays (m)."""
        offset = self._profile.lidar_offset_x
        if offset == 0.0:
            return self._x, self._y
        return (self._x + offset * math.cos(self._theta), self._y + offset * math.sin(self._theta))

    def _clean_command(self, v, w) -> tuple[float, float]:
        try:
            v, w = float(v), float(w)
        except (TypeError, ValueError):
            v, w = math.nan, math.nan
        if math.isfinite(v) and math.isfinite(w):
            # Absurd magnitudes are saturated later; clipping keeps v * 100 etc. finite.
            return (min(max(v, -COMMAND_CLIP), COMMAND_CLIP),
                    min(max(w, -COMMAND_CLIP), COMMAND_CLIP))
        self._bad_commands += 1
        now = _time.monotonic()
        if now - self._last_warning >= _WARN_INTERVAL:
            log.warning("non-finite command (v=%r, w=%r) at t=%.2f s: stopping (treated as zero) "
                        "(%d bad command(s) so far)", v, w, self.time, self._bad_commands)
            self._last_warning = now
        return 0.0, 0.0  # a controller that outputs NaN is broken: stop rather than guess

    # ------------------------------------------------------------------ contacts
    def _on_begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        if self._active_contacts == 0:  # a new contact with the walls, not a next wall segment
            self._collisions += 1
            points = arbiter.contact_point_set.points
            if points:
                cx, cy = points[0].point_b
                self._collision_points.append((float(cx), float(cy)))
        self._active_contacts += 1

    def _on_separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        self._active_contacts = max(0, self._active_contacts - 1)

    # ------------------------------------------------------------------ properties
    @property
    def pose(self) -> tuple[float, float, float]:
        """True pose (x, y, theta) in the world frame, theta wrapped to (-pi, pi]."""
        return (float(self._x), float(self._y), wrap_angle(self._theta))

    @property
    def odometry_pose(self) -> tuple[float, float, float]:
        """Pose dead-reckoned from the wheel encoders in the odom frame.

        The start pose is (0, 0, 0).
        """
        odom = self._odom
        return (float(odom[0]), float(odom[1]), wrap_angle(float(odom[2])))

    @property
    def wheel_angles(self) -> tuple[float, float]:
        """Accumulated wheel angles (left, right) in rad, as the encoders count them."""
        return (self._wheel_angles[0], self._wheel_angles[1])

    @property
    def executed_command(self) -> tuple[float, float]:
        """The twist (v, w) the robot executed in the last step, after quantisation and limits."""
        return self._command

    @property
    def effects(self):
        """The reality-gap effects of this run (amr_sim.effects.Effects), or None (clean)."""
        return self._real.effects if self._real is not None else None

    @property
    def scan_geometry(self) -> tuple[float, float, int, float, float]:
        """(angle_min, angle_increment, rays, range_min, range_max) of the newest scan.

        The profile's, except with the LDS-02, whose rays change from scan to scan. The same
        tuple object until the geometry changes (`is not` tells a change cheaply).
        """
        return self._scan_geometry

    @property
    def lidar(self) -> Lidar:
        """The scanner: any object with scan(x, y, theta, noise) -> ranges.

        Replaceable, e.g. by benchmarks.
        """
        return self._lidar

    @lidar.setter
    def lidar(self, scanner) -> None:
        self._lidar = scanner
        if hasattr(scanner, "circles"):  # it sees the movers too
            scanner.circles = self._movers.circles

    @property
    def space(self) -> pymunk.Space:
        """The pymunk space (walls are static segments; the robot is the only dynamic body)."""
        return self._space

    @property
    def robot_shape(self) -> pymunk.Circle:
        """The robot's pymunk circle."""
        return self._shape

    @property
    def time(self) -> float:
        """Simulated time, s (steps * dt)."""
        return self._steps * self._dt

    @property
    def scan_time(self) -> float:
        """Simulated time (s) at which the newest scan was taken (turtlebot3*: every 0.2 s)."""
        return self._scan_time

    @property
    def steps(self) -> int:
        """Steps taken since the start."""
        return self._steps

    @property
    def dt(self) -> float:
        """Step length, s."""
        return self._dt

    @property
    def profile(self) -> SensorProfile:
        """The sensor profile (ideal, turtlebot3, ...)."""
        return self._profile

    @property
    def world(self) -> World:
        """The world being simulated."""
        return self._world

    @property
    def start(self) -> tuple[float, float, float]:
        """The start pose (x, y, theta) in the world frame."""
        return self._start

    @property
    def collisions(self) -> int:
        """Number of contacts the robot started, with walls and movers."""
        return self._collisions

    @property
    def collisions_with_movers(self) -> int:
        """The part of `collisions` with movers."""
        return self._mover_collisions

    @property
    def movers(self) -> MovingObstacles:
        """The world's movers as simulated: positions, clocks, waits (amr_sim.moving_obstacles)."""
        return self._movers

    @property
    def mover_waits(self) -> list[list[list[float]]]:
        """Per mover, the intervals [t_from, t_to] (s) it waited for the robot."""
        return self._movers.waits

    @property
    def first_collision_time(self) -> float | None:
        """Simulated time (s) at the end of the step in which the first contact began."""
        return self._first_collision_time

    @property
    def collision_points(self) -> list[tuple[float, float]]:
        """The wall's (or mover's) point where each contact started."""
        return list(self._collision_points)

    @property
    def in_contact(self) -> bool:
        """True while the robot touches a wall or a mover."""
        return self._active_contacts > 0 or self._movers.in_contact

    @property
    def min_clearance(self) -> float:
        """Smallest distance from the robot's edge to a wall so far (m; <= 0 in contact).

        Walls only: a mover may come within KEEP_OFF of a robot that stands still.
        """
        return float(self._min_clearance)

    @property
    def clearance(self) -> float:
        """Current distance from the robot's edge to the nearest wall (m)."""
        return float(self._walls.clearance(self._x, self._y) - robot.ROBOT_RADIUS)

    @property
    def distance(self) -> float:
        """Path length travelled (m)."""
        return self._distance

    @property
    def bad_commands(self) -> int:
        """Number of non-finite commands replaced by zero."""
        return self._bad_commands


__all__ = ["Simulator"]
