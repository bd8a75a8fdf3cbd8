"""What an /initialpose message asks of the particle filter node, or why it is ignored.

A geometry_msgs/PoseWithCovarianceStamped (RViz's and Foxglove's "2D Pose Estimate"): the pose
in the map frame (an empty frame counts as it) and sigmas from its x, y and yaw variances (zero
or negative variances mean "not given": None, the filter's initial_pose_sigma).
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import PoseWithCovarianceStamped

from amr_common.ros.ros_conversions import pose_from_message


def initial_pose_request(message: PoseWithCovarianceStamped, map_frame: str
                         ) -> tuple[tuple[float, float, float], np.ndarray | None] | str:
    """((x, y, theta), sigma or None) the message asks for, or why it is ignored (a text)."""
    frame = message.header.frame_id
    if frame and frame != map_frame:
        return f"/initialpose in frame '{frame}' ignored: expected '{map_frame}'"
    try:
        x, y, theta = pose_from_message(message.pose.pose)
    except ValueError as exc:
        return f"/initialpose ignored: {exc}"
    cov = np.asarray(message.pose.covariance, dtype=float)
    variances = cov[[0, 7, 35]] if cov.size == 36 else np.zeros(3)
    if not all(math.isfinite(v) for v in (x, y, theta, *variances)):
        return (f"/initialpose ignored: pose ({x}, {y}, {theta}) or variances "
                f"{variances.tolist()} not finite")
    return (x, y, theta), (np.sqrt(variances) if np.all(variances > 0.0) else None)


__all__ = ["initial_pose_request"]
