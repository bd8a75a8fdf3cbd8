"""The /cmd_vel end of the controller nodes (wall follower, pure pursuit).

One publisher, one reused message, the node parameters every commanding node checks the same
way, the forced final zero a robot without a command timeout needs, and the lifecycle callbacks
that start and stop commanding (CommandingNode, a GuardedLifecycleNode).
"""
from __future__ import annotations

from typing import Any, Callable

from geometry_msgs.msg import Twist, TwistStamped
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher

from amr_common.navigation_behaviour import limit_command
from amr_common.plugins.link_failure import checked_commands, class_spec
from amr_common.plugins.parameter_table import above
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.qos import RELIABLE_10

# The parameters every commanding node declares alike (the nodes add their own, e.g. what
# data_timeout applies to).
COMMAND_PARAMETERS: dict[str, tuple[Any, str]] = {
    "cmd_vel_stamped": (True, "Publish geometry_msgs/TwistStamped (Jazzy) instead of Twist "
                              "(Humble); simulation mode always uses TwistStamped"),
    "angular_sign": (1, "+1 for REP 103 (counter-clockwise positive), -1 for setups with the "
                        "opposite convention"),
}
# The rules of the parameters every commanding node has (each describes them in its table).
COMMAND_RULES = {"dt": above(0.0), "data_timeout": above(0.0)}


def command_parameter_problems(p: dict[str, Any]) -> list[str]:
    """What is wrong with angular_sign (dt and data_timeout: COMMAND_RULES, in the tables)."""
    if p["angular_sign"] not in (1, -1):
        return [f"angular_sign must be 1 or -1 (got {p['angular_sign']})"]
    return []


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


class CommandingNode(GuardedLifecycleNode):
    """The lifecycle callbacks of a node that commands the robot: zero on the way down.

    The base of the wall follower and pure pursuit nodes. The node's on_configure sets
    `simulation`, `dt` and `_output` (a CommandOutput); the node keeps `_timer`, `_latest` (its
    newest stored input) and `_last_stamp` (the newest answered stamp in lockstep), and provides
    `_on_timer` (robot mode) and `release()` (destroys what on_configure created, the timer
    first, e.g. with `_stop_timer()`).
    """

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable /cmd_vel and start commanding.

        Forgets any stored input; in robot mode creates the control timer (every dt). In
        simulation mode each input is answered as it comes.
        """
        result = super().on_activate(state)
        self._latest = None
        if not self.simulation:
            self._timer = self.create_timer(self.dt, self._on_timer)
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop commanding: destroy the control timer and send a zero command.

        The zero goes out while the publisher is still enabled; then the publisher is disabled.
        What on_configure created stays for a later activate.
        """
        self._stop_timer()
        self._publish_zero("deactivating")  # before the publisher goes quiet
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Send a zero command, then release everything on_configure created.

        The zero is sent even though the publisher is disabled (inactive state).
        """
        self._publish_zero("cleaning up", force=True)
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state (Ctrl-C included): stop, send a final zero command, release all.

        The timer is destroyed first so no command follows the zero.
        """
        self._stop_timer()
        self._publish_zero("shutting down", force=True)
        return super().on_shutdown(state)

    def link_commands(self, link: str, obj: Any, compute: Callable[..., Any], *args: Any,
                      time_s: float | None = None) -> tuple[float, float]:
        """(v, w) of `compute(*args)` (the link `obj`'s compute_commands), clipped to the limits.

        Zero once the link failed: what it raised or a return that is not two finite numbers
        is its failure (fail_link; `time_s`: the measurement's time), and the node commands
        zero from then on, without calling it again.
        """
        out = self.use_link(link, "compute_commands", compute, *args, spec=class_spec(obj),
                            check=lambda out: checked_commands(link, out), time_s=time_s,
                            then="commanding zero")
        return (0.0, 0.0) if out is None else limit_command(*out)

    def _stop_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None

    def _publish_zero(self, why: str, force: bool = False) -> None:
        if self._output is not None:
            self._output.publish_zero(why, self._last_stamp if self.simulation else None, force)


__all__ = ["COMMAND_PARAMETERS", "COMMAND_RULES", "CommandOutput", "CommandingNode",
           "command_parameter_problems", "limit_command"]
