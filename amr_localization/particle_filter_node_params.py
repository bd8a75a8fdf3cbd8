"""The particle filter node's own parameters (the filter's are particle_filter_params) and checks.

No rclpy import: the run scripts check -p / --pf-param values with these before any node
exists.
"""
from __future__ import annotations

from typing import Any

from amr_common.plugins.loader import DEFAULT_LOCALIZER
from amr_common.plugins.parameter_table import Param, at_least, between, check_values, ruled

NODE_PARAMETERS: dict[str, Param] = ruled({
    "world": ("lab02", "Bundled world name or path to a world .yaml / course map .json / Nav2 "
                       "map .yaml (the simulator's loader)"),
    "localizer": (DEFAULT_LOCALIZER, "Localizer class as MODULE:CLASS implementing "
                                     "amr_common.plugins.interfaces.Localizer (its tuning values "
                                     "become parameters of this node)"),
    "queue_size": (10, "Synchronizer queue size per input"),
    "slop": (0.15, "Synchronizer slop in seconds (lockstep stamps are equal; the real robot's "
                   "/odometry and /scan differ by up to half an odometry period)"),
    "max_odometry_gap_s": (1.0, "Odometry messages further apart than this (stamp time) are not "
                                "integrated across the gap (the data in between is lost)"),
    "max_scan_age_s": (1.0, "Report localized false when the last usable scan is older than "
                            "this (stamp time)"),
    "min_valid_share": (0.1, "A scan with fewer valid readings than this share is skipped"),
    "particles_period_s": (0.5, "Least stamp time between two /particles messages (0 = every "
                                "/pose)"),
    "particles_published": (500, "Most particles in one /particles message (evenly picked)"),
    "map_frame": ("map", "Frame of /pose, /amcl_pose and /particles"),
    "odom_frame": ("odom", "Odometry frame: map -> odom_frame goes on /tf"),
    "base_frame": ("base_footprint", "Robot frame: the LiDAR position is read from /tf_static "
                                     "as base_frame -> scan_frame"),
    "scan_frame": ("base_scan", "LiDAR frame; without it on /tf_static, lidar_offset_x_m is "
                                "used"),
    "publish_tf": (True, "Publish map -> odom on /tf with every /pose (off when another node "
                         "does, e.g. a simulator's ground truth)"),
    "odometry_topic": ("/odometry", "nav_msgs/Odometry input with twist filled"),
    "scan_topic": ("/scan", "sensor_msgs/LaserScan input (subscribed best effort)"),
    "pose_topic": ("/pose", "amr_msgs/PoseStamped output (with localized)"),
    "amcl_pose_topic": ("/amcl_pose", "geometry_msgs/PoseWithCovarianceStamped output"),
    "particles_topic": ("/particles", "geometry_msgs/PoseArray output"),
    "initialpose_topic": ("/initialpose", "geometry_msgs/PoseWithCovarianceStamped input"),
}, at_least(0.0), min_valid_share=between(0.0, 1.0), queue_size=at_least(1),
    particles_published=at_least(1))


def node_parameters() -> dict[str, tuple[Any, str]]:
    """The node's own parameters (not the filter's): name -> (default, description)."""
    return dict(NODE_PARAMETERS)


def node_parameter_problems(node: dict[str, Any]) -> list[str]:
    """What is wrong with the node's own parameter values: each against its rule."""
    return check_values(NODE_PARAMETERS, node)[1]
