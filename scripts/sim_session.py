"""One in-process simulation run for run_sim.py: build the graph, bring it up, run, report.

Lockstep: simulator (lockstep, /odometry with the encoder twist in both profiles) + wall
follower (simulation mode, params/sim.yaml).
Rehearsal (`--realtime --profile turtlebot3`): simulator (real time) + the robot graph of
run_robot.py (amr_odometry + wall follower in robot mode, params/turtlebot3.yaml).
With a goal (`--goal`), both add the particle filter, the planner and the pure pursuit: the wall
follower explores until /pose is localized, the simulator ends the run once the robot rests at
the goal.
With a map that is not the world (`--map`), the particle filter and the planner load the map,
and /map is the map (amr_map_publisher, as on the robot; the simulator publishes none).
With `--slam`, the slam node maps (its /map and map -> odom replace the simulator's) in
the world's frame; the map is written at the end (`--map-out`), Ctrl-C included.
"""
from __future__ import annotations

import math
import sys
import time

import rclpy
from rclpy.signals import SignalHandlerOptions
from sim_report import (
    link_failure_fields,
    localization_fields,
    navigation_fields,
    navigation_line,
    run_line,
    run_report,
    slam_fields,
)

from amr_common.ros.lifecycle_manager import LifecycleManager, LifecycleStartupError
from amr_common.ros.lifecycle_node import first_link_failure
from amr_common.ros.node_runner import make_executor, shutdown_node
from amr_common.world.world import start_label
from amr_sim.simulator_node import SimulatorNode
from launch_common import (
    ROBOT_PARAMS,
    SIM_PARAMS,
    localizing_wall_follower,
    make_map_publisher,
    make_navigators,
    make_particle_filter,
    make_robot_graph,
    make_viewer_nodes,
    make_wall_follower,
    navigating_wall_follower,
    overrides_to_parameters,
    simulated_robot_parameters,
)

STALL_TIMEOUT_S = 10.0  # lockstep: no step for this long (wall clock) means the loop broke
RECORDER_MATCH_TIMEOUT_S = 2.0  # in one process the recorder matches its publishers in ms


def _simulator_values(args, start: str, own_map: bool, localize: bool, slam: bool) -> dict:
    """The simulator node's parameters from run_sim's options."""
    sim_values = {"world": args.world, "start": start,
                  "profile": args.profile, "dt": args.dt, "seed": args.seed,
                  "mode": "realtime" if args.realtime else "lockstep",
                  "enable_localization": args.enable_localization or localize,
                  # Viewers get a whole TF tree: the particle filter sends map -> odom when
                  # it runs; without it (or a user's own localization node) the truth does.
                  "map_to_odom_from_truth": not (args.enable_localization or localize
                                                 or slam),
                  # The map publisher sends --map; the slam node the map being built.
                  "publish_map": not (own_map or slam),
                  # /world_markers: the world's walls --map lacks
                  "navigation_map": args.map if own_map else ""}
    if args.goal:
        sim_values["goal"] = list(args.goal)
    if getattr(args, "kidnap", None):
        sim_values["kidnap"] = list(args.kidnap)
    return sim_values


class SimSession:
    """One start of a run_sim.py run: the graph in one process, its report and outputs.

    `stop` (an amr_common.ros.node_runner.StopFlag) ends the run early: the report is then marked
    interrupted. `record_path`: an MCAP file for this start's topics. `map_world`: the map of
    the filter, the planner and /map (None or `world`: the world; then args.map is not used).
    """

    def __init__(self, args, world, start, stop=None, record_path=None,
                 map_world=None, map_prefix="") -> None:
        self.args = args
        self.world = world
        self.map_world = map_world if map_world is not None else world
        # What the filter and the planner load: the map's file, else the world's.
        own_map = self.map_world is not world
        map_source = args.map if own_map else args.world
        self.start = start if start is not None else next(iter(world.starts))
        self.stop = stop
        self.record_path = record_path
        self.interrupted = False
        self._sim_time_ns = 0  # the recorder's clock in real time: the newest simulated time
        from amr_sim.profiles import get_profile
        self.rehearsal = args.realtime and get_profile(args.profile).odom_topic == "/odom"
        self.context = rclpy.Context()
        # No arguments for rcl: by default it reads the script's own command line (a value
        # such as '__node:=x' would rename every node, 'name:=value' warns as a remap rule).
        rclpy.init(args=[], context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.executor = make_executor(self.context)

        self.navigating = getattr(args, "goal", None) is not None
        localize = getattr(args, "localize", False) or self.navigating
        slam = getattr(args, "slam", False)
        sim_values = _simulator_values(args, start_label(self.start), own_map, localize, slam)
        self.simulator_node = SimulatorNode(
            context=self.context, parameter_overrides=overrides_to_parameters(sim_values))

        self.control_nodes = self._make_control_nodes(map_source, localize)
        self.slam_node = None
        if slam:
            self._add_slam_node(map_prefix)
        self.wall_follower, self.particle_filter, self.planner_node = (
            next((n for n in self.control_nodes if n.get_name() == name), None)
            for name in ("wall_follower", "particle_filter", "planner"))
        self.estimate: list[list[float]] = []
        self.particles_snapshot: list[list[float]] = []
        if self.particle_filter is not None:
            self.particle_filter.on_pose.append(self._on_pose)
        # Viewers (the Foxglove bridge) first: they see the graph from its first message.
        self.viewer_nodes = make_viewer_nodes(self.context, args, use_sim_time=True)
        if own_map:
            self.viewer_nodes.append(make_map_publisher(self.context, map_source,
                                                        use_sim_time=True))
        order = [node.get_name() for node in [*self.viewer_nodes, *self.control_nodes]] + [
            self.simulator_node.get_name()]
        self.manager = LifecycleManager(order, context=self.context)
        for node in [*self.viewer_nodes, *self.control_nodes, self.simulator_node, self.manager]:
            self.executor.add_node(node)
        self.trajectory: list[list[float]] = []
        self.wall_errors: list[float] = []
        self.view = None
        self.recorder = None
        self.graph_recorder = None

    def _make_control_nodes(self, map_source: str, localize: bool) -> list:
        """The wall follower, with the filter, planner and pursuit when they run.

        In a rehearsal the robot's graph (params/turtlebot3.yaml), else the simulation's.
        """
        args = self.args
        tuning = dict(args.overrides)
        if args.controller:
            tuning["controller"] = args.controller
        filter_overrides = getattr(args, "pf_overrides", {})
        links = getattr(args, "links", {})  # --localizer, --planner, --follower
        if self.rehearsal:
            params_file = args.params_file or ROBOT_PARAMS
            tuning = {**simulated_robot_parameters(tuning, params_file, args.profile), **tuning}
            control_nodes = make_robot_graph(
                self.context, params_file=params_file, dt=args.dt,
                tuning=tuning, localize_world=map_source if localize else None,
                filter_overrides=filter_overrides,
                goal=args.goal if self.navigating else None, links=links)
            if getattr(args, "no_controller", False):  # the user drives (teleop.py)
                from launch_slam import without_controller
                without_controller(control_nodes)
        else:
            base = {"simulation": True, "dt": args.dt}
            if args.enable_localization:  # a localization node of the user's
                base["enable_localization"] = True
            # (Not False otherwise: the graphs with the filter below synchronize /pose.)
            if self.navigating:
                base = navigating_wall_follower(base)
            elif localize:
                base = localizing_wall_follower(base)
            tuning = {**base, **tuning}  # -p wins
            params_file = args.params_file or SIM_PARAMS
            tuning = {**simulated_robot_parameters(tuning, params_file, args.profile), **tuning}
            control_nodes = [make_wall_follower(
                self.context, params_file=params_file, overrides=tuning)]
            if localize:
                from amr_common.plugins.loader import DEFAULT_LOCALIZER, link_class
                from amr_evaluation.episode import filter_parameters
                from amr_sim.profiles import get_profile
                sensor = filter_parameters(  # those the localizer takes
                    get_profile(args.profile), self.map_world is self.world,
                    link_class(links.get("localizer") or DEFAULT_LOCALIZER, "localizer"))
                lidar_offset_x = sensor.pop("lidar_offset_x_m")
                # The filter draws from --seed, as the headless episodes' filter does.
                control_nodes.append(make_particle_filter(
                    self.context, world=map_source, lidar_offset_x_m=lidar_offset_x,
                    overrides={"seed": args.seed, **filter_overrides},
                    localizer=links.get("localizer"), sensor=sensor))
            if self.navigating:
                control_nodes += make_navigators(
                    self.context, world=map_source, goal=args.goal,
                    wall_follower=control_nodes[0], lidar_offset_x_m=lidar_offset_x,
                    links=links)
        return control_nodes

    def _add_slam_node(self, map_prefix: str) -> None:
        """The slam node, mapping in the world's frame (its start pose), saving to map_prefix.

        The simulated scanner's LiDAR position, `deskew`, its range error and the unit's
        calibration (args.slam_lidar: launch_slam.lidar_parameters) or --slam-param.
        """
        from launch_slam import make_slam_node
        self.map_prefix = map_prefix
        self.slam_estimate: list[list[float]] = []
        self.slam_raster = None  # the map at the end of the run (for the plot)
        overrides = dict(self.args.slam_lidar)  # launch_slam.lidar_parameters (run_sim checks)
        offset = overrides.pop("lidar_offset_x_m")
        self.slam_range_correction = overrides.get("range_correction")
        self.slam_node = make_slam_node(self.context, lidar_offset_x_m=offset,
                                        output_prefix=map_prefix, overrides=overrides,
                                        start_pose=self.world.resolve_start(self.start))
        self.slam_node.on_estimate.append(
            lambda stamp_ns, estimate, node: self.slam_estimate.append(
                [round(stamp_ns * 1e-9, 6), *estimate.pose]))
        self.control_nodes.append(self.slam_node)

    # --- per-step observation (called by the simulator node after each step) ------------
    def _on_step(self, sim) -> None:
        x, y, theta = sim.pose
        self.trajectory.append([round(sim.time, 6), x, y, theta])
        self._sim_time_ns = sim.steps * round(sim.dt * 1e9)
        controller = getattr(self.wall_follower, "controller", None)
        error = getattr(controller, "wall_distance_error", None)
        if error is not None and math.isfinite(error):
            self.wall_errors.append(float(error))
        if self.view is not None and not self.view.update(sim, sim.last_scan):
            self.stop_requested = True

    def _on_pose(self, stamp_ns: int, pose, localized: bool, node) -> None:
        self.estimate.append([round(stamp_ns * 1e-9, 6), *pose, float(localized)])
        if localized and not self.particles_snapshot:
            particles = node.filter.particles
            step = max(1, len(particles) // 500)
            self.particles_snapshot = particles[::step].round(4).tolist()
    def _stop_requested(self) -> bool:
        return self.stop_requested or (self.stop is not None and self.stop.requested)

    def run(self) -> dict:
        """Bring the graph up, step until the duration, the goal or a stop; return the report.

        StartupInterrupted (lifecycle_manager) if stopped before the graph ran.
        """
        args = self.args
        if args.gui:
            from amr_sim.live_view import LiveView
            self.view = LiveView(self.world, title=f"amr_sim: {args.world} / "
                                                   f"{start_label(self.start)}")
        if self.record_path:
            from amr_tools.mcap_recorder import McapRecorder
            self.recorder = McapRecorder(self.record_path, metadata={
                "world": self.world.name, "map": self.map_world.name,
                "start": start_label(self.start),
                "profile": args.profile, "seed": str(args.seed), "dt": str(args.dt),
                "mode": "realtime" if args.realtime else "lockstep"})
            self._record_graph()
        self.simulator_node.on_step.append(self._on_step)
        self.stop_requested = False
        try:
            self.manager.startup(self.executor, self.stop,
                                 before_activation=self._before_activation)
        except LifecycleStartupError as exc:
            raise SystemExit(f"run_sim: {exc}")
        sim = self.simulator_node.simulator
        x, y, theta = sim.pose
        self.trajectory.append([0.0, x, y, theta])
        wall_start = time.monotonic()
        last_steps, last_progress = sim.steps, wall_start
        try:
            # A goal the planner cannot reach ends the run at once: the robot would only wait.
            while (sim.time < args.duration - 1e-9 and not self.simulator_node.finished
                   and not self._stop_requested() and self.planning_error() is None
                   and first_link_failure(self.control_nodes) is None):
                self.executor.spin_once(timeout_sec=0.1)
                if sim.steps != last_steps:
                    last_steps, last_progress = sim.steps, time.monotonic()
                elif time.monotonic() - last_progress > STALL_TIMEOUT_S:
                    raise SystemExit(f"run_sim: the loop stalled: no simulation step for "
                                     f"{STALL_TIMEOUT_S:.0f} s at t={sim.time:.2f} s")
        except KeyboardInterrupt:  # only without a StopFlag (run_sim.py installs one)
            self.interrupted = True
        self.interrupted = self.interrupted or (self.stop is not None and self.stop.requested)
        if self.interrupted:  # (a failed link: its node logged it, the summary says it)
            print(f"run_sim: interrupted at t={sim.time:.2f} s")
        elif self.planning_error() is not None:
            print(f"run_sim: no path to the goal: {self.planning_error()}", file=sys.stderr)
        wall_time = time.monotonic() - wall_start
        if self.recorder is not None:
            # Stop stepping, then let the recorder take the last step's messages.
            if self.simulator_node._state_machine.current_state[1] == "active":
                self.simulator_node.trigger_deactivate()
            self._spin_for(0.15)
        return self._report(sim, wall_time)

    def _spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)

    def _record_graph(self) -> None:
        """Record every topic of the graph into self.recorder, as `ros2 bag record -a`."""
        from amr_tools.graph_recorder import GraphRecorder
        recorder_node = rclpy.create_node("mcap_recorder", context=self.context)
        self.executor.add_node(recorder_node)  # destroyed with the others in close()
        # One time base per file, simulated time. In lockstep every message is stamped with it
        # (exact log times; /tf by its first transform); in real time the controller stamps
        # with the wall clock, so each message is logged when it arrives, on the simulated clock.
        self.graph_recorder = GraphRecorder(
            self.recorder, recorder_node, clock=lambda: self._sim_time_ns,
            log_time="receive" if self.args.realtime else "header")

    def _before_activation(self) -> None:
        """All configured, nothing published: record from the first measurement on (matched)."""
        if self.graph_recorder is None:
            return
        self.graph_recorder.discover()
        deadline = time.monotonic() + RECORDER_MATCH_TIMEOUT_S
        while not (self.graph_recorder.matched() or self._stop_requested()) and \
                time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)

    def recording_line(self) -> str | None:
        """'recording written: F (N messages, T s)' once the recording is closed, else None."""
        recorder = self.recorder
        return None if recorder is None or not recorder.closed else (
            f"recording written: {recorder.path} ({sum(recorder.message_counts.values())} "
            f"messages, {recorder.duration_s:.1f} s)")

    def _report(self, sim, wall_time: float) -> dict:
        follower = self.wall_follower
        return run_report(self.args, self.world, self.start, sim, self.trajectory,
                          self.wall_errors, wall_time, self.interrupted, graph={
                              "controller": None if follower is None else
                              follower.get_parameter("controller").value,
                              "nodes": self.manager.node_startup_order,
                              "controller_mode": "none (teleop)" if follower is None else
                              "simulation" if follower.get_parameter("simulation").value
                              else "robot (timer)"},
                          map_world=self.map_world) \
            | self._localization_report() | self._navigation_report() | self._slam_report() \
            | link_failure_fields(first_link_failure(self.control_nodes))

    def _slam_report(self) -> dict:
        """The SLAM figures; the map written to the --map-out prefix first (if any)."""
        node = self.slam_node
        if node is None:
            return {}
        map_file, map_error = None, "no scan was mapped" if self.map_prefix else None
        if node.mapper is not None and node.mapped_scans:
            self.slam_raster = node.map_raster()  # None if the mapper failed
            if self.map_prefix:
                try:
                    map_file, map_error = node.save_map(self.map_prefix), None
                except (ValueError, OSError) as exc:  # checked, but it may go (run_sim says)
                    map_error = str(exc)
        return slam_fields(self.world, self.args.profile, self.trajectory, self.slam_estimate,
                           self.slam_raster, node.mapper_statistics(), node.mapper_max_range(),
                           node.timings(), map_file, self.slam_range_correction, map_error)

    def _localization_report(self) -> dict:
        return {} if self.particle_filter is None else localization_fields(
            self.args, self.trajectory, self.estimate, self.particles_snapshot)

    def _navigation_report(self) -> dict:
        if not self.navigating:
            return {}
        return navigation_fields(self.args.goal, self.simulator_node.summary(),
                                  self.planner_node.last_plan, self.estimate,
                                  self.planning_error())

    def planning_error(self) -> str | None:
        """Why the planner found no path to the goal (it logged it), or None."""
        return None if self.planner_node is None else self.planner_node.last_error

    def summary_line(self, report: dict) -> str:
        """One line for the terminal: where, how long, how fast, how safe."""
        return navigation_line(report) if self.navigating else run_line(report)

    def close(self) -> None:
        """Shut the graph down (controllers first: their zero command goes out), close files."""
        # Controllers first: they publish their final zero command while the graph still runs.
        for node in self.control_nodes:
            shutdown_node(node)
        if self.recorder is not None:
            self._spin_for(0.1)  # the recording ends with that zero command
        for node in [self.simulator_node, *self.viewer_nodes]:
            shutdown_node(node)
        if self.graph_recorder is not None:
            self.graph_recorder.close()
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
