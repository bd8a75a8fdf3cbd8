"""The `amr_simulator` lifecycle node: the amr_sim core behind the course's ROS interface.

Thin: commands become `Simulator.step(v, w)` calls and results become messages
(amr_common.ros.ros_conversions). Two modes:
- lockstep (default, as CoppeliaSim stepping): each /cmd_vel advances exactly one dt, then
  /clock and /ground_truth (while anyone subscribes), the odometry topic and /scan are
  published with the simulated time as stamp; on activation a first measurement is published
  so the loop starts.
- realtime: a wall-clock timer at dt advances the simulation with the newest command (older than
  `command_timeout` = zero) and each sensor is published at its profile's own rate.
TF (REP 105) as the robot's bringup: /tf_static base_footprint -> base_scan at the profile's LiDAR
position; /tf with each odometry message (while anyone subscribes): odom -> base_footprint, map
-> base_footprint_truth (the true pose) and, with `map_to_odom_from_truth`, map -> odom. /map and
/map_markers: the world, latched, published on activation; /world_markers: the walls
`navigation_map` lacks and the world's movers, where they walk.
With `enable_localization`, /pose (amr_msgs/PoseStamped) is compared with the true pose; the goal
counts as reached when the true position is within goal_tolerance while localized (logged), and
the run finishes once the robot has then been commanded to rest for goal_rest_time (at once for
0, as the course template), so the final error is measured where it stops (`summary()`).
For in-process run scripts: `node.simulator` and `node.on_step` (callables called with the
simulator after every step) give access without topics; `node.finish(reason)` stops stepping.
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable

from geometry_msgs.msg import Twist, TwistStamped
from rclpy.clock import Clock, ClockType
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn

from amr_common.geometry import angle_difference
from amr_common.navigation_behaviour import GoalCheck, KidnapSchedule
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_parameters, read_parameters
from amr_common.ros.qos import RELIABLE_10
from amr_common.ros.ros_conversions import command_from_twist, pose_from_message
from amr_common.world.movers import collisions_text
from amr_common.world.world import World
from amr_sim.simulator import Simulator
from amr_sim.simulator_outputs import SimulatorOutputs
from amr_sim.simulator_params import DEFAULT_START, PARAMETERS, check_parameters


class SimulatorNode(GuardedLifecycleNode):
    """The amr_sim Simulator behind the course's topics, as a lifecycle node.

    __init__ declares the parameters; configure loads the world, builds the Simulator and
    creates the publishers (SimulatorOutputs) and the /cmd_vel (+ /pose) inputs; activate
    publishes a first measurement (the lockstep loop starts) or starts the real-time timer;
    deactivate pauses; cleanup and shutdown release everything (release()). It commands no
    robot, so nothing is sent on the way down: the simulated robot just stops being stepped.
    """

    def __init__(self, node_name: str = "amr_simulator", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # Numbers take ints for doubles (`-p dt:=1`): amr_common.ros.parameters.
        declare_parameters(self, PARAMETERS)
        # Run scripts append callables here; each is called with the simulator after a step.
        self.on_step: list[Callable[[Any], None]] = []
        self._reset()

    # --- configuration ---------------------------------------------------------------------
    def _reset(self) -> None:
        self.simulator = None
        self.finished = False
        self.finish_reason = ""
        self.goal: tuple[float, float] | None = None
        self.localized = False
        self.localization_error: tuple[float, float] | None = None  # (m, rad)
        self._goal_check: GoalCheck | None = None
        self._outputs: SimulatorOutputs | None = None
        self._inputs: list = []
        self._filters: list = []
        self._synchronizer = None
        self._timer = None
        self._wall_start: float | None = None
        self._wall_time = 0.0
        self._command = (0.0, 0.0)
        self._command_received: float | None = None  # monotonic time of the newest command
        self._kidnap = KidnapSchedule(None)

    def _read_parameters(self) -> dict[str, Any]:
        """Parameter values, checked; raises ValueError naming every bad one."""
        values, problems = read_parameters(self, PARAMETERS)
        if problems:
            raise ValueError("; ".join(problems))
        return check_parameters(values)

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Check the parameters, load the world, build the Simulator and create the topics.

        Creates the lifecycle publishers /clock, the odometry topic (/odometry in lockstep,
        the profile's topic in real time), /scan and, with publish_ground_truth,
        /ground_truth; and the /cmd_vel subscription (+ /pose with enable_localization,
        synchronized with the command in lockstep). A bad parameter, world or start returns
        FAILURE with the reason logged, before any topic is created.
        """
        self._reset()
        try:
            p = self._read_parameters()
            world = World.load(p["world"])
            start = p["start"]
            if start == DEFAULT_START and start not in world.starts and world.starts:
                # The default names lab02's start; other worlds name theirs differently.
                start = next(iter(world.starts))
                self.get_logger().info(f"world '{world.name}' has no start '{DEFAULT_START}' "
                                       f"(the default): starting at '{start}'")
            self._start_pose = world.resolve_start(start)
            if p["kidnap"] is not None:  # a pose in a wall fails here, not mid-run
                world.resolve_start(p["kidnap"][1:])
            self.simulator = Simulator(world, start=self._start_pose,
                                       dt=p["dt"], profile=p["profile"], seed=p["seed"])
        except Exception as exc:  # WorldError, unknown profile, bad values: all user errors
            self.get_logger().error(f"configure failed: {exc}")
            self._reset()
            return TransitionCallbackReturn.FAILURE
        self.params = p
        self.realtime = p["mode"] == "realtime"
        self.goal = p["goal"] if p["goal"] is not None else world.goal
        self._goal_check = GoalCheck(self.goal, p["goal_tolerance"], p["goal_rest_time"])
        self._kidnap = KidnapSchedule(p["kidnap"])
        profile = self.simulator.profile
        # Lockstep keeps the course's protocol (/odometry with the encoder twist, every step) in
        # both profiles: a pose-only /odom would need the estimator, which publishes nothing for
        # the first message and would stall the loop. Real time publishes what the profile's
        # robot publishes (/odom pose-only for the Burger).
        self.odometry_topic = profile.odom_topic if self.realtime else "/odometry"
        try:
            self._outputs = SimulatorOutputs(self, self.simulator, p, self.odometry_topic,
                                             self.realtime)
        except Exception as exc:  # a map that cannot be built: the user's resolution
            self.get_logger().error(f"configure failed: {exc}")
            self.release()
            return TransitionCallbackReturn.FAILURE
        self._create_inputs(p)
        x, y, theta = self.simulator.pose
        self.get_logger().info(
            f"configured: world '{world.name}' ({world.source}), start ({x:.3f}, {y:.3f}, "
            f"{theta:.3f}), profile {profile.name}, {p['mode']}, dt {p['dt']} s, goal "
            f"{self.goal}, localization {'on' if p['enable_localization'] else 'off'}"
            + (f"; effects {self.simulator.effects.summary()}" if self.simulator.effects
               else ""))
        return TransitionCallbackReturn.SUCCESS

    def _create_inputs(self, p: dict[str, Any]) -> None:
        command_type = TwistStamped if p["cmd_vel_stamped"] else Twist
        if p["enable_localization"]:
            from amr_msgs.msg import PoseStamped
        synchronize = p["enable_localization"] and not self.realtime and p["cmd_vel_stamped"]
        if synchronize:
            # As the course template: a step needs a command AND the pose estimate it was
            # computed with (slop 10 s: in lockstep the stamps are simulated times).
            from amr_common.ros import message_filters
            self._filters = [
                message_filters.Subscriber(self, TwistStamped, "/cmd_vel",
                                           qos_profile=RELIABLE_10),
                message_filters.Subscriber(self, PoseStamped, "/pose", qos_profile=RELIABLE_10)]
            self._synchronizer = message_filters.ApproximateTimeSynchronizer(
                self._filters, 10, 10.0)
            self._synchronizer.registerCallback(self._on_command_and_pose)
            return
        on_command = self._store_command if self.realtime else self._on_command
        self._inputs.append(self.create_subscription(
            command_type, "/cmd_vel", on_command, RELIABLE_10))
        if p["enable_localization"]:  # Twist has no stamp / real time: newest estimate
            self._inputs.append(self.create_subscription(
                PoseStamped, "/pose", self._check_estimated_pose, RELIABLE_10))

    def release(self) -> None:
        """Destroy the real-time timer, the publishers and the inputs; drop the Simulator.

        The run ends; nothing is sent on the way down.
        """
        self._stop_timer()
        if self._outputs is not None:
            self._outputs.destroy()
        for subscription in self._inputs:
            self.destroy_subscription(subscription)
        for message_filter in self._filters:
            message_filter.close()
        self._reset()

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publishers and start stepping.

        Publishes the current measurement (it starts a lockstep loop); in real time creates
        the steady-clock timer that steps every dt. A finished run stays finished.
        """
        result = super().on_activate(state)  # enables the lifecycle publishers
        if self._wall_start is None:
            self._wall_start = time.monotonic()
        if self.finished:
            return result
        simulator = self.simulator
        # The first measurement starts a lockstep loop.
        self._outputs.publish_first(*simulator.measure())
        if self.realtime:
            # Steady clock: with use_sim_time a ROS-time timer would wait for our own /clock.
            self._timer = self.create_timer(simulator.dt, self._on_timer,
                                            clock=Clock(clock_type=ClockType.STEADY_TIME))
        return result

    def _stop_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self.destroy_timer(self._timer)
            self._timer = None

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Pause: destroy the real-time timer, ignore commands, disable the publishers.

        Scans still on their way (real time with a reality-gap profile) are dropped. The
        simulator keeps its state, so a later activate resumes the same run.
        """
        self._stop_timer()
        if self._outputs is not None:
            self._outputs.cancel_late_scans()
        return super().on_deactivate(state)

    # --- commands --------------------------------------------------------------------------
    def _finite_command(self, message: Twist | TwistStamped) -> tuple[float, float]:
        v, w = command_from_twist(message)
        if math.isfinite(v) and math.isfinite(w):
            return v, w
        self.get_logger().warning(f"non-finite /cmd_vel (v={v}, w={w}): treated as zero",
                                  throttle_duration_sec=2.0)
        return 0.0, 0.0

    def _on_command(self, message: Twist | TwistStamped) -> None:
        if self.is_active and not self.finished:
            self._advance(*self._finite_command(message))

    def _on_command_and_pose(self, command: TwistStamped, pose) -> None:
        if self.is_active and not self.finished:
            self._check_estimated_pose(pose)
            self._advance(*self._finite_command(command))

    def _store_command(self, message: Twist | TwistStamped) -> None:
        self._command = self._finite_command(message)
        self._command_received = time.monotonic()

    def _on_timer(self) -> None:
        if not self.is_active or self.finished:
            return
        v, w = self._command
        timeout = self.params["command_timeout"]
        if self._command_received is not None and timeout > 0 and \
                time.monotonic() - self._command_received > timeout and (v, w) != (0.0, 0.0):
            self.get_logger().warning(
                f"no /cmd_vel for more than {timeout} s: commanding zero",
                throttle_duration_sec=5.0)
            v, w = self._command = (0.0, 0.0)
        self._advance(v, w)

    # --- stepping and publishing -----------------------------------------------------------
    def _advance(self, v: float, w: float) -> None:
        simulator = self.simulator
        kidnap = self._kidnap.due(simulator.time)
        if kidnap is not None:
            simulator.teleport(kidnap)
            self.get_logger().warning(
                f"kidnapped at t={simulator.time:.2f} s to ({kidnap[0]:.2f}, {kidnap[1]:.2f}, "
                f"{kidnap[2]:.2f})")
        pose_before = simulator.pose
        try:
            z_scan, z_v, z_w = simulator.step(v, w)
        except Exception as exc:  # a core failure must not take the executor down
            self.get_logger().error(f"simulation step failed: {exc!r}")
            self.finish(f"simulation error: {exc}")
            return
        pose = simulator.pose
        for hook in list(self.on_step):
            try:
                hook(simulator)
            except Exception as exc:
                self.get_logger().error(f"on_step hook {hook!r} failed: {exc!r}",
                                        throttle_duration_sec=5.0)
        if self.finished:  # a hook ended the run
            return
        if self.realtime:
            publish_odom = self._outputs.due("odom", simulator.profile.odom_period)
            publish_scan = self._outputs.due("scan", simulator.profile.scan_period)
        else:
            publish_odom = publish_scan = True
        done = self._check_goal(pose, (v, w) == (0.0, 0.0))
        if done:
            publish_odom = publish_scan = False  # the loop stops here, as in the template
        self._outputs.publish(z_scan, z_v, z_w, pose_before, pose, publish_odom, publish_scan)
        if done:
            self.finish("goal reached")

    # --- localization and goal -------------------------------------------------------------
    def _check_estimated_pose(self, message) -> None:
        was_localized, self.localized = self.localized, bool(message.localized)
        if not self.localized or self.simulator is None:
            return
        try:
            x_h, y_h, th_h = pose_from_message(message.pose)
        except ValueError as exc:
            self.get_logger().warning(f"/pose ignored: {exc}", throttle_duration_sec=2.0)
            return
        x, y, th = self.simulator.pose
        position_error = math.hypot(x_h - x, y_h - y)
        heading_error = angle_difference(th_h, th)
        self.localization_error = (position_error, heading_error)
        text = (f"estimated ({x_h:.2f}, {y_h:.2f}, {math.degrees(th_h):.1f} deg) | true "
                f"({x:.2f}, {y:.2f}, {math.degrees(th):.1f} deg) | error {position_error:.3f} m, "
                f"{math.degrees(heading_error):+.1f} deg")
        if not was_localized:
            self.get_logger().info(f"Localized: {text}")
        else:
            self.get_logger().info(text, throttle_duration_sec=1.0)

    @property
    def goal_reached_time(self) -> float | None:
        """Simulated time the goal was reached (amr_common.navigation_behaviour.GoalCheck)."""
        return None if self._goal_check is None else self._goal_check.reached_time

    def _check_goal(self, pose: tuple, resting: bool) -> bool:
        """Note the goal as reached and say whether the run is over (GoalCheck's rule)."""
        check, now = self._goal_check, self.simulator.time
        was_reached = check.reached_time is not None
        done = check.update(now, pose, self.localized, resting, self.simulator.dt)
        if not was_reached and check.reached_time is not None:
            self.get_logger().info(
                f"Congratulations, you reached the goal! (t = {now:.2f} s; the run ends once "
                f"the robot has rested {self.params['goal_rest_time']:g} s)")
        return done

    def finish(self, reason: str) -> None:
        """Stop stepping (commands are ignored from now on) and log the statistics."""
        if self.finished:
            return
        self.finished = True
        self.finish_reason = reason
        self._stop_timer()
        if self._wall_start is not None:
            self._wall_time = time.monotonic() - self._wall_start
        s = self.summary()
        per_step = s["wall_time_s"] / s["steps"] if s["steps"] else 0.0
        self.get_logger().warning(
            f"Finished ({reason}). Execution time: {s['wall_time_s']:.3f} s ({per_step:.4f} "
            f"s/step) | Simulated time: {s['sim_time_s']:.3f} s ({s['steps']} steps) | "
            f"collisions {collisions_text(s['collisions'], s['collisions_with_movers'])}, min "
            f"clearance {s['min_clearance_m']:.3f} m")

    def summary(self) -> dict[str, Any]:
        """Statistics of the run so far (JSON-serializable)."""
        simulator = self.simulator
        if simulator is None:
            return {"configured": False, "finished": self.finished}
        wall = self._wall_time if self.finished or self._wall_start is None else \
            time.monotonic() - self._wall_start
        x, y, theta = simulator.pose
        return {
            "configured": True, "finished": self.finished, "reason": self.finish_reason,
            "goal_reached": self.goal_reached_time is not None,
            "goal_reached_time_s": self.goal_reached_time,
            "stopped_time_s": self._goal_check.rest_since
            if self.finish_reason == "goal reached" else None,
            "world": simulator.world.name, "start": list(self._start_pose),
            "profile": simulator.profile.name,
            "mode": self.params["mode"], "steps": int(simulator.steps),
            "sim_time_s": float(simulator.time), "wall_time_s": float(wall),
            "pose": [float(x), float(y), float(theta)],
            "goal": list(self.goal) if self.goal is not None else None,
            "final_position_error_m": math.hypot(x - self.goal[0], y - self.goal[1])
            if self.goal is not None else None,
            "localized": self.localized,
            "localization_error": list(self.localization_error)
            if self.localization_error else None,
            "collisions": int(simulator.collisions),  # every one, movers' included
            "collisions_with_movers": int(simulator.collisions_with_movers),
            "min_clearance_m": float(simulator.min_clearance),
            "distance_m": float(simulator.distance),
            "effects": simulator.effects.as_dict() if simulator.effects else None,
        }


def main(args=None) -> int:
    return run_lifecycle_node(SimulatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
