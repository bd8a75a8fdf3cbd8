"""Sensor and actuation profiles: the course's idealised CoppeliaSim robot and the real Burger.

`ideal` reproduces the course simulator (turtlebot3.md / course-template.md): a 240-ray scan over
360 deg every step from the robot centre with NaN for no return, and an /odometry twist every
step. `turtlebot3` imitates the real TurtleBot3 Burger with its LDS-01: 360 rays at 1 deg from
base_scan, 32 mm behind the robot centre, 0.12-3.5 m, 0.0 for no return, Gaussian range noise
(sigma 0.01 m), a new scan every 0.2 s (5 Hz), /odom with a pose only at 20 Hz, and commands
quantised like turtlebot3_node (int(v * 100) / 100) and limited to 0.22 m/s and 2.84 rad/s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from amr_common.robot import LIDAR_OFFSET_X, MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED


@dataclass(frozen=True)
class SensorProfile:
    """What the simulated robot's sensors and command path look like (ideal or turtlebot3)."""

    name: str
    scan_rays: int
    angle_min: float  # rad, relative to the robot heading; rays go counter-clockwise
    angle_increment: float  # rad
    range_min: float  # m
    range_max: float  # m
    no_return: float  # value reported for rays without a valid return (nan or 0.0)
    range_noise_sigma: float  # m, Gaussian
    scan_period: float | None  # s between new scans; None = every step
    odom_period: float | None  # s between odometry messages; None = every step
    odom_topic: str  # "/odometry" (twist from encoders) | "/odom" (pose only)
    command_resolution: float | None  # commands truncated toward zero to multiples of this
    max_linear: float  # m/s, command limit
    max_angular: float  # rad/s, command limit
    # True: v and w are clipped separately to max_linear / max_angular before the wheel-speed
    # saturation (turtlebot3_node); False: only the wheel-speed saturation, which keeps the
    # curvature (the course robot; it bounds |v| <= 0.22 and |w| <= 2.75 by itself).
    clamp_commands: bool = False
    # m, forward position of the LiDAR (the scan's origin) from the robot centre, along its axis.
    lidar_offset_x: float = 0.0

    @property
    def angle_max(self) -> float:
        """Angle of the last ray, rad."""
        return self.angle_min + (self.scan_rays - 1) * self.angle_increment


IDEAL = SensorProfile(
    name="ideal", scan_rays=240, angle_min=0.0, angle_increment=2.0 * math.pi / 240,
    range_min=0.016, range_max=8.0, no_return=math.nan, range_noise_sigma=0.0,
    scan_period=None, odom_period=None, odom_topic="/odometry", command_resolution=None,
    max_linear=MAX_LINEAR_SPEED, max_angular=MAX_ANGULAR_SPEED)

TURTLEBOT3 = SensorProfile(
    name="turtlebot3", scan_rays=360, angle_min=0.0, angle_increment=2.0 * math.pi / 360,
    range_min=0.12, range_max=3.5, no_return=0.0, range_noise_sigma=0.01,
    scan_period=0.2, odom_period=0.05, odom_topic="/odom", command_resolution=0.01,
    max_linear=MAX_LINEAR_SPEED, max_angular=MAX_ANGULAR_SPEED, clamp_commands=True,
    lidar_offset_x=LIDAR_OFFSET_X)  # base_scan at (-0.032, 0, 0.172) from base_link

PROFILES: dict[str, SensorProfile] = {p.name: p for p in (IDEAL, TURTLEBOT3)}


def get_profile(name: str | SensorProfile) -> SensorProfile:
    """The profile called `name` ("ideal" or "turtlebot3"); a SensorProfile passes through."""
    if isinstance(name, SensorProfile):
        return name
    try:
        return PROFILES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown profile {name!r}; choose one of {sorted(PROFILES)}") from None
