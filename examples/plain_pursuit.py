"""The course's plain pure pursuit: steer along the arc through a point `lookahead_m` ahead.

A small, readable amr_common.plugins.interfaces.PathFollower: the project's PurePursuit is
regulated (speed from curvature, obstacles and the distance left; stops at sharp corners and turns
in place; an adaptive lookahead). Run it in place of the project's:

    .venv/bin/python scripts/run_sim.py --world lab02 --goal inner_far \
        --follower examples.plain_pursuit:PlainPursuit
    .venv/bin/python scripts/evaluate.py --worlds lab02 --goals all --duration 200 \
        --follower examples.plain_pursuit:PlainPursuit --out out/pursuit

Each step: the nearest path point (searched from the last one on, so the robot never goes back
along the path), the target point the first one at least lookahead_m further along the path,
alpha the angle from the heading to it; turn in place while |alpha| > rotate_angle_rad, else
v = speed_mps (slower within the last slow_down_m) and w = 2 v sin(alpha) / lookahead_m.
Stop within goal_tolerance_m of the path's end. It cuts corners by up to about the lookahead
and ignores the scan: scripts/compare.py shows the clearance it costs.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from amr_common.plugins.parameter_table import above, checked_values, ruled
from amr_common.robot import MAX_ANGULAR_SPEED, ROBOT_RADIUS

_PARAMETERS = ruled({
    "speed_mps": (0.15, "Cruise speed [m/s]"),
    "lookahead_m": (0.15, "Distance of the target point along the path [m]"),
    "rotate_angle_rad": (0.8, "Turn in place while the target is more than this off the "
                              "heading [rad]"),
    "rotate_speed_radps": (1.0, "In-place turning speed [rad/s]"),
    "slow_down_m": (0.2, "Slow down within this of the path's end [m]"),
    "goal_tolerance_m": (0.02, "Stop within this of the path's end [m]"),
    "lidar_offset_x_m": (0.0, "Where the LiDAR sits ahead of the robot centre [m] (not used: "
                              "this follower ignores the scan)"),
}, above(0.0), lidar_offset_x_m=None)


class PlainPursuit:
    """Pure pursuit at constant speed (see the module docstring)."""

    state: str  # the interface's members set in clear_path / compute_commands
    arrived: bool

    @staticmethod
    def parameter_descriptions() -> dict[str, tuple[Any, str]]:
        """Each parameter: name -> (default, description); the node declares them."""
        return dict(_PARAMETERS)

    def __init__(self, dt: float, **params: Any) -> None:
        self.dt = float(dt)
        self.p = checked_values(_PARAMETERS, params, "PlainPursuit")  # ValueError
        self.clear_path()

    @property
    def robot_radius_m(self) -> float:
        """The Burger's footprint radius (m)."""
        return ROBOT_RADIUS

    @property
    def lidar_offset_x_m(self) -> float:
        """Where the LiDAR sits ahead of the robot centre (m)."""
        return float(self.p["lidar_offset_x_m"])

    @property
    def path(self) -> np.ndarray | None:
        """The followed path (K, 2), or None."""
        return self._points

    def clear_path(self) -> None:
        """No path: zero commands."""
        self._points = None
        self._nearest = 0
        self.state, self.arrived = "idle", False

    def set_path(self, points) -> None:
        """Follow a new path from its start."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(points) == 0 or not np.isfinite(points).all():
            raise ValueError("PlainPursuit: a path needs at least one point, all finite")
        self.clear_path()
        self._points = points
        self.state = "rotate"

    def compute_commands(self, x, y, theta, obstacle_clearance_m=None, free_ahead_m=None):
        """(v, w) toward the lookahead point; zero without a path and once arrived."""
        points = self._points
        if points is None or self.arrived or not all(map(math.isfinite, (x, y, theta))):
            return 0.0, 0.0
        p = self.p
        end = points[-1]
        to_end = math.hypot(end[0] - x, end[1] - y)
        if to_end <= p["goal_tolerance_m"]:
            self.state, self.arrived = "arrived", True
            return 0.0, 0.0
        # The nearest point from the last one on (a window, so a loop is not short-cut).
        window = points[self._nearest:self._nearest + 50]
        self._nearest += int(np.argmin(np.hypot(window[:, 0] - x, window[:, 1] - y)))
        # The target: the first point at least lookahead_m from the robot, else the end.
        ahead = points[self._nearest:]
        far = np.flatnonzero(np.hypot(ahead[:, 0] - x, ahead[:, 1] - y) >= p["lookahead_m"])
        tx, ty = ahead[far[0]] if far.size else end
        alpha = math.atan2(ty - y, tx - x) - theta
        alpha = math.atan2(math.sin(alpha), math.cos(alpha))
        if abs(alpha) > p["rotate_angle_rad"] or (self.state == "rotate" and abs(alpha) > 0.1):
            self.state = "rotate"
            return 0.0, math.copysign(p["rotate_speed_radps"], alpha)
        self.state = "track"
        v = p["speed_mps"] * min(1.0, max(to_end / p["slow_down_m"], 0.15))
        distance = max(math.hypot(tx - x, ty - y), 1e-6)
        w = 2.0 * v * math.sin(alpha) / distance
        return v, max(-MAX_ANGULAR_SPEED, min(MAX_ANGULAR_SPEED, w))
