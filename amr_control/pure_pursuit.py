"""A regulated pure pursuit that follows a planned path and stops at its end (no rclpy).

    pursuit = PurePursuit(dt=0.05)
    pursuit.set_path(points)                       # (K, 2) metres, map frame
    v, w = pursuit.compute_commands(x, y, theta, obstacle_clearance_m)
    pursuit.state, pursuit.cross_track_error, pursuit.arrived

Policy (after Nav2's Regulated Pure Pursuit, tightened for 0.4 m corridors):
- The path is cut into sections at sharp corners (a vertex turning more than corner_angle_rad):
  the robot drives each section to its end, stops there and turns in place into the next one,
  so it never cuts a sharp corner. A planned path with rounded corners is one section.
- Pursuit: the target point lies `lookahead` further along the path than the robot's projection
  on it (past a section's end: on the extension of its last segment, so the approach to a stop
  is straight); lookahead = lookahead_time_s * speed, clamped to [min, max]. The command follows
  the arc through the target point: w = v * 2 sin(alpha) / distance.
- Rotate to heading: with the target more than rotate_to_heading_angle_rad off the heading the
  robot turns in place until it is within heading_tolerance_rad (hysteresis: no rotate-drive
  loops), e.g. at the start and at every sharp corner.
- Speed: max_linear_speed_mps, reduced on tight arcs (radius below regulated_min_radius_m: v
  scaled by radius / regulated_min_radius_m), near obstacles (footprint clearance from the scan
  below proximity_distance_m: scaled by clearance / proximity_distance_m, at least
  min_proximity_scale), before a stop (approach_gain_per_s * distance left, at least
  min_approach_speed_mps), by max_linear_accel_mps2, and so both wheels stay within the Burger's
  limit (curvature kept).
- Obstacle ahead (from the scan: `free_ahead_m`, how far the footprint can drive straight on
  before it touches a scan point): something the map lacks (an unmapped box, a moved wall)
  before the section's end makes the robot brake to a halt obstacle_stop_distance_m short of
  it (v <= approach_gain_per_s * the room left, no minimum speed) and wait there (state
  "blocked") until it moves away or a new path comes - as Nav2's Regulated Pure Pursuit stops
  for a collision ahead. Turning in place needs no room: the footprint is round.
- Stop: within goal_tolerance_m of the path's end, or once past it: `arrived`, zero from then on
  until a new path (no creeping back and forth at the goal).
- Farther than max_path_deviation_m from the path: zero (state "off_path") until back or a new
  path comes (after a relocalization the planner replans from the new pose).
"""
from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from amr_common.geometry import without_repeats, wrap_angle
from amr_common.plugins.parameter_table import (
    Param,
    above,
    at_least,
    checked_values,
    finite,
    ruled,
)
from amr_common.robot import MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED, ROBOT_RADIUS, TRACK
from amr_common.sensors.scan_returns import return_mask

# name: (default, description with units). The pure_pursuit node declares each as a parameter.
_TABLE: dict[str, tuple[Any, str]] = {
    "max_linear_speed_mps": (MAX_LINEAR_SPEED, "Cruise speed [m/s]; at most the Burger's "
                                               f"{MAX_LINEAR_SPEED}."),
    "max_angular_speed_radps": (2.0, f"Angular speed limit [rad/s]; at most {MAX_ANGULAR_SPEED}."),
    "max_linear_accel_mps2": (0.5, "Forward acceleration limit [m/s^2] (braking is not limited: "
                                   "the approach slow-down shapes it)."),
    "lookahead_time_s": (0.7, "Lookahead distance per unit of speed [s]."),
    "min_lookahead_m": (0.08, "Shortest lookahead distance [m]."),
    "max_lookahead_m": (0.20, "Longest lookahead distance [m]."),
    "rotate_to_heading_angle_rad": (0.6, "Turn in place when the target is more than this off "
                                         "the heading [rad]."),
    "heading_tolerance_rad": (0.05, "Turning in place ends within this of the target [rad]."),
    "rotate_speed_radps": (1.5, "Fastest in-place turn [rad/s]."),
    "min_rotate_speed_radps": (0.15, "Slowest in-place turn, at the end of a turn [rad/s]."),
    "rotate_gain_per_s": (3.0, "In-place turn speed per radian of heading error [1/s]."),
    "corner_angle_rad": (0.5, "A path vertex turning more than this is a sharp corner: stop "
                              "there and turn in place [rad]."),
    "regulated_min_radius_m": (0.3, "Arcs tighter than this radius slow the robot in "
                                    "proportion [m]."),
    "proximity_distance_m": (0.06, "Footprint clearance (from the scan) below which the robot "
                                   "slows in proportion [m]."),
    "min_proximity_scale": (0.25, "Smallest speed factor near obstacles [-]."),
    "approach_gain_per_s": (2.0, "Before a stop the speed is at most this times the distance "
                                 "left [1/s]."),
    "min_approach_speed_mps": (0.02, "Slowest forward speed while approaching a stop [m/s]."),
    "obstacle_stop_distance_m": (0.02, "Halt this far short of a scan point in the way (footprint "
                                       "straight ahead; an obstacle the map lacks) [m]."),
    "goal_tolerance_m": (0.005, "The path's end (or a sharp corner) is reached within this [m]."),
    "max_path_deviation_m": (0.3, "Farther than this from the path: command zero [m]."),
    "robot_radius_m": (ROBOT_RADIUS, "Robot footprint radius, for the scan clearance [m]."),
    "lidar_offset_x_m": (0.0, "Forward position of the LiDAR relative to the robot centre [m] "
                              "(-0.032 on a real Burger)."),
    "track_m": (TRACK, "Wheel separation [m], to keep both wheels within max_linear_speed."),
}
# Numbers >= 0 but for these; speeds above the Burger's limits are clipped (check_parameters).
PARAMETERS: dict[str, Param] = ruled(
    _TABLE, at_least(0.0), lidar_offset_x_m=None,
    **{name: above(0.0) for name in (
        "max_linear_speed_mps", "max_angular_speed_radps", "min_lookahead_m",
        "rotate_speed_radps", "goal_tolerance_m", "max_linear_accel_mps2",
        "max_path_deviation_m", "regulated_min_radius_m", "approach_gain_per_s")})
_PROJECTION_WINDOW_M = 0.5  # how far along the path the robot's projection may move per step


def check_parameters(overrides: dict[str, Any]) -> dict[str, float]:
    """Every parameter's value (defaults updated with `overrides`), checked.

    Each against its rule in PARAMETERS, speeds clipped to the Burger's limits. ValueError
    names every problem or unknown names.
    """
    checked = checked_values(PARAMETERS, overrides, "PurePursuit")
    checked["max_linear_speed_mps"] = min(checked["max_linear_speed_mps"], MAX_LINEAR_SPEED)
    checked["max_angular_speed_radps"] = min(checked["max_angular_speed_radps"],
                                             MAX_ANGULAR_SPEED)
    if checked["max_lookahead_m"] < checked["min_lookahead_m"]:
        raise ValueError("PurePursuit: max_lookahead_m must be >= min_lookahead_m")
    if not checked["heading_tolerance_rad"] < checked["rotate_to_heading_angle_rad"]:
        raise ValueError("PurePursuit: heading_tolerance_rad must be below "
                         "rotate_to_heading_angle_rad")
    return checked


def scan_clearance(ranges: np.ndarray, angle_min: float, angle_increment: float,
                   range_min: float, range_max: float, lidar_offset_x: float,
                   robot_radius: float) -> float | None:
    """Smallest distance from the robot's footprint to a scan point (m).

    None without a return (amr_common.sensors.scan_returns: NaN, inf, 0.0 and readings outside
    [range_min, range_max] are none).
    """
    points = _scan_points(ranges, angle_min, angle_increment, range_min, range_max,
                          lidar_offset_x)
    if points is None:
        return None
    return float(np.hypot(*points).min() - robot_radius)


def scan_free_ahead(ranges: np.ndarray, angle_min: float, angle_increment: float,
                    range_min: float, range_max: float, lidar_offset_x: float,
                    robot_radius: float) -> float | None:
    """How far the round footprint can drive straight ahead before it touches a scan point (m).

    0 if a point is inside the footprint already, inf if no point lies in the footprint's way,
    None without a valid reading (no returns: see scan_clearance).
    """
    points = _scan_points(ranges, angle_min, angle_increment, range_min, range_max,
                          lidar_offset_x)
    if points is None:
        return None
    x, y = points
    half_chord = np.sqrt(np.maximum(robot_radius * robot_radius - y * y, 0.0))
    # In the swept band and not behind the footprint's back edge.
    in_way = (np.abs(y) < robot_radius) & (x > -half_chord)
    if not in_way.any():
        return math.inf
    return float(max((x[in_way] - half_chord[in_way]).min(), 0.0))


def _scan_points(ranges: np.ndarray, angle_min: float, angle_increment: float,
                 range_min: float, range_max: float,
                 lidar_offset_x: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(x, y) of the valid readings in the robot's frame (m), or None if there is none."""
    r = np.asarray(ranges, dtype=np.float64)
    valid = return_mask(r, range_min, range_max)
    if not valid.any():
        return None
    cos_a, sin_a = _ray_directions(float(angle_min), float(angle_increment), len(r))
    r = r[valid]
    return lidar_offset_x + r * cos_a[valid], r * sin_a[valid]


@functools.lru_cache(maxsize=8)
def _ray_directions(angle_min: float, angle_increment: float, rays: int):
    """The cosine and sine of every ray's angle (cached: a scan's geometry rarely changes)."""
    angles = angle_min + angle_increment * np.arange(rays)
    return np.cos(angles), np.sin(angles)


class PurePursuit:
    """Regulated pure pursuit of a path (see the module docstring).

    Implements amr_common.plugins.interfaces.PathFollower.
    """

    # Instance attributes of the PathFollower interface (set by the path and control methods).
    state: str
    arrived: bool

    def __init__(self, dt: float, **params: Any) -> None:
        """dt: control period [s]; params: names of `parameter_descriptions()`."""
        if not (finite(dt) and dt > 0):
            raise ValueError(f"PurePursuit: dt must be a positive number of seconds, got {dt!r}")
        self.dt = float(dt)
        self.params = check_parameters(params)
        self.clear_path()

    @staticmethod
    def parameter_descriptions() -> dict[str, tuple[Any, str]]:
        """Each tuning parameter: name -> (default, description with units)."""
        return dict(PARAMETERS)

    @property
    def robot_radius_m(self) -> float:
        """Footprint radius (m) the scan clearances are computed for."""
        return float(self.params["robot_radius_m"])

    @property
    def lidar_offset_x_m(self) -> float:
        """Where the LiDAR sits ahead of the robot centre (m)."""
        return float(self.params["lidar_offset_x_m"])

    # --- the path ------------------------------------------------------------------------
    def clear_path(self) -> None:
        """Forget the path: zero commands (state "idle") until the next set_path()."""
        self._points: np.ndarray | None = None
        self.state = "idle"
        self.arrived = False
        self.cross_track_error: float | None = None
        self.remaining_m: float | None = None
        self._v_last = 0.0

    def set_path(self, points) -> None:
        """Follow a new path (K, 2) from its start; ValueError for non-finite or empty input.

        Repeated points are dropped; a single point is driven to in a straight line.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(pts) == 0 or not np.isfinite(pts).all():
            raise ValueError("PurePursuit: a path needs at least one point, all finite")
        self.clear_path()
        self._points = without_repeats(pts)
        self.state = "rotate"
        if len(self._points) >= 2:
            self._prepare()

    @property
    def path(self) -> np.ndarray | None:
        """The followed path (K, 2), or None."""
        return self._points

    def _prepare(self) -> None:
        pts = self._points
        seg = np.diff(pts, axis=0)
        self._lengths = np.hypot(seg[:, 0], seg[:, 1])
        self._dirs = seg / self._lengths[:, None]
        self._s = np.concatenate([[0.0], np.cumsum(self._lengths)])
        a, b = self._dirs[:-1], self._dirs[1:]
        turns = np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
                                  np.einsum("ij,ij->i", a, b)))
        corners = 1 + np.flatnonzero(turns > self.params["corner_angle_rad"])
        # Section k spans vertices ends[k] .. ends[k + 1].
        self._ends = np.concatenate([[0], corners, [len(pts) - 1]]).astype(int)
        self._section = 0
        self._segment = 0

    # --- control -------------------------------------------------------------------------
    def compute_commands(self, x: float, y: float, theta: float,
                         obstacle_clearance_m: float | None = None,
                         free_ahead_m: float | None = None) -> tuple[float, float]:
        """(v, w) for the robot at pose (x, y, theta) in the path's frame.

        obstacle_clearance_m: footprint clearance from the newest scan (None = unknown, no
        proximity slow-down); free_ahead_m: room straight ahead from it (scan_free_ahead; None =
        unknown, no stop for an obstacle in the way).
        """
        if self._points is None or self.arrived:
            return 0.0, 0.0
        if not all(math.isfinite(v) for v in (x, y, theta)):
            self._v_last = 0.0
            return 0.0, 0.0
        if len(self._points) == 1:  # a lone point: drive to it in a straight line
            self._points = np.vstack([[x, y], self._points])
            if np.hypot(*(self._points[1] - self._points[0])) <= self.params["goal_tolerance_m"]:
                self.arrived, self.state = True, "arrived"
                return 0.0, 0.0
            self._prepare()
        p = self.params
        while True:
            s_robot, end_dir, end_point, remaining, past = self._locate(x, y)
            if abs(self.cross_track_error) > p["max_path_deviation_m"]:
                self.state, self._v_last = "off_path", 0.0
                return 0.0, 0.0
            if self.state == "off_path":
                self.state = "rotate"
            reached = past or math.hypot(x - end_point[0], y - end_point[1]) <= \
                p["goal_tolerance_m"]
            if not reached:
                break
            if self._section == len(self._ends) - 2:
                self.arrived, self.state, self._v_last = True, "arrived", 0.0
                self.remaining_m = 0.0
                return 0.0, 0.0
            self._section += 1  # a sharp corner: turn in place into the next section
            self._segment = int(self._ends[self._section])
            self.state = "rotate"
        self.remaining_m = remaining
        lookahead = min(max(p["lookahead_time_s"] * abs(self._v_last), p["min_lookahead_m"]),
                        p["max_lookahead_m"])
        tx, ty = self._target(s_robot + lookahead, end_point, end_dir)
        alpha = wrap_angle(math.atan2(ty - y, tx - x) - theta)
        if self.state == "blocked":
            self.state = "track"  # until _track finds the way still blocked
        if self.state == "rotate" and abs(alpha) <= p["heading_tolerance_rad"]:
            self.state = "track"
        elif self.state == "track" and abs(alpha) > p["rotate_to_heading_angle_rad"]:
            self.state = "rotate"
        if self.state == "rotate":
            self._v_last = 0.0
            speed = min(max(p["rotate_gain_per_s"] * abs(alpha), p["min_rotate_speed_radps"]),
                        p["rotate_speed_radps"], p["max_angular_speed_radps"])
            return 0.0, math.copysign(speed, alpha)
        return self._track(alpha, math.hypot(tx - x, ty - y), remaining, obstacle_clearance_m,
                           free_ahead_m)

    def _track(self, alpha: float, distance: float, remaining: float,
               obstacle_clearance_m: float | None,
               free_ahead_m: float | None) -> tuple[float, float]:
        p = self.params
        curvature = 2.0 * math.sin(alpha) / max(distance, 1e-6)
        v = p["max_linear_speed_mps"]
        if abs(curvature) * p["regulated_min_radius_m"] > 1.0:
            v /= abs(curvature) * p["regulated_min_radius_m"]
        if obstacle_clearance_m is not None and obstacle_clearance_m < p["proximity_distance_m"]:
            v *= max(p["min_proximity_scale"],
                     max(obstacle_clearance_m, 0.0) / p["proximity_distance_m"])
        v = min(v, max(p["min_approach_speed_mps"], p["approach_gain_per_s"] * remaining))
        if free_ahead_m is not None and free_ahead_m - p["obstacle_stop_distance_m"] < remaining:
            # Something in the way before the stop the path asks for: halt short of it.
            room = max(free_ahead_m - p["obstacle_stop_distance_m"], 0.0)
            v = min(v, p["approach_gain_per_s"] * room)
            if v < 1e-3:
                self.state, self._v_last = "blocked", 0.0
                return 0.0, 0.0
        v = min(v, self._v_last + p["max_linear_accel_mps2"] * self.dt)
        w = curvature * v
        if abs(w) > p["max_angular_speed_radps"]:
            v *= p["max_angular_speed_radps"] / abs(w)
            w = math.copysign(p["max_angular_speed_radps"], w)
        wheel = v + abs(w) * 0.5 * p["track_m"]  # the faster wheel's rim speed
        if wheel > MAX_LINEAR_SPEED:
            v, w = v * MAX_LINEAR_SPEED / wheel, w * MAX_LINEAR_SPEED / wheel
        self._v_last = v
        return v, w

    def _locate(self, x: float, y: float):
        """Project the robot on the current section (moving forward only, within a window).

        Returns (arc length of the projection, direction and point of the section's end,
        distance left along the path to it, whether the robot is past it). Sets
        cross_track_error.
        """
        first = self._segment
        last = int(self._ends[self._section + 1]) - 1
        window_end = np.searchsorted(self._s, self._s[first] + _PROJECTION_WINDOW_M, "right")
        last_window = min(last, max(first, int(window_end) - 1))
        a = self._points[first:last_window + 1]
        d = self._dirs[first:last_window + 1]
        rel = np.column_stack([x - a[:, 0], y - a[:, 1]])
        t = np.clip(np.einsum("ij,ij->i", rel, d), 0.0, self._lengths[first:last_window + 1])
        off = rel - t[:, None] * d
        k = int(np.argmin(np.hypot(off[:, 0], off[:, 1])))
        self._segment = first + k
        seg_dir = self._dirs[self._segment]
        self.cross_track_error = float(seg_dir[0] * off[k, 1] - seg_dir[1] * off[k, 0])
        s_robot = float(self._s[self._segment] + t[k])
        end_index = int(self._ends[self._section + 1])
        end_point, end_dir = self._points[end_index], self._dirs[end_index - 1]
        past = self._segment == end_index - 1 and \
            (x - end_point[0]) * end_dir[0] + (y - end_point[1]) * end_dir[1] >= 0.0
        return s_robot, end_dir, end_point, float(self._s[end_index]) - s_robot, bool(past)

    def _target(self, s: float, end_point: np.ndarray, end_dir: np.ndarray) -> tuple[float, float]:
        """The point at arc length s on the current section, or on its end's extension."""
        s_end = self._s[int(self._ends[self._section + 1])]
        if s >= s_end:
            return (float(end_point[0] + (s - s_end) * end_dir[0]),
                    float(end_point[1] + (s - s_end) * end_dir[1]))
        k = int(np.searchsorted(self._s, s, "right")) - 1
        k = min(max(k, self._segment), len(self._lengths) - 1)
        along = s - self._s[k]
        return (float(self._points[k, 0] + along * self._dirs[k, 0]),
                float(self._points[k, 1] + along * self._dirs[k, 1]))


__all__ = ["PurePursuit", "PARAMETERS", "check_parameters", "scan_clearance", "scan_free_ahead"]
