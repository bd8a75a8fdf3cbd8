"""What the odometry says between two scans, how far to trust it, and how wide to search.

The Mapper's motion prior (no robot constants here: the robot's speeds and its odometry's error
model are parameters, amr_mapping.mapper_params):
- `step`: the odometry's motion since the previous scan and the time it took. Stamps are what
  a log or a driver gave: a real log has scans stamped at or before the one before (the Intel
  log: 265 of its first 5,505, some by 0.9 s, while their odometry poses follow each other
  smoothly in the order they came). Such a scan is mapped like any other, with the odometry pose
  it came with (the slam node interpolates the odometry at its stamp), and counted; the time
  its motion took is taken as at least the typical interval between scans (the median of the
  last ones), so a jittered stamp does not make a normal step look impossibly fast.
- A motion faster than max_linear_speed_mps / max_angular_speed_rps (plus a little slack) is a
  jump (a reset, a glitch): not believed, the scan is searched for around the last pose.
- `deskew`: each ray moved to the robot's frame at the stamp (amr_common.sensors.scan_deskew): the
  rays were measured over the scan's scan_time before the stamp, clockwise
  (lidar_models.revolution_ages), and the motion then is the odometry's since the latest scan
  stamped before it (after a jump: not trusted, the history restarts at rest); a scan out of
  order is de-skewed with the motion of the scans before it (time did not move on).
- `sigmas`: the standard deviations of the odometry's error over a motion (a floor plus a share
  of the distance and of the turn, as Karto's and AMCL's odometry models), and `windows`:
  the correlative search's half-widths, `search_sigmas` of them but no less than
  search_linear_m / search_angular_rad and no more than the max_search_* ones (a fast turn
  searches wider, as Cartographer's real-time matcher and Karto's windows do).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from amr_common.geometry import compose, inverse
from amr_common.sensors.lidar_models import revolution_ages
from amr_common.sensors.scan_deskew import MotionHistory, points_now
from amr_mapping.scan_points import scan_revolution_s

_JUMP_SLACK = (0.05, 0.1)  # m, rad beyond the plausible motion before odometry counts as a jump
_INTERVALS_KEPT = 51  # recent scan intervals whose median is the typical one


@dataclass(frozen=True)
class OdometryStep:
    """The odometry between the previous scan and this one."""

    motion: tuple[float, float, float] | None  # (dx, dy, dtheta) in the previous frame; None: jump
    measured: tuple[float, float, float]  # what the odometry said, believed or not
    dt: float  # s the motion took (at least the typical interval)
    out_of_order: bool  # stamped at or before the latest stamp so far
    # The odometry's motion since the latest scan stamped before this one, over dt_since (s):
    # the motion during this scan's revolution (de-skew); None for a scan out of order.
    since_latest: tuple[float, float, float] | None
    dt_since: float


class OdometryMotion:
    """Consecutive odometry poses and stamps -> OdometryStep; the error model's windows."""

    def __init__(self, params: dict[str, Any]) -> None:
        self.p = params
        self._last_odom: tuple[float, float, float] | None = None
        self._last_stamp = -math.inf
        self._latest_odom: tuple[float, float, float] | None = None  # at _last_stamp
        self._intervals: deque[float] = deque(maxlen=_INTERVALS_KEPT)
        self._history = MotionHistory()  # the odometry's motion over the last scans (de-skew)

    @property
    def last_odom(self) -> tuple[float, float, float] | None:
        """The odometry pose of the latest scan (None before the first)."""
        return self._last_odom

    def typical_interval(self) -> float:
        """Median of the recent positive intervals between scans (s), 0 before any."""
        if not self._intervals:
            return 0.0
        ordered = sorted(self._intervals)
        return ordered[len(ordered) // 2]

    def step(self, odom: tuple[float, float, float], stamp: float) -> OdometryStep | None:
        """Take the next scan's odometry pose and stamp; None for the first scan."""
        previous, previous_stamp, latest = self._last_odom, self._last_stamp, self._latest_odom
        self._last_odom = odom
        out_of_order = stamp <= previous_stamp
        if not out_of_order:
            self._last_stamp, self._latest_odom = stamp, odom
        if previous is None:
            return None
        dt = stamp - previous_stamp
        if dt > 0.0:
            self._intervals.append(dt)
        dt = max(dt, self.typical_interval())
        measured = compose(inverse(previous), odom)
        p = self.p
        jump = (math.hypot(measured[0], measured[1]) > p["max_linear_speed_mps"] * dt
                + _JUMP_SLACK[0]
                or abs(measured[2]) > p["max_angular_speed_rps"] * dt + _JUMP_SLACK[1])
        since = None if out_of_order or jump else compose(inverse(latest), odom)
        return OdometryStep(None if jump else measured, measured, dt, out_of_order, since, dt)

    def deskew(self, scan: Any, points: np.ndarray, angles: np.ndarray,
               step: OdometryStep) -> tuple[np.ndarray, bool]:
        """(the points moved to the robot's frame at the stamp, whether scan_time was usable).

        A scan_time that is not a number, negative or over 1 s: the points as measured.
        """
        if step.motion is None:
            self._history.clear()
        elif step.since_latest is not None:
            self._history.add_motion(step.since_latest, step.dt_since)
        revolution = scan_revolution_s(scan)
        if not revolution or len(points) == 0:
            return points, revolution is not None
        return points_now(points, revolution_ages(angles, revolution), self._history), True

    def sigmas(self, motion: tuple[float, float, float]) -> tuple[float, float]:
        """Standard deviations (m, rad) of the odometry's error over `motion`."""
        p = self.p
        distance, turn = math.hypot(motion[0], motion[1]), abs(motion[2])
        return (p["odometry_sigma_m"] + p["odometry_sigma_per_m"] * distance,
                p["odometry_sigma_rad"] + p["odometry_sigma_per_rad"] * turn)

    def windows(self, motion: tuple[float, float, float] | None) -> tuple[float, float]:
        """Half-widths (m, rad) of the search around the prediction; the widest for a jump."""
        p = self.p
        if motion is None:
            return p["max_search_linear_m"], p["max_search_angular_rad"]
        sigma_m, sigma_rad = self.sigmas(motion)
        n = p["search_sigmas"]
        return (min(max(n * sigma_m, p["search_linear_m"]), p["max_search_linear_m"]),
                min(max(n * sigma_rad, p["search_angular_rad"]), p["max_search_angular_rad"]))


__all__ = ["OdometryMotion", "OdometryStep"]
