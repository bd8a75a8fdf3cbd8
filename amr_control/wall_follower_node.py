"""The `wall_follower` lifecycle node: synchronized /odometry + /scan (+ /pose) -> /cmd_vel.

Thin: messages become `compute_commands(z_scan, z_v, z_w)` calls on the controller (by default
amr_control.wall_follower.WallFollower) and results become commands.
- Simulation mode (`simulation: true`): computes on each synchronized set and publishes a
  TwistStamped stamped like the measurement (lockstep with the simulator).
- Robot mode (`simulation: false`): stores the newest synchronized set and computes on a timer
  every dt (real time does not wait); /cmd_vel is TwistStamped (Jazzy bringup) or Twist (Humble)
  by `cmd_vel_stamped`; if the newest data is older than `data_timeout` it commands zero.
The LiDAR position (the controller's `lidar_offset_x_m`) is read from /tf_static (base_frame ->
scan_frame, through chains such as the Burger's base_footprint -> base_link -> base_scan) when a
node publishes it; the parameter is the fallback. A position that arrives after the controller
computed its first command applies from the next configure (the controller is rebuilt).
Safety: the TurtleBot3 keeps its last command forever, so the node sends a zero command on
deactivate, cleanup and shutdown (Ctrl-C included), and never publishes a non-finite value. A
controller that raises or returns anything but two finite numbers has failed
(amr_common.plugins.link_failure): logged once, zero from then on, and the run scripts end the run.
Handover with localization (`enable_localization`): for each synchronized (/odometry, /scan,
/pose) set the node is in charge iff the pose is NOT localized or `stop_when_localized` is false.
Out of charge it publishes nothing (the pure pursuit answers every localized /pose); in robot
mode the step out of charge sends one zero command (the robot keeps its last one). It takes
over again as soon as a set is not localized (localization lost). The controller still sees
every set, so its perception is current when it takes over.
"""
from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import LaserScan

from amr_common.navigation_behaviour import Handover, timer_action
from amr_common.plugins.link_failure import class_spec
from amr_common.plugins.loader import (
    DEFAULT_CONTROLLER,
    PluginSpecError,
    described_parameters,
    load_controller_class,
)
from amr_common.plugins.parameter_table import Param, at_least, check_values, ruled
from amr_common.robot import (
    MAX_PLAUSIBLE_ANGULAR_SPEED,
    MAX_PLAUSIBLE_LINEAR_SPEED,
    is_plausible_twist,
)
from amr_common.ros import message_filters
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_parameters, read_parameters
from amr_common.ros.qos import RELIABLE_10, scan_qos
from amr_common.ros.ros_conversions import time_to_nanoseconds
from amr_common.ros.tf import StaticTransformListener
from amr_control.command_output import (
    COMMAND_PARAMETERS,
    COMMAND_RULES,
    CommandingNode,
    CommandOutput,
    command_parameter_problems,
)

_NODE_PARAMETERS: dict[str, Param] = ruled({
    "simulation": (True, "true: compute on each synchronized set (lockstep with the simulator);"
                         " false: robot mode, compute on a timer every dt with the newest set"),
    "dt": (0.05, "Control period in seconds"),
    "queue_size": (10, "Synchronizer queue size per input"),
    "slop": (-1.0, "Synchronizer slop in seconds; negative = 10 s in simulation, 0.15 s in "
                   "robot mode"),
    "enable_localization": (False, "Also synchronize /pose (amr_msgs/PoseStamped): with "
                                   "stop_when_localized, command only while it is not "
                                   "localized"),
    "stop_when_localized": (True, "With enable_localization: publish nothing while /pose is "
                                  "localized (the planner's controller is in charge), resume "
                                  "when it is not; false = keep exploring"),
    **COMMAND_PARAMETERS,
    "data_timeout": (0.5, "Robot mode: command zero when the newest synchronized data is older "
                          "than this (seconds)"),
    "controller": (DEFAULT_CONTROLLER, "Controller class as MODULE:CLASS with "
                                       "compute_commands(z_scan, z_v, z_w) -> (v, w)"),
    "odometry_topic": ("/odometry", "nav_msgs/Odometry input with twist filled"),
    "scan_topic": ("/scan", "sensor_msgs/LaserScan input (subscribed best effort)"),
    "pose_topic": ("/pose", "amr_msgs/PoseStamped input when enable_localization is true"),
    "cmd_vel_topic": ("/cmd_vel", "Velocity command output"),
    "base_frame": ("base_footprint", "Robot frame: the LiDAR position is read from /tf_static "
                                     "as base_frame -> scan_frame"),
    "scan_frame": ("base_scan", "LiDAR frame (see base_frame); without it on /tf_static, "
                                "lidar_offset_x_m is used"),
}, **COMMAND_RULES, queue_size=at_least(1))


def node_parameters() -> dict[str, Param]:
    """The node's own parameters (not the controller's): name -> (default, description, rule)."""
    return dict(_NODE_PARAMETERS)


def _load_controller_spec(node: GuardedLifecycleNode) -> str:
    """The `controller` parameter, declared early so its tuning parameters can be declared."""
    declare_parameters(node, {"controller": _NODE_PARAMETERS["controller"]})
    return str(node.get_parameter("controller").value)


def tuning_table(controller_class: type) -> dict[str, tuple[Any, str]]:
    """The controller's tuning parameters the node declares: name -> (default, description).

    From the class's `parameter_descriptions()`, if it has one.
    """
    table = described_parameters(controller_class) or {}
    return {name: spec for name, spec in table.items()
            if name not in _NODE_PARAMETERS and name != "use_sim_time"}


def parameter_table(controller_class: type) -> dict[str, tuple[Any, str]]:
    """The node's own parameters and the controller's tuning ones: name -> (default, description).

    use_sim_time (rclpy declares it) included; the run scripts check -p against it.
    """
    return {**_NODE_PARAMETERS, **tuning_table(controller_class),
            "use_sim_time": (False, "Follow /clock (rclpy's parameter)")}


def parameter_names(controller_class: type) -> list[str]:
    """Every parameter the node declares with this controller class (run scripts check -p)."""
    return sorted(parameter_table(controller_class))


def node_parameter_problems(p: dict[str, Any]) -> list[str]:
    """What is wrong with the node's own parameter values (typed as declared).

    Each against its rule in the node's table, then angular_sign.
    """
    own = {name: value for name, value in p.items() if name in _NODE_PARAMETERS}
    return check_values(_NODE_PARAMETERS, own)[1] + command_parameter_problems(p)


class WallFollowerNode(CommandingNode):
    """The wall follower as a lifecycle node: synchronized /odometry + /scan in, /cmd_vel out.

    __init__ declares the node's parameters and, when the controller class describes them
    (`parameter_descriptions()`), its tuning values; nothing else exists until configure.
    Configure creates the controller, the /cmd_vel lifecycle publisher and the synchronized
    subscriptions; activate starts commanding; deactivate, cleanup and shutdown each send a
    zero command, because the TurtleBot3 keeps its last command forever (CommandingNode), and
    cleanup and shutdown then release everything (release()).
    """

    def __init__(self, node_name: str = "wall_follower", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # Numbers take ints for doubles (`-p kp:=5`): amr_common.ros.parameters.
        declare_parameters(self, _NODE_PARAMETERS)
        # The controller's tuning values become ROS parameters when the class describes them.
        self._tuning: dict[str, tuple[Any, str]] = {}
        try:
            self._tuning = tuning_table(load_controller_class(_load_controller_spec(self)))
            declare_parameters(self, self._tuning)
        except PluginSpecError as exc:
            self.get_logger().error(f"{exc} (configure will fail)")
        self._lidar_offset_from_tf: float | None = None  # kept across configures
        self._reset_runtime()

    # --- lifecycle -------------------------------------------------------------------------
    def _reset_runtime(self) -> None:
        self.controller = None
        self._output: CommandOutput | None = None
        self._subscribers: list = []
        self._synchronizer = None
        self._timer = None
        self._latest: tuple | None = None  # (z_scan, z_v, z_w, arrival Time) in robot mode
        self._handover = Handover()
        self._in_charge = True  # of the robot: see the module docstring (handover)
        self._latest_in_charge = True  # robot mode: the newest set's verdict
        self._scan_geometry: tuple | None = None
        self._last_stamp = None  # newest measurement's stamp (simulated time in lockstep)
        self._stop_log_forwarding = None
        self._computed = False  # the controller has computed a command since it was built
        self._static_listener: StaticTransformListener | None = None

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Check the parameters, then create what the node runs on.

        Creates the controller (with its tuning parameters), the /cmd_vel lifecycle publisher
        (TwistStamped, or Twist in robot mode with cmd_vel_stamped false), the /odometry and
        /scan subscriptions (+ /pose with enable_localization) and their approximate-time
        synchronizer. A bad parameter or a controller that cannot be loaded or built returns
        FAILURE with the reason logged, before anything is created.
        """
        p, problems = read_parameters(self, _NODE_PARAMETERS)
        tuning, tuning_problems = read_parameters(self, self._tuning)
        problems += tuning_problems
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        problems = node_parameter_problems(p)
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        if "lidar_offset_x_m" in tuning and self._lidar_offset_from_tf is not None:
            tuning["lidar_offset_x_m"] = self._lidar_offset_from_tf
        try:
            controller_class = load_controller_class(p["controller"])
            self.controller = controller_class(p["dt"], **tuning)
            self._controller_factory = (controller_class, p["dt"], tuning)
        except Exception as exc:  # a user's controller may raise anything
            self.get_logger().error(f"configure failed: controller '{p['controller']}': {exc}")
            return TransitionCallbackReturn.FAILURE
        self.simulation = bool(p["simulation"])
        self.dt = float(p["dt"])
        self.angular_sign = int(p["angular_sign"])
        self.data_timeout = float(p["data_timeout"])
        self.stamped = self.simulation or bool(p["cmd_vel_stamped"])
        self.stop_when_localized = bool(p["stop_when_localized"])
        slop = p["slop"] if p["slop"] >= 0 else (10.0 if self.simulation else 0.15)

        self._output = CommandOutput(self, p["cmd_vel_topic"], self.stamped, self.angular_sign)
        self._subscribers = [
            message_filters.Subscriber(self, Odometry, p["odometry_topic"],
                                       qos_profile=RELIABLE_10),
            message_filters.Subscriber(self, LaserScan, p["scan_topic"],
                                       qos_profile=scan_qos(10))]
        if p["enable_localization"]:
            from amr_msgs.msg import PoseStamped
            self._subscribers.append(message_filters.Subscriber(
                self, PoseStamped, p["pose_topic"], qos_profile=RELIABLE_10))
        self._synchronizer = message_filters.ApproximateTimeSynchronizer(
            self._subscribers, p["queue_size"], slop)
        self._synchronizer.registerCallback(self._on_synchronized)
        # The controller's (throttled) Python warnings go to this node's ROS logger.
        self._stop_log_forwarding = self.forward_python_logging(type(self.controller).__module__)
        if "lidar_offset_x_m" in tuning:
            self._lidar_frames = (p["base_frame"], p["scan_frame"])
            self._static_listener = StaticTransformListener(self, self._on_static_transforms)
        mode = "simulation (lockstep)" if self.simulation else f"robot (timer every {self.dt} s)"
        self.get_logger().info(
            f"configured: {mode}, controller {p['controller']}, slop {slop} s, /cmd_vel as "
            f"{'TwistStamped' if self.stamped else 'Twist'}, angular_sign {self.angular_sign}")
        return TransitionCallbackReturn.SUCCESS

    def release(self) -> None:
        """Destroy what on_configure created; the zero command was sent before (CommandingNode).

        The control timer, the synchronized subscriptions, the /tf_static listener and the
        /cmd_vel publisher; the log forwarding stops and the controller is dropped.
        """
        self._stop_timer()
        for subscriber in self._subscribers:
            subscriber.close()
        if self._static_listener is not None:
            self._static_listener.close()
        if self._output is not None:
            self._output.destroy()
        if self._stop_log_forwarding is not None:
            self._stop_log_forwarding()
        self._reset_runtime()

    # --- data path -------------------------------------------------------------------------
    def _on_static_transforms(self, tree) -> None:
        """Use the LiDAR position of /tf_static; rebuild the controller if it has not run yet."""
        offset = tree.offset(*self._lidar_frames)
        controller_class, dt, tuning = self._controller_factory
        if offset is None or offset.x == tuning["lidar_offset_x_m"]:
            return
        if abs(offset.y) > 1e-3 or abs(offset.yaw) > 1e-3:
            self.get_logger().warning(
                f"{'->'.join(self._lidar_frames)} has y {offset.y:.3f} m, yaw {offset.yaw:.3f} "
                f"rad on /tf_static: only its x is used", throttle_duration_sec=10.0)
        self._lidar_offset_from_tf = offset.x
        if self._computed:
            self.get_logger().warning(
                f"LiDAR at x = {offset.x:.3f} m on /tf_static differs from the "
                f"{tuning['lidar_offset_x_m']:.3f} m in use: it applies from the next configure")
            return
        try:
            tuning = {**tuning, "lidar_offset_x_m": offset.x}
            self.controller = controller_class(dt, **tuning)
        except Exception as exc:  # keep the working controller
            self.get_logger().error(f"LiDAR position from /tf_static refused: {exc}")
            return
        self._controller_factory = (controller_class, dt, tuning)
        self._scan_geometry = None  # the new controller needs the scan geometry again
        self.get_logger().info(f"LiDAR position from /tf_static: x = {offset.x:.3f} m")

    def _on_synchronized(self, odometry: Odometry, scan: LaserScan, pose=None) -> None:
        if not self.is_active:
            return
        # Who commands is the Handover's rule (shared with the headless episodes); the
        # controller computes on every set either way, so its perception stays current.
        if pose is not None:
            self._handover.update(pose.localized)
        in_charge = pose is None or not self.stop_when_localized or \
            self._handover.explorer_in_charge
        measurement = self._measurement(odometry, scan)
        if self.simulation:
            self._hand_over(in_charge)
            # Lockstep: the simulator waits for this answer, so always answer (zero if bad).
            # The command carries the measurement's (simulated) stamp: no clock needed.
            v, w = self._compute(*measurement, time_to_nanoseconds(scan.header.stamp) * 1e-9) \
                if measurement else (0.0, 0.0)
            self._last_stamp = scan.header.stamp
            if in_charge:
                self._publish(v, w, self._last_stamp)
        elif measurement is not None:
            self._latest = (*measurement, self.get_clock().now())
            self._latest_in_charge = in_charge

    def _hand_over(self, in_charge: bool) -> bool:
        """Record who is in charge; True if the node just stepped out of charge."""
        was, self._in_charge = self._in_charge, in_charge
        if was and not in_charge:
            self.get_logger().info("localized: handing over (no more commands while localized)")
        elif in_charge and not was:
            self.get_logger().warning("localization lost: wall following again")
        return was and not in_charge

    def _measurement(self, odometry: Odometry, scan: LaserScan):
        z_v, z_w = odometry.twist.twist.linear.x, odometry.twist.twist.angular.z
        if not (math.isfinite(z_v) and math.isfinite(z_w)):
            self.get_logger().warning("odometry twist is not finite: set ignored",
                                      throttle_duration_sec=2.0)
            return None
        if not is_plausible_twist(z_v, z_w):
            # A corrupt message: the Burger cannot move like this. The next good one is used.
            self.get_logger().warning(
                f"odometry twist (v={z_v:.3g} m/s, w={z_w:.3g} rad/s) is physically impossible "
                f"(limits {MAX_PLAUSIBLE_LINEAR_SPEED:.2f} m/s, {MAX_PLAUSIBLE_ANGULAR_SPEED:.2f}"
                f" rad/s): set ignored", throttle_duration_sec=2.0)
            return None
        if len(scan.ranges) == 0 or not (math.isfinite(scan.angle_min)
                                         and math.isfinite(scan.angle_increment)
                                         and scan.angle_increment != 0.0):
            self.get_logger().warning("scan has no rays or no usable angles: set ignored",
                                      throttle_duration_sec=2.0)
            return None
        geometry = (scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max)
        if not (math.isfinite(scan.range_min) and math.isfinite(scan.range_max)
                and 0.0 <= scan.range_min < scan.range_max):
            self.get_logger().warning(
                f"scan range limits [{scan.range_min}, {scan.range_max}] m are unusable: the "
                f"controller decides which readings to trust", throttle_duration_sec=5.0)
        # NaN never equals itself: compare a NaN-free key, so a repeated broken geometry is
        # handed to the controller once, not with every scan.
        key = tuple(None if math.isnan(value) else value for value in geometry)
        if key != self._scan_geometry and hasattr(self.controller, "set_scan_geometry") \
                and self.link_failure is None:
            self.use_link("controller", "set_scan_geometry", self.controller.set_scan_geometry,
                          *geometry, spec=class_spec(self.controller), then="commanding zero",
                          time_s=time_to_nanoseconds(scan.header.stamp) * 1e-9)
            if self.link_failure is not None:
                return None
            self._scan_geometry = key
        return np.asarray(scan.ranges, dtype=float), float(z_v), float(z_w)

    def _on_timer(self) -> None:
        if not self.is_active:
            return
        now = self.get_clock().now()
        age = None if self._latest is None else (now - self._latest[3]).nanoseconds * 1e-9
        action = timer_action(age, self.data_timeout, self._latest_in_charge)
        if action == "silent":
            self._compute(*self._latest[:3])  # keeps the controller's perception current
            if self._hand_over(False):
                self._publish(0.0, 0.0, now.to_msg())  # the robot keeps its last command
            return
        if action == "zero":
            newest = "no data yet" if age is None else f"newest data {age:.2f} s old"
            self.get_logger().warning(f"{newest} (data_timeout {self.data_timeout} s): "
                                      f"commanding zero", throttle_duration_sec=2.0)
            self._publish(0.0, 0.0, now.to_msg())
            return
        self._hand_over(True)
        v, w = self._compute(*self._latest[:3])
        self._publish(v, w, now.to_msg())

    def _compute(self, z_scan, z_v: float, z_w: float,
                 time_s: float | None = None) -> tuple[float, float]:
        """The controller's command; zero for good once it failed (CommandingNode)."""
        self._computed = True
        return self.link_commands("controller", self.controller,
                                  self.controller.compute_commands, z_scan, z_v, z_w,
                                  time_s=time_s)

    def _publish(self, v: float, w: float, stamp, force: bool = False) -> None:
        if self._output is not None:
            self._output.publish(v, w, stamp, force=force)


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(WallFollowerNode, args)


if __name__ == "__main__":
    sys.exit(main())
