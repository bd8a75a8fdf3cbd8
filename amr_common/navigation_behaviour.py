"""The behaviour rules of the chain explore -> localize -> plan -> follow -> goal, written once.

The ROS nodes (wall follower, particle filter, planner, pure pursuit, simulator) and the headless
episodes of amr_evaluation both call these plain objects, so a headless figure is the ROS graph's
(tests/test_headless_is_the_ros_graph.py runs the same episode both ways and compares the
trajectories). No rclpy here: each rule is unit-tested without ROS.

- `as_sent_ranges`, `as_sent_scan_geometry`, `as_sent_pose`, `stamp_ns`, `limit_command`: what
  crosses a topic - a LaserScan carries float32 ranges and angles, a pose its yaw as a
  quaternion, a stamp whole nanoseconds, a command the Burger's limits.
- `ScanNovelty`: what counts as a new scan (readings that differ from the previous scan's).
- `OdometryClock`: the time over which an odometry twist moves the pose (stamps, gaps, jumps).
- `OdometryHold`: the odometry twist a controller sees between two /odom messages.
- `timer_action`: what a commanding node does with missing or stale data (robot mode).
- `Handover`: who commands (the explorer until localized, then the path follower) and when to
  (re)plan: on the first localization and after each relocalization.
- `GoalCheck`: the goal reached (true position within tolerance while localized) and the run
  over (then rested for rest_time).
- `KidnapSchedule`: the robot teleported once at a given simulated time.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from amr_common.geometry import quaternion_to_yaw, yaw_to_quaternion
from amr_common.robot import MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED

NS_PER_S = 1_000_000_000


# --- what crosses a topic -----------------------------------------------------------------

def as_sent_ranges(ranges) -> np.ndarray:
    """The ranges as a sensor_msgs/LaserScan carries them (float32), as float64."""
    return np.asarray(ranges, dtype=np.float32).astype(np.float64)


def as_sent_scan_geometry(angle_min: float, angle_increment: float, rays: int,
                          range_min: float, range_max: float) -> tuple:
    """A scan geometry as a LaserScan carries it: its angles and limits are float32."""
    def f32(value: float) -> float:
        return float(np.float32(value))
    return f32(angle_min), f32(angle_increment), int(rays), f32(range_min), f32(range_max)


def as_sent_pose(pose: Sequence[float]) -> tuple[float, float, float]:
    """(x, y, theta) as a geometry_msgs/Pose carries it: the yaw through its quaternion."""
    x, y, theta = (float(v) for v in pose)
    return x, y, quaternion_to_yaw(*yaw_to_quaternion(theta))


def stamp_ns(seconds: float) -> int:
    """A message stamp of a time in seconds: whole nanoseconds (as ros_conversions rounds)."""
    return round(seconds * NS_PER_S)


def limit_command(v: float, w: float) -> tuple[float, float]:
    """(v, w) clipped to the Burger's limits; (0, 0) if either is not finite."""
    if not (math.isfinite(v) and math.isfinite(w)):
        return 0.0, 0.0
    return (min(max(v, -MAX_LINEAR_SPEED), MAX_LINEAR_SPEED),
            min(max(w, -MAX_ANGULAR_SPEED), MAX_ANGULAR_SPEED))


# --- sensors --------------------------------------------------------------------------------

class ScanNovelty:
    """What counts as a new scan: readings that differ from the previous scan's.

    The lockstep simulator re-publishes the turtlebot3's 5 Hz scan every step and a standing
    robot's ideal scan repeats: neither is new evidence (the particle filter then weighs it only
    by time). Compared as float32, as the LaserScan carries it.
    """

    def __init__(self) -> None:
        self._last: bytes | None = None

    def is_new(self, ranges, geometry: tuple = ()) -> bool:
        """True (and remembered) if the ranges (or the scan geometry) differ from the previous."""
        key = np.ascontiguousarray(ranges, dtype=np.float32).tobytes() + repr(geometry).encode()
        if key == self._last:
            return False
        self._last = key
        return True


class OdometryClock:
    """The time over which each odometry twist moves the pose, from the message stamps (ns).

    The first message only starts the clock; a stamp that repeats or goes back is not
    integrated (back by more than max_gap_s: the clock restarts from it, so one bogus stamp far
    in the future cannot stop the integration for good); a gap longer than max_gap_s is not
    integrated across (the motion in it is lost).
    """

    def __init__(self, max_gap_s: float = 1.0) -> None:
        self.max_gap_s = float(max_gap_s)
        self._last_ns: int | None = None

    @property
    def last_ns(self) -> int | None:
        """The stamp the clock stands at: the newest odometry integrated to (None: none yet)."""
        return self._last_ns

    def advance(self, stamp: int) -> tuple[float | None, str]:
        """(dt to integrate or None, why): "ok", "first", "back", "jumped back", "gap"."""
        last, self._last_ns = self._last_ns, stamp
        if last is None:
            return None, "first"
        dt = (stamp - last) * 1e-9
        if dt <= 0.0:
            jumped = -dt > self.max_gap_s
            self._last_ns = stamp if jumped else last
            return None, "jumped back" if jumped else "back"
        if dt > self.max_gap_s:
            return None, "gap"
        return dt, "ok"


class OdometryHold:
    """What a controller sees of the odometry: the real robot's only changes with each /odom.

    period None: new values every step (the lockstep /odometry); else once every `period`
    seconds of simulated time, held in between. The values are the twist (v, w), optionally
    followed by more (an odometry pose).
    """

    def __init__(self, period: float | None, *values) -> None:
        self.period = period
        self.held = tuple(values)
        self._next = 0.0

    @property
    def twist(self) -> tuple[float, float]:
        """The held (v, w)."""
        return self.held[0], self.held[1]

    def update(self, time: float, *values) -> tuple:
        """The values to use after a step that measured `values` at simulated `time`."""
        if self.period is None:
            self.held = tuple(values)
        elif time >= self._next - 1e-9:
            self.held = tuple(values)
            while self._next <= time + 1e-9:
                self._next += self.period
        return self.held


# --- who commands ---------------------------------------------------------------------------

def timer_action(age_s: float | None, timeout_s: float, in_charge: bool) -> str:
    """What a commanding node does on its robot-mode timer with its newest data.

    "zero" when there is none or it is older than timeout_s (a robot never keeps moving on
    stale data, whoever commanded it), "silent" when fresh data says another node commands,
    else "compute". The lockstep graph and the headless episodes never see stale data: each
    step waits for its measurement.
    """
    if age_s is None or age_s > timeout_s:
        return "zero"
    return "compute" if in_charge else "silent"



class Handover:
    """Who commands, and when to plan: the explorer until localized, then the path follower.

    `update(localized)` with each pose estimate returns the event it makes:
    "localized" (the first time: plan), "relocalized" (after a loss: plan again, unless
    replan_on_relocalization is off), "lost" (the follower stops and forgets its path; the
    explorer takes over) or None. The explorer computes on every measurement either way (so its
    perception stays current); its command is used only while `explorer_in_charge`.
    """

    def __init__(self, replan_on_relocalization: bool = True) -> None:
        self.replan_on_relocalization = replan_on_relocalization
        self.localized = False
        self.ever_localized = False

    def update(self, localized: bool) -> str | None:
        """The event this estimate makes (see the class docstring)."""
        was, self.localized = self.localized, bool(localized)
        if self.localized and not was:
            first = not self.ever_localized
            self.ever_localized = True
            return "localized" if first else "relocalized"
        if was and not self.localized:
            return "lost"
        return None

    def plans(self, event: str | None) -> bool:
        """True if this event asks for a (new) path."""
        return event == "localized" or (event == "relocalized" and self.replan_on_relocalization)

    @property
    def explorer_in_charge(self) -> bool:
        """True while the explorer (the wall follower) commands: not localized."""
        return not self.localized


class GoalCheck:
    """The goal reached, and the run over.

    Reached: the TRUE position within `tolerance` of the goal while the estimate is localized
    (as the course simulator counts it). Over: once reached, the robot has been commanded to
    rest (a zero command) for `rest_time` seconds (at once for 0), so the final error is
    measured where it stops.
    """

    def __init__(self, goal: Sequence[float] | None, tolerance: float, rest_time: float) -> None:
        self.goal = None if goal is None else (float(goal[0]), float(goal[1]))
        self.tolerance = float(tolerance)
        self.rest_time = float(rest_time)
        self.reached_time: float | None = None
        self.rest_since: float | None = None

    def update(self, time: float, position: Sequence[float], localized: bool, resting: bool,
               dt: float) -> bool:
        """After the step to `time` (commanded zero: `resting`): True once the run is over."""
        if self.reached_time is None:
            if self.goal is None or not localized or self.distance(position) > self.tolerance:
                return False
            self.reached_time = time
        if not resting:
            self.rest_since = None
        elif self.rest_since is None:
            self.rest_since = time - dt  # the zero command began this step
        rest = 0.0 if self.rest_since is None else time - self.rest_since
        return rest >= self.rest_time - 1e-9

    def distance(self, position: Sequence[float]) -> float:
        """Distance (m) of a position to the goal."""
        return math.hypot(position[0] - self.goal[0], position[1] - self.goal[1])


class KidnapSchedule:
    """The robot teleported once: (t, x, y, theta), at the first step from simulated time t on."""

    def __init__(self, kidnap: Sequence[float] | None) -> None:
        self.kidnap = None if kidnap is None else [float(v) for v in kidnap]
        self.done = kidnap is None

    def due(self, time: float) -> tuple[float, float, float] | None:
        """The pose to teleport to before the step from `time`, once; else None."""
        if self.done or time < self.kidnap[0] - 1e-9:
            return None
        self.done = True
        return self.kidnap[1], self.kidnap[2], self.kidnap[3]
