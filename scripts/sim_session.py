"""One in-process simulation run for run_sim.py: build the graph, bring it up, run, report.

Lockstep: simulator (lockstep, /odometry with the encoder twist in both profiles) + wall
follower (simulation mode, params/sim.yaml).
Rehearsal (`--realtime --profile turtlebot3`): simulator (real time) + the robot graph of
run_robot.py (amr_odometry + wall follower in robot mode, params/turtlebot3.yaml).
With a goal (`--goal`), both add the navigation nodes: particle filter, planner and pure
pursuit; the wall follower explores until /pose is localized, the simulator ends the run once
the robot rests at the goal.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import rclpy
from rclpy.signals import SignalHandlerOptions

from amr_common.lifecycle_manager import LifecycleManager, LifecycleStartupError
from amr_common.node_runner import make_executor, shutdown_node
from launch_common import (
    ROBOT_PARAMS,
    SIM_PARAMS,
    make_navigation_nodes,
    make_robot_graph,
    make_viewer_nodes,
    make_wall_follower,
    overrides_to_parameters,
)

STALL_TIMEOUT_S = 10.0  # lockstep: no step for this long (wall clock) means the loop broke


def _robot_parameters(tuning: dict, params_file, profile_name: str) -> dict:
    """The simulated robot's values for the controller (where its LiDAR sits), unless set.

    Only those neither the -p overrides nor the params file set (the rehearsal's
    turtlebot3.yaml sets them itself).
    """
    from amr_common.controller_loader import DEFAULT_CONTROLLER, load_controller_class
    from amr_evaluation.episode import robot_parameters
    from amr_evaluation.evaluation import load_ros_params_file
    from amr_sim.profiles import get_profile
    try:
        in_file = load_ros_params_file(params_file)
        controller_class = load_controller_class(
            tuning.get("controller", in_file.get("controller", DEFAULT_CONTROLLER)))
    except Exception:  # a bad file or class: the node reports it when it configures
        return {}
    defaults = robot_parameters(controller_class, get_profile(profile_name))
    return {k: v for k, v in defaults.items() if k not in in_file and k not in tuning}


def _start_label(start) -> str:
    return start if isinstance(start, str) else ",".join(f"{v:g}" for v in start)


class SimSession:
    def __init__(self, args, world, start) -> None:
        from amr_sim.simulator_node import SimulatorNode
        self.args = args
        self.world = world
        self.start = start if start is not None else next(iter(world.starts))
        self.rehearsal = args.realtime and args.profile == "turtlebot3"
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.executor = make_executor(self.context)

        self.navigating = args.goal is not None
        localizing = args.enable_localization or self.navigating
        sim_values = {"world": args.world, "start": _start_label(self.start),
                      "profile": args.profile, "dt": args.dt, "seed": args.seed,
                      "mode": "realtime" if args.realtime else "lockstep",
                      "enable_localization": localizing,
                      # Viewers get a whole TF tree; a localization node sends its own map -> odom.
                      "map_to_odom_from_truth": not localizing}
        if args.goal:
            sim_values["goal"] = list(args.goal)
        self.simulator_node = SimulatorNode(
            context=self.context, parameter_overrides=overrides_to_parameters(sim_values))

        tuning = dict(args.overrides)
        if args.controller:
            tuning["controller"] = args.controller
        if self.rehearsal:
            params_file = args.params_file or ROBOT_PARAMS
            tuning.setdefault("enable_localization", localizing)
            self.control_nodes = make_robot_graph(
                self.context, params_file=params_file, dt=args.dt, tuning=tuning)
        else:
            tuning.update({"simulation": True, "dt": args.dt,
                           "enable_localization": localizing})
            params_file = args.params_file or SIM_PARAMS
            tuning = {**_robot_parameters(tuning, params_file, args.profile), **tuning}
            self.control_nodes = [make_wall_follower(
                self.context, params_file=params_file, overrides=tuning)]
        self.wall_follower = self.control_nodes[-1]
        self.planner_node = None
        if self.navigating:
            from amr_sim.profiles import get_profile
            self.control_nodes += make_navigation_nodes(
                self.context, world=args.world, goal=args.goal, simulation=not args.realtime,
                params_file=params_file, dt=args.dt,
                lidar_offset_x=None if self.rehearsal else get_profile(
                    args.profile).lidar_offset_x)
            self.planner_node = self.control_nodes[-2]
        self.localized_time: float | None = None
        # Viewers (the Foxglove bridge) first: they see the graph from its first message.
        self.viewer_nodes = make_viewer_nodes(self.context, args, use_sim_time=True)
        order = [node.get_name() for node in [*self.viewer_nodes, *self.control_nodes]] + [
            self.simulator_node.get_name()]
        self.manager = LifecycleManager(order, context=self.context)
        for node in [*self.viewer_nodes, *self.control_nodes, self.simulator_node, self.manager]:
            self.executor.add_node(node)
        self.trajectory: list[list[float]] = []
        self.wall_errors: list[float] = []
        self.view = None
        self.recorder = None

    # --- per-step observation (called by the simulator node after each step) ------------
    def _on_step(self, sim) -> None:
        x, y, theta = sim.pose
        self.trajectory.append([round(sim.time, 6), x, y, theta])
        if self.localized_time is None and self.simulator_node.localized:
            self.localized_time = round(sim.time, 6)
        controller = getattr(self.wall_follower, "controller", None)
        error = getattr(controller, "wall_distance_error", None)
        if error is not None and math.isfinite(error):
            self.wall_errors.append(float(error))
        if self.view is not None and not self.view.update(sim, sim.last_scan):
            self.stop_requested = True

    def run(self) -> dict:
        args = self.args
        if args.gui:
            from amr_sim.live_view import LiveView
            self.view = LiveView(self.world, title=f"amr_sim: {args.world} / "
                                                   f"{_start_label(self.start)}")
        if args.record:
            from amr_common.mcap_recorder import McapRecorder
            Path(args.record).parent.mkdir(parents=True, exist_ok=True)
            self.recorder = McapRecorder(args.record, metadata={
                "world": self.world.name, "start": _start_label(self.start),
                "profile": args.profile, "seed": str(args.seed), "dt": str(args.dt),
                "mode": "realtime" if args.realtime else "lockstep"})
            self._attach_recorder()
        self.simulator_node.on_step.append(self._on_step)
        self.stop_requested = False
        try:
            self.manager.startup(self.executor)
        except LifecycleStartupError as exc:
            raise SystemExit(f"run_sim: {exc}")
        sim = self.simulator_node.simulator
        x, y, theta = sim.pose
        self.trajectory.append([0.0, x, y, theta])
        wall_start = time.monotonic()
        last_steps, last_progress = sim.steps, wall_start
        try:
            while (sim.time < args.duration - 1e-9 and not self.simulator_node.finished
                   and not self.stop_requested):
                self.executor.spin_once(timeout_sec=0.1)
                if sim.steps != last_steps:
                    last_steps, last_progress = sim.steps, time.monotonic()
                elif time.monotonic() - last_progress > STALL_TIMEOUT_S:
                    raise SystemExit(f"run_sim: the loop stalled: no simulation step for "
                                     f"{STALL_TIMEOUT_S:.0f} s at t={sim.time:.2f} s")
        except KeyboardInterrupt:
            print("run_sim: interrupted")
        wall_time = time.monotonic() - wall_start
        if self.recorder is not None:
            # Stop stepping, then let the recorder take the last step's messages.
            if self.simulator_node._state_machine.current_state[1] == "active":
                self.simulator_node.trigger_deactivate()
            drain_end = time.monotonic() + 0.3
            while time.monotonic() < drain_end:
                self.executor.spin_once(timeout_sec=0.05)
        return self._report(sim, wall_time)

    def _attach_recorder(self) -> None:
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import OccupancyGrid, Odometry
        from rclpy.parameter import Parameter
        from sensor_msgs.msg import LaserScan
        from tf2_msgs.msg import TFMessage
        from visualization_msgs.msg import MarkerArray

        from amr_common.tf import TF_STATIC_LISTENER_QOS
        topics = {"/scan": LaserScan, "/ground_truth": Odometry, "/odometry": Odometry,
                  "/tf": TFMessage, "/tf_static": TFMessage, "/map": OccupancyGrid,
                  "/map_markers": MarkerArray}
        latched = {topic: TF_STATIC_LISTENER_QOS for topic in ("/tf_static", "/map",
                                                                "/map_markers")}
        if self.rehearsal:  # the simulated robot's pose-only /odom, before amr_odometry
            topics["/odom"] = Odometry
        stamped = not self.rehearsal or self.wall_follower.get_parameter(
            "cmd_vel_stamped").value
        topics["/cmd_vel"] = TwistStamped if stamped else Twist
        # Simulated time: messages without a header (/tf) are logged at the /clock time.
        recorder_node = rclpy.create_node("mcap_recorder", context=self.context,
                                          parameter_overrides=[Parameter("use_sim_time",
                                                                         value=True)])
        self.executor.add_node(recorder_node)  # destroyed with the others in close()
        self.recorder.attach(recorder_node, topics, qos=latched)

    def _report(self, sim, wall_time: float) -> dict:
        import numpy as np

        from amr_evaluation.episode import count_laps, explored_fraction
        positions = np.array([row[1:3] for row in self.trajectory])
        rms = (math.sqrt(sum(e * e for e in self.wall_errors) / len(self.wall_errors))
               if self.wall_errors else None)
        return {
            "world": self.world.name, "start": _start_label(self.start),
            "profile": self.args.profile, "mode": "realtime" if self.args.realtime else "lockstep",
            "seed": self.args.seed, "dt": self.args.dt,
            "controller": self.wall_follower.get_parameter("controller").value,
            "nodes": self.manager.node_startup_order,
            "controller_mode": "simulation" if self.wall_follower.get_parameter(
                "simulation").value else "robot (timer)",
            "steps": sim.steps, "sim_time_s": round(sim.time, 6),
            "wall_time_s": round(wall_time, 3),
            "real_time_factor": round(sim.time / wall_time, 2) if wall_time > 0 else None,
            "collisions": sim.collisions,
            "first_collision_time_s": sim.first_collision_time,
            "min_clearance_m": sim.min_clearance, "distance_m": sim.distance,
            "explored_fraction": explored_fraction(self.world, positions),
            "laps": count_laps(self.world, positions),
            "rms_wall_error_m": rms,
            **(self._navigation_report() if self.navigating else {}),
            "trajectory": self.trajectory,
            "collision_points": [list(p) for p in sim.collision_points],
        }

    def _navigation_report(self) -> dict:
        """Goal, time to localize, goal reached and stopped times, path, final error."""
        summary = self.simulator_node.summary()
        plan = self.planner_node.last_plan if self.planner_node is not None else None
        return {
            "goal": summary["goal"], "localized_time_s": self.localized_time,
            "goal_reached_time_s": summary["goal_reached_time_s"],
            "stopped_time_s": summary["stopped_time_s"],
            "final_position_error_m": summary["final_position_error_m"],
            "path_length_m": plan.length_m if plan is not None else None,
            "path": plan.points.tolist() if plan is not None else [],
        }

    def summary_line(self, report: dict) -> str:
        laps = report["laps"]
        if self.navigating:
            return self._navigation_line(report)
        return (f"run_sim: {report['world']} / {report['start']} / {report['profile']} "
                f"({report['mode']}): {report['sim_time_s']:.1f} s simulated in "
                f"{report['wall_time_s']:.1f} s ({report['real_time_factor']}x real time), "
                f"{report['steps']} steps, collisions {report['collisions']}, min clearance "
                f"{report['min_clearance_m'] * 100:.1f} cm, distance {report['distance_m']:.1f} m,"
                f" explored {report['explored_fraction'] * 100:.0f}%"
                + (f", laps {laps}" if laps else ""))

    @staticmethod
    def _navigation_line(report: dict) -> str:
        def when(key: str) -> str:
            return "never" if report[key] is None else f"{report[key]:.1f} s"
        path = "no path" if report["path_length_m"] is None else \
            f"path {report['path_length_m']:.2f} m"
        return (f"run_sim: {report['world']} / {report['start']} -> goal "
                f"({report['goal'][0]:g}, {report['goal'][1]:g}) / {report['profile']} "
                f"({report['mode']}): localized {when('localized_time_s')}, goal reached "
                f"{when('goal_reached_time_s')}, stopped {when('stopped_time_s')}, {path}, "
                f"final error {report['final_position_error_m'] * 100:.1f} cm, collisions "
                f"{report['collisions']}, min clearance {report['min_clearance_m'] * 100:.1f} "
                f"cm; {report['sim_time_s']:.1f} s simulated in {report['wall_time_s']:.1f} s "
                f"({report['real_time_factor']}x real time)")

    def close(self) -> None:
        # Controllers first: they publish their final zero command while the graph still runs.
        for node in [*self.control_nodes, self.simulator_node, *self.viewer_nodes]:
            shutdown_node(node)
        if self.recorder is not None:
            self.recorder.close()
        if self.view is not None:
            self.view.close()
        for node in list(self.executor.get_nodes()):
            self.executor.remove_node(node)
            node.destroy_node()
        self.executor.shutdown(timeout_sec=1.0)
        if self.context.ok():
            rclpy.shutdown(context=self.context)
