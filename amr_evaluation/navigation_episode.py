"""Headless navigation episodes: simulator, pose source, planner, pure pursuit, wall follower.

The nodes' lockstep order (the wall follower while not localized), with the figures of
issue 12.

    result = run_navigation_episode("lab02", "outer", goal="inner_far")
    print(result.summary())

Each step, as the nodes do it: the pose source turns the measurement into a pose estimate and a
`localized` flag (the particle filter's /pose). Not localized: the wall follower commands.
Localized: on the first localized step (and again after each loss of localization) the planner
plans from the estimate to the goal, then the pure pursuit commands - a zero command until it has
a path, zero again once it stopped at the path's end. The simulator counts the goal as reached
when the TRUE position is within goal_tolerance while localized (as the course simulator), and
the episode runs on until the pursuit has stopped the robot, so the final position error is
measured where the robot rests.

Pose sources (`pose_source`): "filter" (the particle filter of amr_localization, as the ROS
graph runs it: predicted with every odometry twist, corrected with every new scan), "truth"
(`GroundTruthPose`: the true pose, localized from the start), or any object with
`update(sim, z_scan, z_v, z_w) -> ((x, y, theta), localized)` called once per step with the
newest measurement and odometry twist.

`map` (default the world): the map the pose source and the planner use while the simulator
drives in the world (amr_common.map_vs_world): an unmapped box, a moved wall, a SLAM map. The
goal is checked against the map (the planner's), `goal_warning` says when the world blocks it;
the pursuit still slows near what the scan sees, and every figure is measured in the world.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np

from amr_common.map_vs_world import load_map, resolve_goal_on_map
from amr_common.world import World
from amr_control.pure_pursuit import PurePursuit, scan_clearance, scan_free_ahead
from amr_evaluation.episode import default_controller, filter_parameters, tell_scan_geometry
from amr_planning.planner import Planner, PlanningError
from amr_sim.profiles import get_profile
from amr_sim.simulator import Simulator
from amr_sim.simulator_params import PARAMETERS as SIMULATOR_PARAMETERS

GOAL_TOLERANCE_M = SIMULATOR_PARAMETERS["goal_tolerance"][0]


class GroundTruthPose:
    """The simulator's true pose as the estimate.

    Localized from `localized_after_s` on (the wall follower explores before that), lost again
    during [lost_from_s, lost_until_s).
    """

    def __init__(self, localized_after_s: float = 0.0, lost_from_s: float | None = None,
                 lost_until_s: float | None = None) -> None:
        """Times in simulated seconds."""
        self.localized_after_s = localized_after_s
        self.lost = (lost_from_s, lost_until_s)

    def update(self, sim: Simulator, z_scan, z_v: float, z_w: float):
        """((x, y, theta), localized) for the newest measurement."""
        t = sim.time
        lost = self.lost[0] is not None and self.lost[0] <= t < (self.lost[1] or math.inf)
        return sim.pose, t >= self.localized_after_s - 1e-9 and not lost


class ParticleFilterPose:
    """The particle filter (amr_localization) as the pose source, fed as its node feeds it.

    Every step: predict with the odometry twist over dt; a new scan (the turtlebot3 profile
    refreshes it every 0.2 s) is weighed. The first measurement is weighed at once.
    """

    def __init__(self, world: World, sim: Simulator, seed: int = 0, **filter_params) -> None:
        """A filter on `world` for the profile of `sim` (its LiDAR position and scan)."""
        from amr_localization.particle_filter import ParticleFilter  # the heavy part: lazily
        prof = sim.profile
        params = {"seed": seed, **filter_parameters(prof, world is sim.world), **filter_params}
        self.filter = ParticleFilter(world, **params)
        self._geometry = sim.scan_geometry
        tell_scan_geometry(self.filter, self._geometry, with_rays=True)
        self._scan_time: float | None = None
        self._time = sim.time

    def update(self, sim: Simulator, z_scan, z_v: float, z_w: float):
        """((x, y, theta), localized) after taking in the newest measurement."""
        if sim.time > self._time:
            self.filter.predict(z_v, z_w, sim.time - self._time)
            self._time = sim.time
        if sim.scan_time != self._scan_time:
            if sim.scan_geometry is not self._geometry:  # the LDS-02: every scan
                self._geometry = sim.scan_geometry
                tell_scan_geometry(self.filter, self._geometry, with_rays=True)
            self.filter.correct(z_scan, force=self._scan_time is None,
                                age_s=sim.time - sim.scan_time)
            self._scan_time = sim.scan_time
        return tuple(self.filter.estimate), bool(self.filter.localized)


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
    stopped_time_s: float | None  # the pursuit stopped at the path's end
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
    kidnap: list[float] | None = None  # [t, x, y, theta]
    stalled: bool = False  # localized with zero commands for stall_timeout_s before the goal
    dt: float = 0.05
    map: str = ""  # the name of the map the filter and the planner used (the world's default)
    goal_warning: str | None = None  # the world blocks the goal the map has free
    trajectory: list[list[float]] = field(default_factory=list)  # [[t, x, y, theta], ...]
    path: list[list[float]] = field(default_factory=list)  # the last planned path [[x, y], ...]
    collision_points: list[list[float]] = field(default_factory=list)  # [[x, y], ...]
    effects: dict[str, float] | None = None  # the reality-gap effects in use (drawn if randomized)

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
                f"{100 * self.min_clearance_m:.1f} cm, collisions {self.collisions}, "
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


def make_pose_source(kind: Any, world: World, sim: Simulator, seed: int,
                     filter_params: dict | None = None):
    """The pose source named by `kind` ("truth", "filter") or `kind` itself (an object)."""
    if kind == "truth":
        return GroundTruthPose()
    if kind == "filter":
        return ParticleFilterPose(world, sim, seed, **(filter_params or {}))
    if isinstance(kind, str) or not callable(getattr(kind, "update", None)):
        raise ValueError(f"pose_source must be 'truth', 'filter' or an object with update(), "
                         f"got {kind!r}")
    return kind


def run_navigation_episode(
        world: World | str, start=None, goal=None, profile: str = "ideal", seed: int = 0,
        duration: float = 300.0, dt: float = 0.05, pose_source: Any = "truth",
        filter_params: dict | None = None, kidnap: Sequence[float] | None = None,
        planner: Planner | None = None, planner_params: dict | None = None,
        pursuit_params: dict | None = None, wall_follower: Any = None,
        goal_tolerance: float = GOAL_TOLERANCE_M, stall_timeout_s: float = 30.0,
        record_trajectory: bool = True, map: World | str | None = None) -> NavigationResult:
    """Drive from `start` to `goal` and measure it; see the module docstring.

    start: a name, (x, y, theta) or None (the first start); goal: a name, "x,y", (x, y) or None
    (the map's goal, else the world's). `planner` may be passed prebuilt on the map (its grid
    costs are built once per map). `map`: see the module docstring (None: the world). kidnap
    (t, x, y, theta): the robot is teleported at simulated time t (the filter must notice and
    relocalize). Stalled: localized and commanded zero for stall_timeout_s before reaching the
    goal (the episode then ends) - also when something the map lacks blocks the way.
    """
    duration = float(duration)
    if not (math.isfinite(duration) and duration >= 0.0):
        raise ValueError(f"duration must be a finite number of seconds >= 0, got {duration}")
    world_obj = world if isinstance(world, World) else World.load(world)
    map_obj = load_map(map, world_obj)
    goal_xy, goal_warning = resolve_goal_on_map(goal, map_obj, world_obj)
    prof = get_profile(profile)
    sim = Simulator(world_obj, start=start, dt=dt, profile=prof, seed=seed)
    source_name = pose_source if isinstance(pose_source, str) else type(pose_source).__name__
    pose_source = make_pose_source(pose_source, map_obj, sim, seed, filter_params)
    planner = planner if planner is not None else Planner(map_obj, **(planner_params or {}))
    params = {"lidar_offset_x_m": prof.lidar_offset_x, **(pursuit_params or {})}
    pursuit = PurePursuit(sim.dt, **params)
    radius = pursuit.params["robot_radius_m"]
    if wall_follower is None:
        wall_follower = default_controller(sim.dt, prof)
    geometry = sim.scan_geometry
    tell_scan_geometry(wall_follower, geometry)

    n_steps = int(round(duration / sim.dt))
    trajectory = [[0.0, *sim.pose]] if record_trajectory else []
    events: dict[str, float | None] = {"localized": None, "reached": None, "stopped": None}
    plans, errors, plan_ms, path = 0, [], None, None
    pursued: list[tuple[float, float]] = []  # true positions while the pursuit drives
    was_localized = stalled = False
    idle_steps = 0  # consecutive localized zero commands before the goal
    kidnapped = kidnap is None
    next_odom = 0.0
    z_scan, z_v, z_w = sim.measure()
    held_v, held_w = z_v, z_w
    wall_start = time.perf_counter()
    for _ in range(n_steps):
        estimate, localized = pose_source.update(sim, z_scan, held_v, held_w)
        if localized:
            if events["localized"] is None:
                events["localized"] = sim.time
            if not was_localized:  # first localization or relocalized: (re)plan from here
                plans += 1
                try:
                    plan = planner.plan(estimate[:2], goal_xy)
                    pursuit.set_path(plan.points)
                    path, plan_ms = plan, plan.total_time_s * 1e3
                except PlanningError as exc:
                    errors.append(f"t={sim.time:.2f} s: {exc}")
                    pursuit.clear_path()
            scan = (z_scan, geometry[0], geometry[1], geometry[3], geometry[4],
                    prof.lidar_offset_x, radius)
            v, w = pursuit.compute_commands(*estimate, scan_clearance(*scan),
                                            scan_free_ahead(*scan))
            if pursuit.state in ("track", "rotate"):
                pursued.append(sim.pose[:2])
        else:
            if was_localized:
                pursuit.clear_path()  # the wall follower takes over; replan when relocalized
            v, w = wall_follower.compute_commands(z_scan, held_v, held_w)
        was_localized = localized
        x, y, _ = sim.pose
        if localized and events["reached"] is None and \
                math.hypot(x - goal_xy[0], y - goal_xy[1]) <= goal_tolerance:
            events["reached"] = sim.time
        if localized and pursuit.arrived:
            events["stopped"] = sim.time
            break
        idle_steps = idle_steps + 1 if localized and (v, w) == (0.0, 0.0) else 0
        if idle_steps * sim.dt >= stall_timeout_s:
            stalled = True
            break
        if not kidnapped and sim.time >= kidnap[0] - 1e-9:
            sim.teleport(kidnap[1:])
            kidnapped = True
        z_scan, z_v, z_w = sim.step(v, w)
        if sim.scan_geometry is not geometry:  # the LDS-02: every scan
            geometry = sim.scan_geometry
            tell_scan_geometry(wall_follower, geometry)
        if prof.odom_period is None or sim.time >= next_odom - 1e-9:
            held_v, held_w = z_v, z_w  # the real robot's twist only changes with each /odom
            if prof.odom_period is not None:
                while next_odom <= sim.time + 1e-9:
                    next_odom += prof.odom_period
        if record_trajectory:
            trajectory.append([sim.time, *sim.pose])
    wall_time = time.perf_counter() - wall_start

    x, y, _ = sim.pose
    cross = distances_to_polyline(np.array(pursued), path.points) \
        if pursued and path is not None else None
    start_label = start if isinstance(start, str) else (
        next(iter(world_obj.starts)) if start is None and world_obj.starts
        else [float(c) for c in sim.start])
    return NavigationResult(
        world=world_obj.name, start=start_label, goal=[float(goal_xy[0]), float(goal_xy[1])],
        profile=prof.name, seed=int(seed), pose_source=source_name, steps=sim.steps,
        sim_time_s=sim.time,
        wall_time_s=wall_time,
        real_time_factor=sim.time / wall_time if wall_time > 0 else None,
        localized_time_s=events["localized"], goal_reached_time_s=events["reached"],
        stopped_time_s=events["stopped"],
        path_length_m=path.length_m if path is not None else None,
        path_min_clearance_m=path.min_clearance_m if path is not None else None,
        distance_m=sim.distance,
        final_position_error_m=math.hypot(x - goal_xy[0], y - goal_xy[1]),
        min_clearance_m=sim.min_clearance, collisions=sim.collisions, plans=plans,
        planning_errors=errors, plan_time_ms=plan_ms,
        cross_track_mean_m=float(cross.mean()) if cross is not None else None,
        cross_track_max_m=float(cross.max()) if cross is not None else None,
        finish_reason="stopped at the goal" if events["stopped"] is not None else
        "stalled" if stalled else "duration",
        invalid_commands=sim.bad_commands,
        kidnap=[float(k) for k in kidnap] if kidnap is not None else None, stalled=stalled,
        dt=sim.dt, map=map_obj.name, goal_warning=goal_warning, trajectory=trajectory,
        path=path.points.tolist() if path is not None else [],
        collision_points=[[float(px), float(py)] for px, py in sim.collision_points],
        effects=sim.effects.as_dict() if sim.effects else None)


__all__ = ["run_navigation_episode", "NavigationResult", "GroundTruthPose",
           "ParticleFilterPose", "make_pose_source",
           "distances_to_polyline", "GOAL_TOLERANCE_M"]
