"""TF (REP 105) for planar robots without tf2_ros: build, publish and read transforms.

The PyPI wheels have no tf2_ros; tf2_msgs/TFMessage comes from third_party/tf2_msgs (built into
the venv, same type hash as Jazzy's). This module is the little of tf2 the project needs:
- `planar_transform(...)`: a geometry_msgs/TransformStamped of a planar pose (x, y, yaw, z),
  filled in place when given one (the simulator refills its transforms every step).
- `TF_QOS` / `TF_STATIC_QOS` (tf2_ros' QoS: /tf reliable depth 100, /tf_static transient
  local) and `StaticTransformBroadcaster`: latched /tf_static, one message with every static
  transform the node sent so far (as tf2_ros does).
- `StaticTransformTree` + `StaticTransformListener`: the /tf_static tree, and the planar offset
  of one frame in another through chains (the Burger's bringup publishes base_footprint ->
  base_link -> base_scan). Roll and pitch are taken as zero: planar robots.
Frames: map -> odom -> base_footprint -> base_scan; the simulator adds map ->
base_footprint_truth (ground truth, for comparison) and the localization node map -> odom.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable

from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from amr_common import geometry
from amr_common.geometry import compose, inverse, map_to_odom
from amr_common.ros.qos import LATCHED

TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    history=HistoryPolicy.KEEP_LAST)
TF_STATIC_QOS = LATCHED
# Subscribers keep more than one: several nodes may each latch their own /tf_static.
TF_STATIC_LISTENER_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                    history=HistoryPolicy.KEEP_LAST,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)


def planar_transform(stamp, parent: str, child: str, x: float, y: float, yaw: float,
                     z: float = 0.0, message: TransformStamped | None = None) -> TransformStamped:
    """TransformStamped placing `child` at (x, y, z) with heading `yaw` (rad) in `parent`."""
    if message is None:
        message = TransformStamped()
    if stamp is not None:
        message.header.stamp = stamp
    message.header.frame_id = parent
    message.child_frame_id = child
    translation = message.transform.translation
    translation.x, translation.y, translation.z = float(x), float(y), float(z)
    rotation = message.transform.rotation
    rotation.x, rotation.y, rotation.z, rotation.w = geometry.yaw_to_quaternion(yaw)
    return message


@dataclass(frozen=True)
class FrameOffset:
    """Where a frame sits in another: x, y, z in metres, yaw in rad (roll, pitch taken as 0)."""

    x: float
    y: float
    z: float
    yaw: float


class StaticTransformTree:
    """The latest static transform of every child frame, and offsets through chains."""

    def __init__(self) -> None:
        self._parents: dict[str, tuple[str, FrameOffset]] = {}

    def add(self, transforms: Iterable[TransformStamped]) -> None:
        """Store transforms (a child's newer transform replaces its older one)."""
        for t in transforms:
            tr, q = t.transform.translation, t.transform.rotation
            values = (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)
            if not all(math.isfinite(v) for v in values):
                continue  # a broken transform must not poison every lookup
            try:
                yaw = geometry.quaternion_to_yaw(q.x, q.y, q.z, q.w)
            except ValueError:
                continue
            self._parents[t.child_frame_id.lstrip("/")] = (
                t.header.frame_id.lstrip("/"), FrameOffset(tr.x, tr.y, tr.z, yaw))

    def offset(self, parent: str, child: str) -> FrameOffset | None:
        """`child` in `parent` through the chain of static transforms, or None if not linked."""
        parent, frame = parent.lstrip("/"), child.lstrip("/")
        pose, z = (0.0, 0.0, 0.0), 0.0
        for _ in range(len(self._parents) + 1):  # bounded: a cycle ends the walk
            if frame == parent:
                return FrameOffset(pose[0], pose[1], z, pose[2])
            link = self._parents.get(frame)
            if link is None:
                return None
            frame, step = link
            pose, z = compose((step.x, step.y, step.yaw), pose), z + step.z
        return None


class StaticTransformBroadcaster:
    """Latched /tf_static publisher: every transform sent so far, in one message (as tf2_ros).

    `publisher_factory` defaults to node.create_publisher; a lifecycle node passes its
    create_lifecycle_publisher and sends after activation.
    """

    def __init__(self, node, publisher_factory: Callable | None = None) -> None:
        factory = publisher_factory or node.create_publisher
        self.publisher = factory(TFMessage, TF_STATIC_TOPIC, TF_STATIC_QOS)
        self._transforms: dict[str, TransformStamped] = {}

    def send(self, transforms: Iterable[TransformStamped]) -> None:
        """Add or replace transforms (by child frame) and publish them all."""
        for t in transforms:
            self._transforms[t.child_frame_id] = t
        self.publisher.publish(TFMessage(transforms=list(self._transforms.values())))


class StaticTransformListener:
    """Subscribes to /tf_static and calls `on_change(tree)` whenever a message arrives."""

    def __init__(self, node, on_change: Callable[[StaticTransformTree], None]) -> None:
        self.tree = StaticTransformTree()
        self._on_change = on_change
        self._node = node
        self.subscription = node.create_subscription(
            TFMessage, TF_STATIC_TOPIC, self._on_message, TF_STATIC_LISTENER_QOS)

    def _on_message(self, message: TFMessage) -> None:
        self.tree.add(message.transforms)
        self._on_change(self.tree)

    def close(self) -> None:
        """Destroy the subscription."""
        if self.subscription is not None:
            self._node.destroy_subscription(self.subscription)
            self.subscription = None


__all__ = ["TF_TOPIC", "TF_STATIC_TOPIC", "TF_QOS", "TF_STATIC_QOS", "TF_STATIC_LISTENER_QOS",
           "planar_transform", "compose", "inverse", "map_to_odom", "FrameOffset",
           "StaticTransformTree", "StaticTransformBroadcaster", "StaticTransformListener"]
