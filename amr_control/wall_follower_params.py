"""The WallFollower's tuning parameters and their checking.

name -> (default, description with units, rule). No rclpy import; the wall_follower node
declares each as a ROS parameter (with its range).
"""
from __future__ import annotations

import math
from typing import Any

from amr_common.plugins.parameter_table import (
    Param,
    at_least,
    between,
    checked_values,
    one_of,
    ruled,
)
from amr_common.robot import MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED, ROBOT_RADIUS, TRACK

# name: (default, description). Defaults work in the simulator's ideal and turtlebot3 profiles.
_TABLE: dict[str, tuple[Any, str]] = {
    "follow_side": ("right", "Wall kept on this side: 'right' (right-hand rule) or 'left'."),
    "wall_distance_m": (0.20, "Target distance from the robot centre to the followed wall [m]."),
    "kp": (10.0, "Proportional gain: angular speed per metre of wall-distance error [rad/s/m]."),
    "kd": (10.0, "Derivative gain: angular speed per m/s of wall-distance rate, the rate being "
                 "estimated from the fitted wall angle at cruise speed [rad/s per m/s]."),
    "max_linear_speed_mps": (0.20, "Cruise (maximum) forward speed [m/s]; at most "
                                   f"{MAX_LINEAR_SPEED}."),
    "max_angular_speed_radps": (MAX_ANGULAR_SPEED, "Hard limit on the commanded angular speed "
                                                   "[rad/s]."),
    "follow_max_angular_speed_radps": (1.5, "Limit on the angular speed while following [rad/s]."),
    "turn_speed_radps": (1.5, "Angular speed of in-place turns [rad/s]."),
    "min_turn_speed_radps": (0.3, "Slowest angular speed at the end of an in-place turn [rad/s]."),
    "front_turn_distance_m": (0.21, "A wall closer than this ahead (from the robot centre) ends "
                                    "straight driving: turn away, turn around or take the side "
                                    "[m]."),
    "front_stop_distance_m": (0.15, "Never drive forward with an obstacle closer than this in the "
                                    "robot's path (from the robot centre) [m]."),
    "front_slowdown_distance_m": (0.15, "Forward speed ramps from 0 at the stop distance to "
                                        "cruise at stop distance + this [m]."),
    "side_window_half_length_m": (0.03, "Points within +-this along x of the robot centre count "
                                        "as beside it for the side-open tests [m]."),
    "side_open_distance_m": (0.32, "A side with nothing closer than this is open (no wall) [m]."),
    "min_gap_width_m": (0.30, "Openings in the followed wall narrower than this are not "
                              "entered [m]."),
    "outer_corner_advance_m": (0.20, "How far past the end of the followed wall the robot drives "
                                     "before turning around the corner [m]."),
    "corner_slowdown_m": (0.06, "Over the last this many metres before an outer corner's "
                                "turn point the forward speed ramps down to settle_speed_mps, "
                                "so the drive's latency and lag do not carry the robot past "
                                "it [m]; 0 = cruise up to the turn."),
    "settle_time_s": (0.3, "Straight driving after an in-place turn before following again [s]."),
    "settle_speed_mps": (0.10, "Forward speed while settling or approaching a wall [m/s]."),
    "sector_half_width_rad": (0.1745, "Half-width of the front/left/right/back sectors [rad]."),
    "wall_fit_half_length_m": (0.15, "Scan points up to this far ahead/behind the robot centre "
                                     "are used to fit the followed wall [m]."),
    "heading_gain_per_s": (2.0, "Angular speed per radian of heading error while driving "
                                "straight between walls (corners, settling) [1/s]."),
    "heading_memory_m": (0.6, "The direction of the last well-fitted wall (or last turn) "
                              "is used to align turns for this far of travel [m]."),
    "escape_islands": (True, "Leave a wall group after one full lap around it with it on the "
                             "followed side (a free-standing obstacle), to explore elsewhere."),
    "range_min_m": (0.016, "Readings below this are invalid when no scan geometry is given [m]."),
    "range_max_m": (8.0, "Readings above this are invalid when no scan geometry is given [m]."),
    "invalid_hold_time_s": (0.6, "A close point whose ray stops returning is kept this long [s]."),
    "invalid_hold_range_m": (0.30, "Only points closer than this are kept when their ray goes "
                                   "invalid (LDS-01 reports 0.0 below 0.12 m) [m]."),
    "robot_radius_m": (ROBOT_RADIUS, "Radius of the robot footprint [m]."),
    "path_margin_m": (0.03, "Lateral margin added to the radius for the swept-path check [m]."),
    "lidar_offset_x_m": (0.0, "Forward position of the LiDAR relative to the robot centre [m] "
                              "(-0.032 on a real Burger)."),
    "track_m": (TRACK, "Wheel separation [m], to keep both wheels within max_linear_speed."),
    "scan_revolution_s": (0.0, "Time one scan's rays span, measured clockwise and stamped at "
                               "the end as the LDS-01/LDS-02 drivers do: each ray is moved "
                               "with the odometry to the stamp (de-skew) [s]; 0.2 on a real "
                               "Burger, 0 when all rays are taken at once (the simulator's "
                               "ideal and turtlebot3_clean profiles)."),
    "memory_time_s": (3.0, "The scans' points stay obstacles for the swept-path check this "
                           "long after a scan last showed a point in their 2 cm cell (the end "
                           "of a thin wall seen end-on returns no ray) [s]; 0 = off."),
    "memory_range_m": (0.7, "Only points this close to the robot centre are remembered [m]."),
}
# Numbers >= 0 but for these; speeds above the Burger's limits are clipped (check_parameters).
PARAMETERS: dict[str, Param] = ruled(
    _TABLE, at_least(0.0), follow_side=one_of("right", "left"), lidar_offset_x_m=None,
    sector_half_width_rad=between(0.0, 0.5 * math.pi, low_open=True, high_open=True))


def check_parameters(overrides: dict[str, Any]) -> dict[str, Any]:
    """Every parameter's value (defaults updated with `overrides`), checked.

    Each against its rule in PARAMETERS; speeds above the Burger's limits are clipped to them.
    Raises ValueError naming every problem, or unknown names.
    """
    checked = checked_values(PARAMETERS, overrides, "WallFollower")
    checked["max_linear_speed_mps"] = min(checked["max_linear_speed_mps"], MAX_LINEAR_SPEED)
    checked["max_angular_speed_radps"] = min(checked["max_angular_speed_radps"], MAX_ANGULAR_SPEED)
    if checked["front_stop_distance_m"] >= checked["front_turn_distance_m"]:
        raise ValueError("WallFollower: front_stop_distance_m must be below front_turn_distance_m")
    return checked
