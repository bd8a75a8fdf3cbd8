"""The TF side of a node that estimates the robot's pose in the map (REP 105).

The particle filter and the SLAM node both send map -> odom and both need the LiDAR position:
- map -> odom on /tf: `publish_map_to_odom(estimate, odometry, stamp)` sends the transform that
  makes map -> odom -> base_footprint equal the estimate, given an Odometry message's pose (what
  AMCL sends, with every /pose whose estimate is finite); `publish(transform, stamp)` sends one
  the node computed itself (SLAM). Stamped with the scan's stamp.
- base_footprint -> base_scan from /tf_static (the simulator and the Burger's bringup publish
  it): its x is the LiDAR position the node uses; its `lidar_offset_x_m` is the fallback.
"""
from __future__ import annotations

import math
from typing import Callable

from tf2_msgs.msg import TFMessage

from amr_common.ros.ros_conversions import pose_from_message
from amr_common.ros.tf import (
    TF_QOS,
    TF_TOPIC,
    StaticTransformListener,
    StaticTransformTree,
    map_to_odom,
    planar_transform,
)


class MapOdomTf:
    """Publisher of map -> odom and listener of the LiDAR's static frame, for one node."""

    def __init__(self, node, frames: dict[str, str],
                 on_lidar_offset: Callable[[float], None]) -> None:
        """Create the /tf lifecycle publisher and the /tf_static listener on `node`.

        `frames`: map_frame, odom_frame, base_frame and scan_frame names. `on_lidar_offset(x)`
        is called with the LiDAR's x in the base frame whenever /tf_static gives a new one.
        """
        self._node = node
        self._frames = frames
        self._on_lidar_offset = on_lidar_offset
        self._lidar_offset: float | None = None
        self._message = TFMessage(transforms=[planar_transform(
            None, frames["map_frame"], frames["odom_frame"], 0.0, 0.0, 0.0)])
        self.publisher = node.create_lifecycle_publisher(TFMessage, TF_TOPIC, TF_QOS)
        self.listener = StaticTransformListener(node, self._on_static_transforms)

    def publish_map_to_odom(self, estimate: tuple[float, float, float], odometry, stamp) -> bool:
        """Send map -> odom for `estimate` and the /odometry message's pose; False if unusable."""
        if not all(math.isfinite(v) for v in estimate):
            return False
        try:
            odom_to_base = pose_from_message(odometry.pose.pose)
        except ValueError:
            return False
        if not all(math.isfinite(v) for v in odom_to_base):
            return False
        return self.publish(map_to_odom(estimate, odom_to_base), stamp)

    def publish(self, transform: tuple[float, float, float], stamp) -> bool:
        """Send map -> odom = `transform` (x, y, yaw); False (nothing sent) if not finite."""
        if not all(math.isfinite(v) for v in transform):
            return False
        f = self._frames
        planar_transform(stamp, f["map_frame"], f["odom_frame"], *transform,
                         message=self._message.transforms[0])
        self.publisher.publish(self._message)
        return True

    def _on_static_transforms(self, tree: StaticTransformTree) -> None:
        offset = tree.offset(self._frames["base_frame"], self._frames["scan_frame"])
        if offset is None or offset.x == self._lidar_offset:
            return
        if not math.isfinite(offset.x) or abs(offset.x) > 1.0:
            self._node.get_logger().warning(
                f"/tf_static places the LiDAR at x = {offset.x} m: ignored",
                throttle_duration_sec=10.0)
            return
        self._lidar_offset = offset.x
        self._on_lidar_offset(offset.x)

    def close(self) -> None:
        """Destroy the publisher and the listener."""
        self.listener.close()
        self._node.destroy_lifecycle_publisher(self.publisher)
