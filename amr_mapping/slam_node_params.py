"""The slam node's own parameters (the Mapper's are amr_mapping.mapper_params) and their checks.

No rclpy import: the run scripts check -p / --slam-param values with these before any node
exists.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from amr_common.plugins.loader import DEFAULT_MAPPER
from amr_common.plugins.parameter_table import finite

NODE_PARAMETERS: dict[str, tuple[Any, str]] = {
    "mapper": (DEFAULT_MAPPER, "Mapper class as MODULE:CLASS implementing "
                               "amr_common.plugins.interfaces.Mapper (its tuning values become "
                               "parameters of this node)"),
    "scan_topic": ("/scan", "sensor_msgs/LaserScan input (subscribed best effort)"),
    "odometry_topic": ("/odometry", "nav_msgs/Odometry input whose POSE is used: the "
                                    "project's /odometry (simulator, amr_odometry) or a "
                                    "robot's /odom"),
    "map_topic": ("/map", "nav_msgs/OccupancyGrid output (transient local)"),
    "pose_topic": ("/slam_pose", "amr_msgs/PoseStamped output: the SLAM pose with every mapped "
                                 "scan (localized: matched to the map)"),
    "map_frame": ("map", "Frame of /map and /slam_pose"),
    "odom_frame": ("odom", "Odometry frame: map -> odom_frame goes on /tf"),
    "base_frame": ("base_footprint", "Robot frame: the LiDAR position is read from /tf_static "
                                     "as base_frame -> scan_frame"),
    "scan_frame": ("base_scan", "LiDAR frame; without it on /tf_static, lidar_offset_x_m is "
                                "used"),
    "publish_tf": (True, "Publish map -> odom on /tf (off when another node does)"),
    "map_update_interval_s": (1.0, "Least time between two /map messages, node clock [s] "
                                   "(slam_toolbox's map_update_interval); /map only when the "
                                   "map changed"),
    "transform_publish_period_s": (0.05, "Between scans, map -> odom is sent again with the "
                                         "odometry at most this often, stamp time [s] (0: with "
                                         "every odometry message)"),
    "map_start_pose": ([0.0, 0.0, 0.0], "Pose [x, y, theta] of the robot in the map frame at "
                                        "the first scan (slam_toolbox's map_start_pose) [m, m, "
                                        "rad]"),
    "output_prefix": ("", "Save the map as PREFIX.yaml + PREFIX.pgm on deactivate and shutdown "
                          "(Ctrl-C included); empty: only when ~/save_map is called"),
    "image_format": ("pgm", "Image format of saved maps: pgm (map_saver's default) or png"),
    "max_odometry_gap_s": (0.5, "A scan between two odometry poses farther apart than this "
                                "(stamp time) is not mapped: its pose would be a guess [s]"),
    "skip_repeated_scans": (True, "Skip a scan whose ranges equal the previous one's (the "
                                  "lockstep simulator re-sends its held scan every step)"),
}


def node_parameters() -> dict[str, tuple[Any, str]]:
    """The node's own parameters (not the Mapper's): name -> (default, description)."""
    return dict(NODE_PARAMETERS)


def node_parameter_problems(node: dict[str, Any]) -> list[str]:
    """What is wrong with the node's own parameter values (typed as declared)."""
    problems = []
    for name, low in (("map_update_interval_s", 0.0), ("max_odometry_gap_s", 0.0)):
        if not finite(node[name]) or node[name] <= low:
            problems.append(f"{name} must be a number > 0 (got {node[name]!r})")
    if not finite(node["transform_publish_period_s"]) or node["transform_publish_period_s"] < 0:
        problems.append(f"transform_publish_period_s must be a number >= 0 (got "
                        f"{node['transform_publish_period_s']!r})")
    start = node["map_start_pose"]
    if len(start) != 3 or not all(finite(v) for v in start):
        problems.append(f"map_start_pose must be [x, y, theta], finite (got {list(start)!r})")
    if node["image_format"] not in ("pgm", "png"):
        problems.append(f"image_format must be pgm or png (got {node['image_format']!r})")
    if node["output_prefix"]:
        problems += output_prefix_problems(node["output_prefix"])
    return problems


def output_prefix_problems(prefix: str) -> list[str]:
    """Why maps could not be saved at PREFIX (its folder is created if missing), or nothing."""
    folder = Path(prefix).expanduser().parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return [f"output_prefix '{prefix}': cannot create its folder: {exc.strerror or exc}"]
    if not os.access(folder, os.W_OK | os.X_OK):
        return [f"output_prefix '{prefix}': its folder {folder} is not writable"]
    return []



def configured_line(node: dict[str, Any], mapper_params: dict[str, Any],
                    lidar_offset_x_m: float, start: tuple[float, float, float]) -> str:
    """The slam node's log line once configured: its mapper and the settings that matter."""
    p = mapper_params
    return (f"configured: mapper {node['mapper']}"
            + (f", {100 * p['resolution_m']:g} cm cells" if "resolution_m" in p else "")
            + (f", loop closure {'on' if p['loop_closure'] else 'off'}"
               if "loop_closure" in p else "")
            + (f", scans {'de-skewed' if p['deskew'] else 'taken as instantaneous'}"
               if "deskew" in p else "")
            + f", odometry from {node['odometry_topic']}, map start pose {list(start)}, "
            f"LiDAR at x = {lidar_offset_x_m} m until /tf_static says otherwise"
            + (f", saved to {node['output_prefix']}.yaml on the way down"
               if node["output_prefix"] else ""))


__all__ = ["NODE_PARAMETERS", "configured_line", "node_parameter_problems", "node_parameters",
           "output_prefix_problems"]
