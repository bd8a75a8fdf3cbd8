"""Headless navigation episodes: simulator, pose source, planner, pure pursuit, wall follower.

The nodes' lockstep order (the wall follower while not localized), with the figures of the
navigation runs (goal reached, time localized, final error, clearance).

    result = run_navigation_episode("lab02", "outer", goal="inner_far")
    print(result.summary())

Each step, as the nodes do it, by the same rules (amr_common.navigation_behaviour): the pose
source turns the measurement into a pose estimate and a `localized` flag (the particle filter's
/pose). The wall follower computes on every measurement and commands while not localized
(Handover). Localized: on the first localized step (and again after each loss of localization)
the planner plans from the estimate to the goal; the path reaches the pursuit after that pose
(as /path does in the graph), so the pursuit answers it with zero, then follows, and commands
zero once stopped at the path's end. The goal counts as reached when the TRUE position is within
goal_tolerance while localized, and the episode ends once the robot has then rested
goal_rest_time (GoalCheck, as the simulator node), so the final position error is measured where
the robot rests. tests/test_headless_is_the_ros_graph.py checks the trajectory is the ROS
lockstep graph's.

Pose sources (`pose_source`): "filter" (the particle filter of amr_localization, as the ROS
graph runs it: predicted with every odometry twist, corrected with every new scan), "truth"
(`GroundTruthPose`: the true pose, localized from the start), or any object with
`update(sim, z_scan, z_v, z_w) -> ((x, y, theta), localized)` called once per step with the
newest measurement and odometry twist.

`map` (default the world): the map the pose source and the planner use while the simulator
drives in the world (amr_common.world.map_vs_world): an unmapped box, a moved wall, a SLAM map. The
goal is checked against the map (the planner's), `goal_warning` says when the world blocks it;
the pursuit still slows near what the scan sees, and every figure is measured in the world.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np

from amr_common.geometry import polyline_length
from amr_common.navigation_behaviour import (
    GoalCheck,
    Handover,
    KidnapSchedule,
    OdometryHold,
    as_sent_pose,
    as_sent_ranges,
)
from amr_common.plugins.interfaces import PathFollower
from amr_common.plugins.link_failure import checked_path, link_call
from amr_common.plugins.loader import (
    DEFAULT_FOLLOWER,
    DEFAULT_LOCALIZER,
    DEFAULT_PLANNER,
    link_class,
)
from amr_common.world.map_vs_world import load_map, resolve_goal_on_map
from amr_common.world.movers import collisions_text
from amr_common.world.world import World
from amr_control.pure_pursuit import scan_clearance, scan_free_ahead
from amr_evaluation.episode import (
    checked_duration,
    commanded,
    default_controller,
    episode_start_label,
    failures_placed,
    tell_scan_geometry,
)
from amr_evaluation.localization_episode import localization_metrics
from amr_evaluation.pose_sources import make_pose_source
from amr_sim.profiles import get_profile
from amr_sim.simulator import Simulator
from amr_sim.simulator_params import PARAMETERS as SIMULATOR_PARAMETERS

GOAL_TOLERANCE_M = SIMULATOR_PARAMETERS["goal_tolerance"][0]
GOAL_REST_TIME_S = SIMULATOR_PARAMETERS["goal_rest_time"][0]


def _pursue(pursuit: PathFollower, pose, z_scan, geometry, prof, radius: float):
    """The pure pursuit node's command for a localized pose (amr_control.pure_pursuit_node).

    The scan's obstacles only once it has a path; the command clipped to the Burger's limits
    (what the follower raises or a command that is not two finite numbers: its failure).
    """
    def compute():
        obstacles = (None, None)
        if pursuit.path is not None:
            scan = (z_scan, geometry[0], geometry[1], geometry[3], geometry[4],
                    prof.lidar_offset_x, radius)
            obstacles = (scan_clearance(*scan), scan_free_ahead(*scan))
        return pursuit.compute_commands(*pose, *obstacles)
    return commanded("follower", compute)


@dataclass
class NavigationResult:
    """What a navigation episode measured (simulated seconds; None if it never happened)."""

    world: str
    start: str | list[float]
    goal: list[float]
    profile: str
    seed: int
    steps: int
    sim_time_s: float
    wall_time_s: float
    real_time_factor: float | None
    pose_source: str
    localized_time_s: float | None  # first localized step
    goal_reached_time_s: float | None  # true position within goal_tolerance while localized
    stopped_time_s: float | None  # the robot came to rest at the goal (GoalCheck.rest_since)
    path_length_m: float | None  # the last planned path
    path_min_clearance_m: float | None  # its smallest distance to a wall (robot centre)
    distance_m: float  # driven
    final_position_error_m: float  # true position to the goal at the end
    min_clearance_m: float  # smallest footprint clearance of the run (the simulator's)
    collisions: int
    plans: int
    planning_errors: list[str]
    plan_time_ms: float | None  # the last plan
    cross_track_mean_m: float | None  # true position to the followed path while pursuing
    cross_track_max_m: float | None
    finish_reason: str
    invalid_commands: int = 0  # commands that were not finite numbers (the robot stopped)
    # The pose source against the truth (amr_evaluation.localization_episode's metrics): a
    # wrong pose declared localized (> 10 cm or 10 deg), and the error while localized.
    false_localizations: int = 0
    tracking_error_mean_m: float | None = None
    kidnap: list[float] | None = None  # [t, x, y, theta]
    stalled: bool = False  # localized with zero commands for stall_timeout_s before the goal
    dt: float = 0.05
    map: str = ""  # the name of the map the filter and the planner used (the world's default)
    goal_warning: str | None = None  # the world blocks the goal the map has free
    trajectory: list[list[float]] = field(default_factory=list)  # [[t, x, y, theta], ...]
    path: list[list[float]] = field(default_factory=list)  # the last planned path [[x, y], ...]
    collision_points: list[list[float]] = field(default_factory=list)  # [[x, y], ...]
    effects: dict[str, float] | None = None  # the reality-gap effects in use (drawn if randomized)
    collisions_with_movers: int = 0  # the part of `collisions` with the world's movers
    mover_waits: list[list[list[float]]] = field(default_factory=list)  # per mover [t0, t1]s

    @property
    def goal_reached(self) -> bool:
        """True if the simulator counted the goal as reached."""
        return self.goal_reached_time_s is not None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable dict."""
        return asdict(self)

    def summary(self) -> str:
        """One line for a terminal."""
        def when(t):
            return "never" if t is None else f"{t:.1f} s"
        on_map = f" (map {self.map})" if self.map and self.map != self.world else ""
        return (f"{self.world}{on_map} / {self.start} -> ({self.goal[0]:g}, {self.goal[1]:g}) / "
                f"{self.profile}: localized {when(self.localized_time_s)}, goal reached "
                f"{when(self.goal_reached_time_s)}, stopped {when(self.stopped_time_s)}, path "
                f"{self.path_length_m or 0:.2f} m, final error "
                f"{100 * self.final_position_error_m:.1f} cm, min clearance "
                f"{100 * self.min_clearance_m:.1f} cm, collisions "
                f"{collisions_text(self.collisions, self.collisions_with_movers)}, "
                f"{self.real_time_factor or 0:.0f}x real time ({self.finish_reason})")


def distances_to_polyline(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Distance from each point (K, 2) to the polyline `path` (M, 2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    path = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    if len(path) == 1:
        return np.hypot(*(pts - path[0]).T)
    a, d = path[:-1], np.diff(path, axis=0)
    out = np.empty(len(pts))
    for i0 in range(0, len(pts), 512):  # chunks keep the (K, M) matrices small
        p = pts[i0:i0 + 512, None, :]
        t = np.clip(np.einsum("kmj,mj->km", p - a, d) / np.einsum("mj,mj->m", d, d), 0.0, 1.0)
        nearest = a + t[..., None] * d
        out[i0:i0 + 512] = np.hypot(*(nearest - p).transpose(2, 0, 1)).min(axis=1)
    return out


def run_navigation_episode(
        world: World | str, start=None, goal=None, profile: str = "ideal", seed: int = 0,
        duration: float = 300.0, dt: float = 0.05, pose_source: Any = "truth",
        filter_params: dict | None = None, kidnap: Sequence[float] | None = None,
        planner: Any = None, planner_params: dict | None = None,
        pursuit_params: dict | None = None, wall_follower: Any = None,
        goal_tolerance: float = GOAL_TOLERANCE_M, goal_rest_time: float = GOAL_REST_TIME_S,
        stall_timeout_s: float = 30.0,
        record_trajectory: bool = True, map: World | str | None = None,
        localizer: str | type = DEFAULT_LOCALIZER, planner_class: str | type = DEFAULT_PLANNER,
        follower: str | type = DEFAULT_FOLLOWER) -> NavigationResult:
    """Drive from `start` to `goal` and measure it; see the module docstring.

    start: a name, (x, y, theta) or None (the first start); goal: a name, "x,y", (x, y) or None
    (the map's goal, else the world's). `planner` may be passed prebuilt on the map (its grid
    costs are built once per map). `map`: see the module docstring (None: the world). kidnap
    (t, x, y, theta): the robot is teleported at simulated time t (the filter must notice and
    relocalize). Stalled: localized and commanded zero for stall_timeout_s before reaching the
    goal (the episode then ends) - also when something the map lacks blocks the way.
    localizer, planner_class, follower: the classes (or their MODULE:CLASS) of the links
    (amr_common.plugins.interfaces), default the project's; the episode uses only interface
    members.
    """
    duration = checked_duration(duration)
    world_obj = world if isinstance(world, World) else World.load(world)
    map_obj = load_map(map, world_obj)
    goal_xy, goal_warning = resolve_goal_on_map(goal, map_obj, world_obj)
    prof = get_profile(profile)
    sim = Simulator(world_obj, start=start, dt=dt, profile=prof, seed=seed)
    source_name = pose_source if isinstance(pose_source, str) else type(pose_source).__name__
    pose_source = make_pose_source(pose_source, map_obj, sim, seed, filter_params, localizer)
    if planner is None:
        planner = link_class(planner_class, "planner")(map_obj, **(planner_params or {}))
    params = {"lidar_offset_x_m": prof.lidar_offset_x, **(pursuit_params or {})}
    pursuit = link_class(follower, "follower")(sim.dt, **params)
    if wall_follower is None:
        wall_follower = default_controller(sim.dt, prof)
    run = _Navigation(sim, pose_source, planner, pursuit, wall_follower, goal_xy, kidnap,
                      GoalCheck(goal_xy, goal_tolerance, goal_rest_time), record_trajectory)
    wall_start = time.perf_counter()
    with failures_placed(sim, {"controller": wall_follower, "planner": planner,
                               "follower": pursuit,
                               "localizer": getattr(pose_source, "filter", None)}):
        for _ in range(int(round(duration / sim.dt))):
            if run.step(stall_timeout_s):
                break
    wall_time = time.perf_counter() - wall_start
    start_label = episode_start_label(start, world_obj, sim)
    return run.result(world_obj.name, start_label, map_obj, source_name, seed, wall_time,
                      goal_warning)


class _Navigation:
    """One navigation episode's loop: the rules the nodes follow (navigation_behaviour)."""

    def __init__(self, sim: Simulator, pose_source: Any, planner: Any, pursuit: PathFollower,
                 wall_follower: Any, goal_xy: tuple[float, float],
                 kidnap: Sequence[float] | None, goal_check: GoalCheck,
                 record_trajectory: bool) -> None:
        self.sim, self.pose_source, self.planner = sim, pose_source, planner
        self.pursuit, self.wall_follower, self.goal_xy = pursuit, wall_follower, goal_xy
        self.kidnap, self.goal_check = kidnap, goal_check
        self.record_trajectory = record_trajectory
        self.geometry = sim.scan_geometry
        tell_scan_geometry(wall_follower, self.geometry)
        self.trajectory = [[0.0, *sim.pose]] if record_trajectory else []
        self.localized_time: float | None = None
        self.plans, self.errors, self.plan_ms, self.path = 0, [], None, None
        self.pursued: list[tuple[float, float]] = []  # true positions while pursuing
        # (t, true x, y, theta, estimated x, y, theta, localized)
        self.poses: list[tuple[float, ...]] = []
        self.stalled = False
        self.idle_steps = 0  # consecutive localized zero commands before the goal
        self.handover = Handover()
        self.kidnapping = KidnapSchedule(kidnap)
        z_scan, z_v, z_w = sim.measure()
        self.z_scan = as_sent_ranges(z_scan)
        self.odometry = OdometryHold(sim.profile.odom_period, z_v, z_w)

    def step(self, stall_timeout_s: float) -> bool:
        """One measurement -> command -> simulator step; True when the episode is over."""
        sim, pursuit = self.sim, self.pursuit
        estimate, localized = self.pose_source.update(sim, self.z_scan, *self.odometry.twist)
        self.poses.append((sim.time, *sim.pose, *estimate, float(localized)))
        event = self.handover.update(localized)
        if localized and self.localized_time is None:
            self.localized_time = sim.time
        if event == "lost":
            pursuit.clear_path()  # the wall follower takes over; replan when relocalized
        # The wall follower computes on every measurement (as its node), commands while in charge.
        explore = commanded("controller", self.wall_follower.compute_commands, self.z_scan,
                            *self.odometry.twist)
        if self.handover.explorer_in_charge:
            v, w = explore
        else:
            v, w = _pursue(pursuit, as_sent_pose(estimate), self.z_scan, self.geometry,
                           sim.profile, pursuit.robot_radius_m)
            if pursuit.state in ("track", "rotate"):
                self.pursued.append(sim.pose[:2])
        if self.handover.plans(event):
            # After the pursuit answered this pose: in the graph the planner's /path arrives
            # after the /pose it was planned from has reached the pursuit (a zero command).
            self._plan(estimate)
        self.idle_steps = self.idle_steps + 1 if localized and (v, w) == (0.0, 0.0) else 0
        if self.idle_steps * sim.dt >= stall_timeout_s:
            self.stalled = True
            return True
        teleport = self.kidnapping.due(sim.time)
        if teleport is not None:
            sim.teleport(teleport)
        z_scan, z_v, z_w = sim.step(v, w)
        self.z_scan = as_sent_ranges(z_scan)
        if self.record_trajectory:
            self.trajectory.append([sim.time, *sim.pose])
        if self.goal_check.update(sim.time, sim.pose, localized, (v, w) == (0.0, 0.0), sim.dt):
            return True
        if sim.scan_geometry is not self.geometry:  # the LDS-02: every scan
            self.geometry = sim.scan_geometry
            tell_scan_geometry(self.wall_follower, self.geometry)
        self.odometry.update(sim.time, z_v, z_w)
        return False

    def _plan(self, estimate: Sequence[float]) -> None:
        """A path from the estimate to the goal for the pursuit (or the planner's error)."""
        self.plans += 1
        began = time.perf_counter()
        try:  # the planner node's checks (amr_common.plugins.link_failure): no path, or a failure
            self.path = checked_path(link_call("planner", "plan", self.planner.plan,
                                               estimate[:2], self.goal_xy, allowed=(ValueError,)))
            self.plan_ms = (time.perf_counter() - began) * 1e3
            self.pursuit.set_path(self.path)
        except ValueError as exc:  # PlanningError (the interface's): no path
            self.errors.append(f"t={self.sim.time:.2f} s: {exc}")
            self.pursuit.clear_path()

    def result(self, world_name: str, start_label: Any, map_obj: World, source_name: str,
               seed: int, wall_time: float, goal_warning: str | None) -> NavigationResult:
        """What the episode measured."""
        sim, path, goal_check, kidnap = self.sim, self.path, self.goal_check, self.kidnap
        x, y, _ = sim.pose
        rows = np.array(self.poses, dtype=float).reshape(-1, 8)
        pose_figures = localization_metrics(rows[:, :4], rows[:, [0, 4, 5, 6, 7]],
                                            np.zeros(len(rows)), kidnap)
        over = goal_check.reached_time is not None and goal_check.rest_since is not None and \
            sim.time - goal_check.rest_since >= goal_check.rest_time - 1e-9
        stopped_time = goal_check.rest_since if over else None
        cross = distances_to_polyline(np.array(self.pursued), path) \
            if self.pursued and path is not None else None
        return NavigationResult(
            world=world_name, start=start_label,
            goal=[float(self.goal_xy[0]), float(self.goal_xy[1])], profile=sim.profile.name,
            seed=int(seed), pose_source=source_name, steps=sim.steps, sim_time_s=sim.time,
            wall_time_s=wall_time,
            real_time_factor=sim.time / wall_time if wall_time > 0 else None,
            localized_time_s=self.localized_time, goal_reached_time_s=goal_check.reached_time,
            stopped_time_s=stopped_time,
            path_length_m=polyline_length(path) if path is not None else None,
            path_min_clearance_m=float(map_obj.clearances(path).min()) if path is not None
            else None,
            distance_m=sim.distance,
            final_position_error_m=math.hypot(x - self.goal_xy[0], y - self.goal_xy[1]),
            min_clearance_m=sim.min_clearance, collisions=sim.collisions, plans=self.plans,
            planning_errors=self.errors, plan_time_ms=self.plan_ms,
            cross_track_mean_m=float(cross.mean()) if cross is not None else None,
            cross_track_max_m=float(cross.max()) if cross is not None else None,
            finish_reason="stopped at the goal" if stopped_time is not None else
            "stalled" if self.stalled else "duration",
            invalid_commands=sim.bad_commands,
            false_localizations=pose_figures["false_localizations"],
            tracking_error_mean_m=pose_figures["tracking_error_mean_m"],
            kidnap=[float(k) for k in kidnap] if kidnap is not None else None,
            stalled=self.stalled, dt=sim.dt, map=map_obj.name, goal_warning=goal_warning,
            trajectory=self.trajectory, path=path.tolist() if path is not None else [],
            collision_points=[[float(px), float(py)] for px, py in sim.collision_points],
            effects=sim.effects.as_dict() if sim.effects else None,
            collisions_with_movers=sim.collisions_with_movers, mover_waits=sim.mover_waits)


__all__ = ["run_navigation_episode", "NavigationResult", "distances_to_polyline",
           "GOAL_TOLERANCE_M"]
