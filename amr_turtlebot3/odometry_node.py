"""The `amr_odometry` lifecycle node: the robot's /odom (pose) -> /odometry (pose + velocities).

The TurtleBot3 publishes nav_msgs/Odometry on /odom; the controller reads twist.twist.linear.x and
twist.twist.angular.z from /odometry. This node republishes each incoming message with those two
fields estimated from consecutive poses (amr_turtlebot3.velocity_estimator: signed, right across
+-pi, reset on time jumps). Pose, covariances, frames and the header stamp are preserved, so
/odometry stays synchronizable with /scan.

Nothing is published for a first message (nor the first after a reset, a duplicate stamp, a
stamp less than 1 ms after the previous one, a rejected pose or a physically impossible pose
jump): a zero twist would be false for a moving robot. The last three are logged (throttled).
Messages received while inactive are ignored, and activation restarts the estimator.

Parameters: max_gap, smoothing_time_constant, input_topic, output_topic (see _PARAMETERS).
Both topics are reliable, KeepLast(10), like the robot's /odom.
"""
from __future__ import annotations

from nav_msgs.msg import Odometry
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn

from amr_common.plugins.parameter_table import Param, above, at_least, ruled
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_parameters, read_parameters
from amr_common.ros.qos import RELIABLE_10
from amr_common.ros.ros_conversions import time_to_nanoseconds
from amr_turtlebot3.velocity_estimator import Status, VelocityEstimator

WARNING_PERIOD = 5.0  # seconds between repeated warnings of one kind

_PARAMETERS: dict[str, Param] = ruled({
    "max_gap": (0.5, "Seconds between /odom stamps above which the estimator resets instead "
                     "of differentiating across the gap"),
    "smoothing_time_constant": (0.0, "Time constant in seconds of a first-order low-pass on "
                                     "(v, w); 0 = off"),
    "input_topic": ("/odom", "nav_msgs/Odometry input with the pose filled (the robot's /odom)"),
    "output_topic": ("/odometry", "nav_msgs/Odometry output: the input with twist.twist."
                                  "linear.x and angular.z estimated"),
}, max_gap=above(0.0), smoothing_time_constant=at_least(0.0))


class OdometryNode(GuardedLifecycleNode):
    """The real robot's /odom (pose only) in, /odometry (pose + estimated twist) out.

    __init__ declares the parameters; configure creates the VelocityEstimator, the output
    lifecycle publisher and the input subscription; activate starts republishing (deactivate
    stops it; everything stays for a later activate); cleanup and shutdown release them
    (release()). The node commands nothing, so nothing is sent on the way down: /odometry just
    stops, and the wall follower's data timeout commands zero.
    """

    def __init__(self, node_name: str = "amr_odometry", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # Numbers take ints for doubles (`-p max_gap:=1`), and a wrong value fails configure
        # with a reason instead of raising in the constructor: amr_common.ros.parameters.
        declare_parameters(self, _PARAMETERS)
        self.estimator: VelocityEstimator | None = None
        self._publisher = None
        self._subscription = None

    # --- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Check the parameters, then create the estimator, publisher and subscription.

        A bad value (max_gap, smoothing_time_constant, empty or equal topic names) or a topic
        rclpy rejects returns FAILURE with the reason logged; anything already created is
        released again.
        """
        p, problems = read_parameters(self, _PARAMETERS)
        max_gap, tau = p["max_gap"], p["smoothing_time_constant"]
        for name in ("input_topic", "output_topic"):
            if not (isinstance(p[name], str) and p[name].strip()):
                problems.append(f"{name} must be a non-empty topic name (got {p[name]!r})")
        if not problems and p["input_topic"] == p["output_topic"]:
            problems.append(f"input_topic and output_topic are both {p['input_topic']!r}")
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        self.estimator = VelocityEstimator(max_gap=max_gap, smoothing_time_constant=tau)
        try:
            self._publisher = self.create_lifecycle_publisher(
                Odometry, p["output_topic"], RELIABLE_10)
            self._subscription = self.create_subscription(
                Odometry, p["input_topic"], self._on_odom, RELIABLE_10)
        except Exception as exc:  # e.g. an invalid topic name
            self.get_logger().error(f"configure failed: {exc}")
            self.release()
            return TransitionCallbackReturn.FAILURE
        self.get_logger().info(
            f"{p['input_topic']} -> {p['output_topic']}: max_gap {max_gap} s, smoothing "
            f"{'off' if tau == 0.0 else f'time constant {tau} s'}")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Reset the estimator and enable the publisher: /odom is republished from now on."""
        self.estimator.reset()  # poses seen before an inactive period are stale
        return super().on_activate(state)

    def release(self) -> None:
        """Destroy the subscription and the publisher and drop the estimator; sends nothing."""
        if self._subscription is not None:
            self.destroy_subscription(self._subscription)
            self._subscription = None
        if self._publisher is not None:
            self.destroy_lifecycle_publisher(self._publisher)
            self._publisher = None
        self.estimator = None

    # --- data ------------------------------------------------------------------------------
    def _on_odom(self, msg: Odometry) -> None:
        if not self.is_active or self.estimator is None or self._publisher is None:
            return
        position, orientation = msg.pose.pose.position, msg.pose.pose.orientation
        result = self.estimator.update(position.x, position.y, orientation.x, orientation.y,
                                       orientation.z, orientation.w,
                                       time_to_nanoseconds(msg.header.stamp))
        if result.ok:
            msg.twist.twist.linear.x = result.v
            msg.twist.twist.angular.z = result.w
            self._publisher.publish(msg)
        # One call per kind: rclpy throttles per call site, and one kind must not hide another.
        elif result.status is Status.REJECTED:
            self.get_logger().warning(self._dropped(result.reason),
                                      throttle_duration_sec=WARNING_PERIOD)
        elif result.status is Status.TOO_SHORT:
            self.get_logger().warning(self._dropped(result.reason),
                                      throttle_duration_sec=WARNING_PERIOD)
        elif result.status is Status.RESET_IMPLAUSIBLE:
            self.get_logger().warning(self._dropped(result.reason),
                                      throttle_duration_sec=WARNING_PERIOD)
        elif result.status in (Status.RESET_BACKWARDS, Status.RESET_GAP):
            self.get_logger().info(result.reason, throttle_duration_sec=WARNING_PERIOD)

    def _dropped(self, reason: str) -> str:
        return f"{self.get_parameter('input_topic').value}: {reason}; message dropped"


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(OdometryNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
