"""The `pure_pursuit` lifecycle node: /pose (localized) + /path (+ /scan) -> /cmd_vel.

Thin: the algorithm is the `follower` parameter's class (MODULE:CLASS of
amr_common.plugins.interfaces.PathFollower; default amr_control.pure_pursuit.PurePursuit). Handover
with the wall follower (which commands while /pose is NOT localized):
- Simulation mode (`simulation: true`, lockstep): EVERY localized /pose gets exactly one /cmd_vel
  stamped like the pose: zero until a path has come, the pursuit's command while following, zero
  again once stopped at the path's end. A non-localized /pose gets none (the wall follower
  answers it), so each step of the loop gets exactly one command.
- Robot mode (`simulation: false`): the newest /pose is stored and a timer computes every dt;
  it commands while the newest pose is localized, and zero if that pose is older than
  `data_timeout` (stale: the robot must not keep moving on old data).
Losing localization: the pursuit stops commanding (in robot mode after one zero command) and
forgets its path; the planner replans from the relocalized pose and the new /path is followed.
Stamps: a /pose older than the newest one is not used (lockstep: answered with zero; robot mode:
the newest stays, aging out after data_timeout). Older by more than data_timeout, it is taken as
a jump back in time (or the newest stamp was bogus, e.g. far in the future): still not used, but
later poses are compared with it, so one bad stamp never stops the pursuit for good. On a loss,
the path is forgotten unless it was planned (stamped) at most data_timeout after the lost pose.
/scan gives the footprint clearance for the proximity slow-down and the room straight ahead
for the stop short of an obstacle the map lacks (both ignored when stale).
Safety as the wall follower: a zero command on deactivate, cleanup and shutdown (Ctrl-C
included), never a non-finite value; a follower that raises or returns anything but two
finite numbers has failed (amr_common.plugins.link_failure): zero from then on, the run fails.
"""
from __future__ import annotations

import math
import sys
from typing import Any

from nav_msgs.msg import Path
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import LaserScan

from amr_common.geometry import polyline_length
from amr_common.navigation_behaviour import Handover, timer_action
from amr_common.plugins.interfaces import PathFollower
from amr_common.plugins.link_failure import class_spec
from amr_common.plugins.loader import DEFAULT_FOLLOWER
from amr_common.plugins.parameter_table import Param, ruled
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_link, declare_parameters, read_parameters
from amr_common.ros.qos import LATCHED, RELIABLE_10, scan_qos
from amr_common.ros.ros_conversions import (
    path_points,
    pose_from_message,
    scan_ranges,
    time_to_nanoseconds,
)
from amr_control.command_output import (
    COMMAND_PARAMETERS,
    COMMAND_RULES,
    CommandingNode,
    CommandOutput,
    command_parameter_problems,
)
from amr_control.pure_pursuit import scan_clearance, scan_free_ahead

_NODE_PARAMETERS: dict[str, Param] = ruled({
    "simulation": (True, "true: answer each localized /pose (lockstep with the simulator); "
                         "false: robot mode, compute on a timer every dt with the newest pose"),
    "dt": (0.05, "Control period in seconds"),
    **COMMAND_PARAMETERS,
    "data_timeout": (0.5, "Robot mode: command zero when the newest /pose is older than this; "
                          "a /scan older than this is not used (seconds)"),
    "follower": (DEFAULT_FOLLOWER, "Path follower class as MODULE:CLASS implementing "
                                   "amr_common.plugins.interfaces.PathFollower (its tuning values "
                                   "become parameters of this node)"),
    "frame_id": ("map", "Frame of /pose and /path"),
    "pose_topic": ("/pose", "amr_msgs/PoseStamped input (the particle filter's estimate)"),
    "path_topic": ("/path", "nav_msgs/Path input (transient local, from the planner)"),
    "scan_topic": ("/scan", "sensor_msgs/LaserScan input for the proximity slow-down"),
    "cmd_vel_topic": ("/cmd_vel", "Velocity command output"),
}, **COMMAND_RULES)


class PurePursuitNode(CommandingNode):
    """Follows /path with a regulated pure pursuit while /pose is localized (module docstring).

    Parameters: the node's own (simulation, dt, topics, ...) and every PurePursuit tuning value.
    Configure creates the PurePursuit, the /cmd_vel lifecycle publisher and the /pose, /path
    and /scan subscriptions; activate starts commanding (robot mode: a timer every dt);
    deactivate, cleanup and shutdown each send a zero command (CommandingNode), and cleanup and
    shutdown then release everything (release()).
    """

    def __init__(self, node_name: str = "pure_pursuit", **kwargs) -> None:
        """Declare the parameters; nothing is created before on_configure."""
        super().__init__(node_name, **kwargs)
        declare_parameters(self, _NODE_PARAMETERS)
        self._follower_class, self._tuning = declare_link(self, "follower", _NODE_PARAMETERS)
        self._reset_runtime()

    def _reset_runtime(self) -> None:
        self.pursuit: PathFollower | None = None
        self._output: CommandOutput | None = None
        self._subscriptions: list = []
        self._timer = None
        self._handover = Handover()  # who commands: the shared rule (navigation_behaviour)
        self._latest = None  # robot mode: (pose, stamp ns, arrival Time) of the newest /pose
        self._newest_stamp_ns: int | None = None  # newest /pose stamp (see _in_order)
        self._last_stamp = None  # ... as a message stamp: the zero on the way down carries it
        self._path_stamp_ns = -1
        self._scan: tuple[LaserScan | None, Any] = (None, None)  # (newest, arrival Time)

    # --- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Check the parameters, then create what the node runs on.

        Builds the PurePursuit, the /cmd_vel lifecycle publisher and the /pose, /path and /scan
        subscriptions. FAILURE with a logged reason on bad parameters.
        """
        p, problems = read_parameters(self, _NODE_PARAMETERS)
        tuning, tuning_problems = read_parameters(self, self._tuning)
        problems += tuning_problems
        if self._follower_class is None:
            problems.append(f"follower '{p['follower']}' cannot be loaded (see the error above)")
        if not problems:
            problems = command_parameter_problems(p)
        if not problems:
            try:
                pursuit = self._follower_class(p["dt"], **tuning)
            except Exception as exc:  # its checks of several parameters; a user's class: any
                problems.append(str(exc))
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        self.pursuit = pursuit
        self.simulation = bool(p["simulation"])
        self.dt = float(p["dt"])
        self.data_timeout = float(p["data_timeout"])
        self.frame_id = str(p["frame_id"])
        from amr_msgs.msg import PoseStamped
        self._output = CommandOutput(self, p["cmd_vel_topic"],
                                     self.simulation or bool(p["cmd_vel_stamped"]),
                                     int(p["angular_sign"]))
        self._subscriptions = [
            self.create_subscription(PoseStamped, p["pose_topic"], self._on_pose, RELIABLE_10),
            self.create_subscription(Path, p["path_topic"], self._on_path, LATCHED),
            self.create_subscription(LaserScan, p["scan_topic"], self._on_scan, scan_qos(10))]
        mode = "simulation (lockstep)" if self.simulation else f"robot (timer every {self.dt} s)"
        self.get_logger().info(f"configured: {mode}, follower {p['follower']}")
        return TransitionCallbackReturn.SUCCESS

    def release(self) -> None:
        """Destroy what on_configure created; the zero command was sent before (CommandingNode).

        The control timer, the /pose, /path and /scan subscriptions and the /cmd_vel publisher;
        the pursuit and its path are dropped.
        """
        self._stop_timer()
        for subscription in self._subscriptions:
            self.destroy_subscription(subscription)
        if self._output is not None:
            self._output.destroy()
        self._reset_runtime()

    # --- inputs ----------------------------------------------------------------------------
    def _on_path(self, message: Path) -> None:
        if self.pursuit is None:
            return
        if message.header.frame_id not in (self.frame_id, ""):
            self.get_logger().error(f"/path in frame '{message.header.frame_id}' ignored: "
                                    f"expected '{self.frame_id}'")
            return
        points = path_points(message)
        self._path_stamp_ns = time_to_nanoseconds(message.header.stamp)
        if len(points) == 0:
            self._path_call("clear_path")
            self.get_logger().warning("empty /path (no plan): commanding zero while localized")
            return
        try:
            if not self._path_call("set_path", points):
                return
        except ValueError as exc:
            self._path_call("clear_path")
            self.get_logger().error(f"/path rejected ({exc}): commanding zero while localized")
            return
        length = polyline_length(points)
        self.get_logger().info(f"following a new path: {len(points)} poses, {length:.2f} m")

    def _on_scan(self, message: LaserScan) -> None:
        # Kept as is: the clearance is worked out only when the pursuit commands.
        self._scan = (message, self.get_clock().now())

    def _scan_obstacles(self) -> tuple[float | None, float | None]:
        """(footprint clearance, room straight ahead) from the newest /scan.

        (None, None) if there is none, or it is stale or unusable.
        """
        message, arrival = self._scan
        if message is None or (not self.simulation and (
                self.get_clock().now() - arrival).nanoseconds * 1e-9 > self.data_timeout):
            return None, None  # a stale scan says nothing about the obstacles now
        geometry = (message.angle_min, message.angle_increment, message.range_min,
                    message.range_max)
        if len(message.ranges) == 0 or not all(math.isfinite(v) for v in geometry):
            return None, None
        scan = (scan_ranges(message), *geometry, self.pursuit.lidar_offset_x_m,
                self.pursuit.robot_radius_m)
        return scan_clearance(*scan), scan_free_ahead(*scan)

    def _on_pose(self, message) -> None:
        if not self.is_active or self.pursuit is None:
            return
        stamp_ns = time_to_nanoseconds(message.header.stamp)
        if self._handover.update(message.localized) == "lost":
            self._lose_localization(message.header.stamp, stamp_ns)
        if not message.localized:
            return
        try:
            pose = pose_from_message(message.pose)
        except ValueError as exc:
            pose = None
            self.get_logger().warning(f"/pose unusable ({exc}): commanding zero",
                                      throttle_duration_sec=2.0)
        if pose is not None and not all(math.isfinite(v) for v in pose):
            self.get_logger().warning("/pose not finite: commanding zero",
                                      throttle_duration_sec=2.0)
            pose = None
        in_order = self._in_order(stamp_ns)
        if self._newest_stamp_ns == stamp_ns:
            self._last_stamp = message.header.stamp
        if not self.simulation:
            if self._newest_stamp_ns == stamp_ns:  # the newest, or a jump back (then zero)
                self._latest = (pose if in_order else None, stamp_ns, self.get_clock().now())
            return
        # Lockstep: the simulator waits for this answer, so always answer exactly once.
        v, w = self._compute(pose, stamp_ns * 1e-9) if pose is not None and in_order \
            else (0.0, 0.0)
        self._output.publish(v, w, message.header.stamp)

    def _in_order(self, stamp_ns: int) -> bool:
        """True if a /pose with this stamp may be used: not older than the newest one.

        Older by more than data_timeout: a jump back in time, or the newest stamp was bogus
        (far in the future); not used either, but it becomes the newest, so the stream goes on.
        """
        newest = self._newest_stamp_ns
        if newest is None or stamp_ns >= newest:
            self._newest_stamp_ns = stamp_ns
            return True
        if (newest - stamp_ns) * 1e-9 > self.data_timeout:
            self._newest_stamp_ns = stamp_ns
            self.get_logger().warning(
                f"/pose stamp jumped back {(newest - stamp_ns) * 1e-9:.3g} s: commanding zero "
                "once, following the poses from this stamp on", throttle_duration_sec=2.0)
        else:
            self.get_logger().warning("/pose older than the previous one (out of order): "
                                      "not used", throttle_duration_sec=2.0)
        return False

    def _lose_localization(self, stamp, stamp_ns: int) -> None:
        self._latest = None
        self.get_logger().warning("localization lost: stopping; the wall follower takes over "
                                  "until the planner replans from the relocalized pose")
        # A path planned after this pose (from the relocalized one) stays; one stamped far
        # beyond it is bogus and goes too.
        if not 0 < self._path_stamp_ns - stamp_ns <= self.data_timeout * 1e9:
            self._path_call("clear_path")
        if not self.simulation:
            self._output.publish(0.0, 0.0, self.get_clock().now().to_msg())

    def _on_timer(self) -> None:
        if not self.is_active or self._latest is None or \
                self._handover.explorer_in_charge:
            return  # not localized: the wall follower commands
        pose, _, arrival = self._latest
        now = self.get_clock().now()
        age = (now - arrival).nanoseconds * 1e-9
        if timer_action(age, self.data_timeout, in_charge=True) == "zero":
            self.get_logger().warning(f"newest /pose {age:.2f} s old (data_timeout "
                                      f"{self.data_timeout} s): commanding zero",
                                      throttle_duration_sec=2.0)
            self._output.publish(0.0, 0.0, now.to_msg())
            return
        v, w = self._compute(pose) if pose is not None else (0.0, 0.0)
        self._output.publish(v, w, now.to_msg())

    def _compute(self, pose: tuple[float, float, float],
                 time_s: float | None = None) -> tuple[float, float]:
        """The follower's command; zero for good once it failed (CommandingNode)."""
        return self.link_commands("follower", self.pursuit, self._pursue, pose, time_s=time_s)

    def _pursue(self, pose: tuple[float, float, float]) -> Any:
        """The follower's compute_commands with the scan's obstacles; its state change logged."""
        state = self.pursuit.state
        obstacles = self._scan_obstacles() if self.pursuit.path is not None else (None, None)
        out = self.pursuit.compute_commands(*pose, *obstacles)
        if self.pursuit.state != state:
            self._log_state(self.pursuit.state)
        return out

    def _path_call(self, member: str, *args: Any) -> bool:
        """The follower's set_path / clear_path; False if it failed (fail_link) or had failed.

        set_path's ValueError (an empty or non-finite path) passes through: a rejected path.
        """
        newest = self._newest_stamp_ns
        self.use_link("follower", member, getattr(self.pursuit, member), *args,
                      spec=class_spec(self.pursuit),
                      allowed=(ValueError,) if member == "set_path" else (),
                      time_s=None if newest is None else newest * 1e-9, then="commanding zero")
        return self.link_failure is None

    def _log_state(self, state: str) -> None:
        if state == "arrived":
            self.get_logger().info("stopped at the end of the path")
        elif state == "off_path":
            self.get_logger().warning(
                "too far from the path: commanding zero until back on it or a new path comes")
        elif state == "blocked":  # (range noise may let it creep on and halt again)
            self.get_logger().warning(
                "something the map lacks is in the way (/scan): halted short of it, waiting",
                throttle_duration_sec=10.0)



def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(PurePursuitNode, args)


if __name__ == "__main__":
    sys.exit(main())
