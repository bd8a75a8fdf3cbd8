"""Calibrating a simulated LiDAR unit's ranges the way a Burger's owner calibrates a real one.

The simulated robot stands facing a flat wall at tape-measured distances (from the LiDAR's
centre), the unit takes `scans` scans at each, and amr_common.sensors.range_calibration turns the
readings into the `range_correction` the Mapper applies. The unit is the one a run with the
same profile and seed drives (the reality-gap effects are drawn from the seed); nothing is
read from the simulator but its scans.

    correction = calibrate_in_simulation("turtlebot3:randomized", seed=3)
    correction.as_list()   # the Mapper's range_correction parameter
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from amr_common.robot import ROBOT_RADIUS
from amr_common.sensors.range_calibration import (
    RangeCorrection,
    fit_correction,
    wall_distance,
    wall_points,
)
from amr_common.world.world import World
from amr_sim.profiles import SensorProfile, get_profile
from amr_sim.simulator import Simulator

CALIBRATION_DISTANCES_M = (0.3, 1.0, 2.0)  # one below the LDS-01's 0.5 m band edge, two above
CALIBRATION_SCANS = 25
_WALL_X = 3.0  # the calibration room: 3.2 m x 2 m, the wall at x = 3 m, the robot facing it
_BACK_X = -0.2  # the room's wall behind the robot


def calibration_world() -> World:
    """A bare room whose wall at x = 3 m the robot faces (its other walls are farther)."""
    boundary = np.array([[_BACK_X, -1.0], [_WALL_X, -1.0], [_WALL_X, 1.0], [_BACK_X, 1.0],
                         [_BACK_X, -1.0]])
    segments = np.hstack([boundary[:-1], boundary[1:]]).astype(np.float64)
    return World(name="calibration", source="calibration", segments=segments,
                 boundary=boundary)


def distance_limits(profile: str | SensorProfile) -> tuple[float, float]:
    """(closest, farthest) distances from the LiDAR's centre to the wall it can calibrate at.

    Closer, the robot's body would touch the wall (or the wall would lie within the LiDAR's
    range_min); farther, its back would be through the calibration room's back wall.
    """
    prof = get_profile(profile)
    body = ROBOT_RADIUS + 0.001  # a millimetre off the walls, so rounding cannot touch them
    return (round(max(body - prof.lidar_offset_x, prof.range_min), 6),
            round(_WALL_X - _BACK_X - body - prof.lidar_offset_x, 6))


def wall_reading(profile: str | SensorProfile, seed: int, distance: float,
                 scans: int = CALIBRATION_SCANS) -> float | None:
    """wall_distance() of `scans` scans with the LiDAR `distance` from the wall."""
    prof = get_profile(profile)
    start = (_WALL_X - distance - prof.lidar_offset_x, 0.0, 0.0)
    sim = Simulator(calibration_world(), start=start, dt=0.05, profile=prof, seed=seed)
    points, last = [], sim.scan_time
    while len(points) < scans:
        ranges = sim.step(0.0, 0.0)[0]
        if sim.scan_time == last:
            continue
        last = sim.scan_time
        angle_min, increment = sim.scan_geometry[:2]  # the newest scan's (the LDS-02 changes it)
        points.append(wall_points(ranges, angle_min, increment))
    return wall_distance(np.vstack(points))


@lru_cache(maxsize=64)
def calibrate_in_simulation(profile: str, seed: int,
                            distances: tuple[float, ...] = CALIBRATION_DISTANCES_M,
                            scans: int = CALIBRATION_SCANS) -> RangeCorrection:
    """The unit's range correction from its readings at `distances` (see the module docstring).

    ValueError (one line) when the unit gives no reading of the wall at one of them (a profile
    whose rays nearly all drop out, or whose noise scatters them off any line).
    """
    try:
        return fit_correction({d: wall_reading(profile, seed, d, scans) for d in distances})
    except ValueError as exc:
        raise ValueError(f"the LiDAR of profile {getattr(profile, 'name', profile)}, seed "
                         f"{seed} cannot be calibrated for SLAM's range correction ({exc}: too "
                         "few of its returns lie on the wall's line)") from None


__all__ = ["CALIBRATION_DISTANCES_M", "calibrate_in_simulation", "calibration_world",
           "distance_limits", "wall_reading"]
