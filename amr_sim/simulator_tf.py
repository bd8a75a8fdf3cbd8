"""The simulator node's frames and map: /tf, /tf_static, /map and /map_markers.

What the real Burger's bringup publishes (robot_state_publisher's base_footprint -> base_scan,
turtlebot3_node's odom -> base_footprint with each /odom) plus what only a simulator knows: the
true pose as map -> base_footprint_truth and, for viewers when no localization node runs, the
perfect map -> odom (`map_to_odom_from_truth`). The world is published as /map and
/map_markers, latched. Publishers are lifecycle publishers of the simulator node.
"""
from __future__ import annotations

from typing import Any

from tf2_msgs.msg import TFMessage

from amr_common.coverage_grid import GridTooLargeError
from amr_common.map_messages import MAP_MARKERS_TOPIC, MAP_TOPIC, world_map_messages
from amr_common.qos import LATCHED
from amr_common.robot import LIDAR_HEIGHT
from amr_common.tf import (
    TF_QOS,
    TF_TOPIC,
    StaticTransformBroadcaster,
    map_to_odom,
    planar_transform,
)


class SimulatorTf:
    """Creates the publishers on construction (in on_configure); `destroy()` releases them."""

    def __init__(self, node, simulator, p: dict[str, Any]) -> None:
        self._node = node
        self._simulator = simulator
        self._frames = (p["world_frame"], p["odom_frame"], p["base_frame"], p["truth_frame"])
        self._map_to_odom = bool(p["map_to_odom_from_truth"])
        self._scan_frame = p["scan_frame"]
        self._map_messages = None
        if p["publish_map"]:
            try:
                self._map_messages = world_map_messages(simulator.world, p["map_resolution"],
                                                        p["world_frame"])
            except GridTooLargeError as exc:  # a huge world still simulates, without /map
                node.get_logger().warning(f"no /map: {exc}")
        create = node.create_lifecycle_publisher
        self._tf = create(TFMessage, TF_TOPIC, TF_QOS)
        self._static = StaticTransformBroadcaster(node, create)
        self._map_publishers = [] if self._map_messages is None else [
            create(type(message), topic, LATCHED)
            for message, topic in zip(self._map_messages, (MAP_TOPIC, MAP_MARKERS_TOPIC))]
        # Reused every step (publish copies): odom -> base, map -> truth[, map -> odom].
        self._message = TFMessage(transforms=[
            planar_transform(None, "", "", 0.0, 0.0, 0.0)
            for _ in range(3 if self._map_to_odom else 2)])

    def publish_static(self, stamp) -> None:
        """base_footprint -> base_scan at the profile's LiDAR position, then the map."""
        lidar_x = self._simulator.profile.lidar_offset_x
        self._static.send([planar_transform(stamp, self._frames[2], self._scan_frame,
                                            lidar_x, 0.0, 0.0, LIDAR_HEIGHT)])
        if self._map_messages is not None:
            grid, markers = self._map_messages
            grid.header.stamp = grid.info.map_load_time = stamp
            for marker in markers.markers:
                marker.header.stamp = stamp
            for publisher, message in zip(self._map_publishers, self._map_messages):
                publisher.publish(message)

    def publish(self, stamp, true_pose: tuple[float, float, float]) -> None:
        """The moving frames at `stamp`, while anyone subscribes to /tf (cheap otherwise)."""
        if self._tf.get_subscription_count() == 0:
            return
        world, odom, base, truth = self._frames
        odometry_pose = self._simulator.odometry_pose
        transforms = self._message.transforms
        planar_transform(stamp, odom, base, *odometry_pose, message=transforms[0])
        planar_transform(stamp, world, truth, *true_pose, message=transforms[1])
        if self._map_to_odom:
            planar_transform(stamp, world, odom, *map_to_odom(true_pose, odometry_pose),
                             message=transforms[2])
        self._tf.publish(self._message)

    def destroy(self) -> None:
        """Destroy every publisher this object created."""
        for publisher in [self._tf, self._static.publisher, *self._map_publishers]:
            self._node.destroy_lifecycle_publisher(publisher)
        self._map_publishers = []
