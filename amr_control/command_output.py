"""The /cmd_vel end of the controller nodes (wall follower, pure pursuit).

One publisher, one reused message, the node parameters every commanding node checks the same
way, and the forced final zero a robot without a command timeout needs.
"""
from __future__ import annotations

import math
from typing import Any

from geometry_msgs.msg import Twist, TwistStamped
from rclpy.lifecycle import LifecycleNode
from rclpy.publisher import Publisher

from amr_common.qos import RELIABLE_10
from amr_common.robot import MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED


def command_parameter_problems(p: dict[str, Any]) -> list[str]:
    """What is wrong with the commanding parameters dt, angular_sign and data_timeout."""
    problems = []
    if not (isinstance(p["dt"], (int, float)) and not isinstance(p["dt"], bool)
            and math.isfinite(p["dt"]) and p["dt"] > 0):
        problems.append(f"dt must be a positive number of seconds (got {p['dt']})")
    if p["angular_sign"] not in (1, -1):
        problems.append(f"angular_sign must be 1 or -1 (got {p['angular_sign']})")
    if not (isinstance(p["data_timeout"], (int, float)) and math.isfinite(p["data_timeout"])
            and p["data_timeout"] > 0):
        problems.append(f"data_timeout must be > 0 s (got {p['data_timeout']})")
    return problems


def limit_command(v: float, w: float) -> tuple[float, float]:
    """(v, w) clipped to the Burger's limits; (0, 0) if either is not finite."""
    if not (math.isfinite(v) and math.isfinite(w)):
        return 0.0, 0.0
    return (min(max(v, -MAX_LINEAR_SPEED), MAX_LINEAR_SPEED),
            min(max(w, -MAX_ANGULAR_SPEED), MAX_ANGULAR_SPEED))


class CommandOutput:
    """A lifecycle publisher of TwistStamped (frame base_footprint) or Twist commands."""

    def __init__(self, node: LifecycleNode, topic: str, stamped: bool,
                 angular_sign: int = 1) -> None:
        """Create the publisher on `node` (call in on_configure)."""
        self.node = node
        self.stamped = stamped
        self.angular_sign = angular_sign
        # One message object reused: publish() serializes it at once, and building a
        # TwistStamped per step is a noticeable share of the lockstep loop.
        self._message = TwistStamped() if stamped else Twist()
        if stamped:
            self._message.header.frame_id = "base_footprint"
        self._publisher: Publisher | None = node.create_lifecycle_publisher(
            TwistStamped if stamped else Twist, topic, RELIABLE_10)

    def publish(self, v: float, w: float, stamp, force: bool = False) -> None:
        """Send (v, w).

        `force`: even while the lifecycle publisher is deactivated (a final zero on the way
        down).
        """
        if self._publisher is None:
            return
        msg = self._message
        twist = msg.twist if self.stamped else msg
        twist.linear.x = v
        twist.angular.z = self.angular_sign * w
        if self.stamped:
            msg.header.stamp = stamp
        if force:
            Publisher.publish(self._publisher, msg)
        else:
            self._publisher.publish(msg)

    def publish_zero(self, why: str, stamp=None, force: bool = False) -> None:
        """Send a zero command and log why.

        stamp: the newest measurement's simulated stamp in lockstep, None for the node's clock.
        """
        if self._publisher is None:
            return
        self.node.get_logger().info(f"{why}: commanding zero velocity")
        self.publish(0.0, 0.0, stamp if stamp is not None else
                     self.node.get_clock().now().to_msg(), force=force)

    def destroy(self) -> None:
        """Release the publisher (on_cleanup / on_shutdown). Idempotent."""
        publisher, self._publisher = self._publisher, None
        if publisher is not None:
            self.node.destroy_lifecycle_publisher(publisher)


__all__ = ["CommandOutput", "command_parameter_problems", "limit_command"]
