"""The Mapper's parameters: name -> (default, description with units), and their checking.

No rclpy import; the slam node declares each as a ROS parameter. The defaults map the bundled
worlds with the `turtlebot3_clean` and `turtlebot3` profiles (LDS-01: 360 rays, 3.5 m, 2 cm
cells) and a real robot's log with only the sensor's facts changed (the Intel Research Lab:
SICK LMS, 50 m, 5 cm cells; docs/realdata.md). What is the robot's (its speed limits) the run
scripts set for the Burger; the defaults suit faster robots too.
"""
from __future__ import annotations

import math
from typing import Any

from amr_common.plugins.parameter_table import (
    Param,
    above,
    at_least,
    between,
    checked_values,
    one_of,
    ruled,
    vector,
)
from amr_common.sensors.lidar_models import LIDAR_MODELS
from amr_common.sensors.range_calibration import RangeCorrection

MODEL_NAMES = ("none",) + tuple(LIDAR_MODELS)

# name: (default, description)
_TABLE: dict[str, tuple[Any, str]] = {
    # --- sensor
    "lidar_offset_x_m": (0.0, "Forward position of the LiDAR relative to the robot centre [m] "
                              "(-0.032 on a real Burger; the run scripts set the profile's)."),
    "max_range_m": (3.5, "Returns farther than this are not used [m] (the scan's own "
                         "range_max applies as well)."),
    "deskew": (True, "Move each ray to the robot's pose at the scan's stamp with the odometry "
                     "(de-skew): the rays were measured over the scan's scan_time, clockwise, "
                     "before the stamp (the LDS-01/LDS-02 drivers). False for scans taken at "
                     "once (the simulator's ideal and turtlebot3_clean profiles: the run scripts "
                     "set the profile's)."),
    "lidar_model": ("none", "The LiDAR's range-error model: 'none' for exact ranges (the "
                            "simulator's ideal and turtlebot3_clean profiles); 'LDS-01' or "
                            "'LDS-02': how its noise grows with the range (the datasheet's "
                            "precision), for smooth_half_window. The run scripts set the "
                            "simulated profile's, run_robot.py the LDS-01, each with the "
                            "parameters that go with it (range_error_parameters)."),
    "range_correction": ([], "The unit's range calibration: [measured range, correction, ...] "
                             "in m, true = measured + correction, piecewise linear "
                             "(amr_common.sensors.range_calibration; scripts/calibrate_lidar.py "
                             "measures it). [] = as measured."),
    "smooth_half_window": (0, "Range noise smoothing: each return moves onto the line through "
                              "a window of this many neighbours on each side, the most central "
                              "straight one, else the straightest (amr_mapping.scan_smoothing; "
                              "0: off)."),
    "smooth_straightness": (1.5, "... only where that window is straight within this many "
                                 "times the scan's typical window (else as measured)."),
    "min_points": (30, "Scans with fewer valid returns are not matched: the pose follows the "
                       "odometry."),
    # --- occupancy grid
    "resolution_m": (0.02, "Cell size of the map [m]."),
    "max_map_cells": (25_000_000, "Most cells a grid may grow to (4 bytes each; 25 M = a "
                                  "100 m x 100 m map at 2 cm). Rays beyond are dropped, with a "
                                  "warning."),
    "log_odds_hit": (0.9, "Log-odds added to the cell a ray ends in."),
    "log_odds_miss": (0.4, "Log-odds taken from each cell a ray crosses."),
    "occupied_log_odds": (0.6, "A cell is occupied above this log-odds (0.6 = p 0.65, "
                               "map_saver's occupied_thresh)."),
    "occupied_min_hit_share": (0.2, "... and has at least this share of the hits of the "
                                    "most-hit cell around it (within occupied_peak_radius_m): "
                                    "range noise spreads a few hits beside each wall, also "
                                    "behind it where no ray clears them."),
    "occupied_min_hits": (1, "... and was hit at least this often (a far return's noise leaves "
                             "lone hits behind the walls, where no ray clears them)."),
    "occupied_peak_radius_m": (0.02, "How far around a cell its most-hit neighbour is looked for "
                                     "[m] (0.02: the 3 x 3 cells at 2 cm)."),
    "free_log_odds": (-0.4, "A cell is free below this log-odds; between the two: unknown."),
    "miss_stop_m": (0.02, "Rays clear cells only up to this far short of their end [m]: "
                          "grazing rays then do not erode the wall they end on."),
    # --- front end: keyframes and scan-to-map matching
    "keyframe_distance_m": (0.1, "A scan becomes a keyframe (inserted into the map and the "
                                 "pose graph) after the robot moved this far [m] ..."),
    "keyframe_angle_rad": (0.1, "... or turned this much [rad] since the last keyframe."),
    "local_map_keyframes": (160, "Scans are matched against a map of this many latest "
                                 "keyframes (older ones are joined through loop closures); "
                                 "the more, the less the heading random-walks from keyframe "
                                 "to keyframe (Cartographer's submaps: 90-180 scans)."),
    "search_linear_m": (0.1, "Least half-width of the correlative search in x and y around "
                             "the odometry prediction [m] ..."),
    "search_angular_rad": (0.08, "... and in heading [rad]."),
    "search_sigmas": (3.0, "The search covers this many standard deviations of the "
                           "odometry's error over the motion since the last scan "
                           "(odometry_sigma_*): a fast turn searches wider."),
    "max_search_linear_m": (0.4, "A match that scores below min_match_score or lies on the "
                                 "window's edge is searched again over twice the window, up "
                                 "to this half-width [m] ..."),
    "max_search_angular_rad": (0.4, "... and this one in heading [rad]; an odometry jump is "
                                    "searched over these around the last pose."),
    "max_linear_speed_mps": (3.0, "Odometry moving faster than this between two scans is a "
                                  "jump (a reset, a glitch), not believed [m/s] (the run "
                                  "scripts set the robot's: the Burger 0.66) ..."),
    "max_angular_speed_rps": (10.0, "... or turning faster than this [rad/s] (the Burger "
                                    "8.5)."),
    "smear_sigma_m": (0.03, "Standard deviation of the Gaussian that smooths the map for "
                            "scoring [m]."),
    "prior_sigma_m": (0.1, "The search's score is weighted by exp(-d^2 / 2 sigma^2) for a "
                           "distance d from the odometry prediction [m] ..."),
    "prior_sigma_rad": (0.1, "... and likewise for the heading difference [rad]."),
    "odometry_sigma_m": (0.005, "Standard deviation of the odometry's motion between two "
                                "scans, translation [m], plus ..."),
    "odometry_sigma_per_m": (0.05, "... this share of the distance moved [m/m]; weighs the "
                                   "odometry against the scan in the sub-cell refinement and "
                                   "sizes the search (search_sigmas)."),
    "odometry_sigma_rad": (0.005, "The same for rotation [rad], plus ..."),
    "odometry_sigma_per_rad": (0.05, "... this share of the angle turned [rad/rad]."),
    "point_sigma_m": (0.015, "Standard deviation of a scan point about the wall line of its "
                             "map cell, in the sub-cell refinement [m]."),
    "correlative_search": ("branch_and_bound", "How the correlative search finds its optimum: "
                                               "'branch_and_bound' (compiled), or "
                                               "'exhaustive' (every pose scored with numpy: the "
                                               "same optimum, for benchmarks)."),
    "min_match_score": (0.25, "Matches scoring below this (mean smoothed-map value under the "
                              "points, 0..1) are rejected: the pose follows the odometry. A "
                              "quarter of the points on the map's walls still fixes a pose; "
                              "walls seen at grazing angles from many poses weigh little, so a "
                              "good match on a big real map can score 0.3."),
    # --- back end: pose graph and loop closure
    "loop_closure": (True, "Search for loop closures (off: the pose graph is a chain)."),
    "loop_search_radius_m": (1.0, "Earlier keyframes within this distance of the current "
                                  "estimate, plus how far the search window grew "
                                  "(loop_drift_*), are loop-closure candidates [m] ..."),
    "loop_min_travel_m": (5.0, "... if the robot travelled at least this far since [m]."),
    "loop_chain_keyframes": (8, "The candidate's map: this many keyframes on each side of it."),
    "loop_window_m": (0.3, "Half-width of the loop-closure search in x and y right after a "
                           "closure [m] ..."),
    "loop_window_rad": (0.25, "... and in heading [rad]; both grow with the travel since the "
                              "last closure (or since the earlier keyframe, if less):"),
    "loop_drift_per_m": (0.04, "... by this much per metre [m/m] (search_sigmas standard "
                               "deviations of the estimate's drift between closures; the "
                               "Intel log's: 0.3-0.6 % of the travel) ..."),
    "loop_drift_rad_per_m": (0.005, "... and this much per metre in heading [rad/m] ..."),
    "loop_max_window_m": (4.0, "... up to this half-width [m] ..."),
    "loop_max_window_rad": (math.pi, "... and this one in heading [rad] (pi: every heading)."),
    "loop_map_keyframes": (50, "A window wider than loop_window_m matches against the "
                               "candidate's chain and the earlier keyframes within the window: "
                               "at most this many, evenly spaced."),
    "loop_min_score": (0.55, "A loop-closure match must score at least this ..."),
    "loop_ambiguity_ratio": (0.92, "... and the best match farther than "
                                   "loop_ambiguity_distance_m away must score below this share "
                                   "of it (no closure along a featureless corridor)."),
    "loop_ambiguity_distance_m": (0.1, "See loop_ambiguity_ratio [m]."),
    "loop_max_free_share": (0.05, "... and at most this share of the scan's points may land "
                                  "deep in space the candidate's map saw free (a scan placed "
                                  "one corridor over). A match on the window's edge is "
                                  "refused too."),
    "anchor_keyframes": (3, "A loop-closure attempt that finds nothing within "
                            "loop_search_radius_m of the first keyframe matches the scan against "
                            "the map of this many first keyframes (the heading anchor) ..."),
    "anchor_max_shift_m": (0.05, "... and links it to the first unless that would move it "
                                 "more than this [m] ..."),
    "anchor_max_turn_rad": (0.05, "... or turn it more than this [rad] from its estimate."),
    "loop_interval_keyframes": (10, "Loop closure is tried every this many keyframes."),
    "sequential_sigma_m": (0.01, "Standard deviation of a chain link between consecutive "
                                 "keyframes, translation [m] ..."),
    "sequential_sigma_rad": (0.005, "... and rotation [rad]."),
    "loop_sigma_m": (0.02, "Standard deviation of a loop-closure link, translation [m] ..."),
    "loop_sigma_rad": (0.01, "... and rotation [rad] (Huber-robust)."),
    "rerender_tolerance_m": (0.002, "After an optimization, keyframes that moved more than "
                                    "this [m] ..."),
    "rerender_tolerance_rad": (0.002, "... or turned more than this [rad] are redrawn in the "
                                      "map."),
}

# Numbers > 0 but for these; integers >= 1. Checks of several parameters: check_parameters.
PARAMETERS: dict[str, Param] = ruled(
    _TABLE, above(0.0), lidar_offset_x_m=None, free_log_odds=None,
    correlative_search=one_of("branch_and_bound", "exhaustive"),
    lidar_model=one_of(*MODEL_NAMES),
    smooth_half_window=at_least(0), occupied_peak_radius_m=at_least(0.0),
    range_correction=vector(*range(0, 17, 2)),
    **{name: at_least(1) for name in ("min_points", "max_map_cells", "local_map_keyframes",
                                      "loop_chain_keyframes", "loop_interval_keyframes",
                                      "loop_map_keyframes", "anchor_keyframes",
                                      "occupied_min_hits")},
    **{name: at_least(0.0) for name in (
        "miss_stop_m", "keyframe_distance_m", "keyframe_angle_rad", "odometry_sigma_per_m",
        "odometry_sigma_per_rad", "loop_min_travel_m", "rerender_tolerance_m",
        "loop_drift_per_m", "loop_drift_rad_per_m",
        "rerender_tolerance_rad", "occupied_log_odds")},
    **{name: between(0.0, 1.0) for name in ("min_match_score", "occupied_min_hit_share",
                                            "loop_max_free_share")},
    **{name: between(0.0, 1.0, low_open=True) for name in ("loop_min_score",
                                                           "loop_ambiguity_ratio")})


def check_parameters(overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Every parameter's value (defaults updated with `overrides`), checked and normalised.

    Floats, ints and bools, each against its rule in PARAMETERS, then together; ValueError
    naming every bad one.
    """
    values = checked_values(PARAMETERS, overrides, "Mapper")
    problems = []
    if not values["free_log_odds"] < values["occupied_log_odds"]:
        problems.append(f"free_log_odds ({values['free_log_odds']}) must be below "
                        f"occupied_log_odds ({values['occupied_log_odds']})")
    if values["smear_sigma_m"] > 10.0 * values["resolution_m"]:
        # Named by the one changed: a tiny resolution_m is not smear_sigma_m's fault.
        if values["smear_sigma_m"] != PARAMETERS["smear_sigma_m"][0]:
            problems.append(f"smear_sigma_m ({values['smear_sigma_m']}) must be at most 10 "
                            f"cells ({10.0 * values['resolution_m']:g} m)")
        else:
            problems.append(f"resolution_m ({values['resolution_m']}) must be at least "
                            f"smear_sigma_m / 10 ({values['smear_sigma_m'] / 10.0:g} m): the "
                            "matcher smooths the map over at most 10 cells")
    try:
        RangeCorrection.from_list(values["range_correction"])
    except ValueError as exc:
        problems.append(str(exc))
    if problems:
        raise ValueError("Mapper: " + "; ".join(problems))
    return values


def range_error_parameters(lidar_model: str) -> dict[str, Any]:
    """The parameters for a LiDAR whose range error grows with the range (its datasheet's).

    Smooth the noise along straight walls by the model's precision, and keep only each wall's
    most-hit cells within 8 cm, hit at least 3 times, as occupied: measured under the
    simulator's reality gap
    (docs/slam.md, "Mapping figures"). 'none': {} (the defaults: exact ranges). The unit's own
    calibration, range_correction, comes on top.
    """
    if lidar_model == "none":
        return {}
    if lidar_model not in MODEL_NAMES:
        raise ValueError(f"lidar_model must be one of {', '.join(MODEL_NAMES)}, got "
                         f"{lidar_model!r}")
    return {"lidar_model": lidar_model, "smooth_half_window": 7, "occupied_min_hit_share": 0.5,
            "occupied_peak_radius_m": 0.08, "occupied_min_hits": 3}


def parameter_descriptions() -> dict[str, tuple[Any, str]]:
    """Name -> (default, description) of every parameter."""
    return dict(PARAMETERS)


__all__ = ["PARAMETERS", "check_parameters", "parameter_descriptions",
           "range_error_parameters"]
