"""Headless episodes: a Simulator and a controller in a loop, with the figures a lab report needs.

    result = run_episode("lab02", "outer", profile="ideal", duration=120.0)
    print(result.collisions, result.laps, result.explored_fraction)
    json.dump(result.to_dict(), open("run.json", "w"))

The controller is any object with `compute_commands(z_scan, z_v, z_w) -> (v, w)`; by default
`amr_control.wall_follower.WallFollower(dt)`. If it has `set_scan_geometry(angle_min,
angle_increment, range_min, range_max)` it is told the scan geometry first, and again whenever
it changes (the LDS-02's changes every scan: profile turtlebot3_lds02).

Timing: with `ideal` the loop is the course's lockstep (measure, compute, step, ...). With
the turtlebot3 profiles it emulates the real robot: the controller still runs every dt, on the
newest scan (a new one only every scan_period, 0.2 s) and on the newest odometry twist
(refreshed every odom_period, 0.05 s).

Metrics:
- explored_fraction: share of the world's free cells (cell_size grid aligned with the map, see
  amr_common.world.coverage_grid; centre clearance > robot radius) whose centre the robot passed
  within cell_size / 2 of.
- laps: full turns of the robot's position around the centroid of the world's free space, from
  the accumulated (unwrapped) winding angle: floor(|winding| / 2 pi). Meaningful for ring-shaped
  routes (lab02 `outer`, corridor_loop); a route that never encircles the centroid gives 0.
- rms_wall_error_m: RMS of the controller's `wall_distance_error` attribute (read after each
  compute_commands; a float while it follows a straight wall, else None); None without samples.
- invalid_commands: commands that were not a pair of finite numbers (NaN, inf, a string ...);
  the simulator stopped the robot for each (amr_sim.Simulator.bad_commands).
A metric that cannot be computed (explored_fraction and laps on a world whose coverage grid
would be too large) is None, with the reason in `metric_errors`; the rest is reported.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from amr_common.geometry import wrap_angles
from amr_common.navigation_behaviour import (
    OdometryHold,
    as_sent_ranges,
    as_sent_scan_geometry,
    limit_command,
)
from amr_common.plugins.link_failure import LinkFailure, checked_commands, class_spec, link_call
from amr_common.plugins.loader import described_parameters
from amr_common.robot import MAX_PLAUSIBLE_ANGULAR_SPEED, MAX_PLAUSIBLE_LINEAR_SPEED
from amr_common.world.coverage_grid import GridTooLargeError
from amr_common.world.movers import collisions_text
from amr_common.world.world import WORLDS_DIR, World
from amr_evaluation.lidar_calibration import calibrate_in_simulation
from amr_mapping.mapper_params import range_error_parameters
from amr_sim.profiles import SensorProfile, get_profile
from amr_sim.simulator import Simulator


@dataclass
class EpisodeResult:
    """What one headless episode did: its setup, metrics and (optionally) trajectory."""

    world: str  # bundled name, or the file path for other worlds
    start: str | list[float]  # start name or [x, y, theta]
    profile: str
    seed: int
    steps: int
    sim_time_s: float
    wall_time_s: float
    collisions: int
    first_collision_time_s: float | None
    min_clearance_m: float
    distance_m: float
    explored_fraction: float | None  # None: not computable, see metric_errors
    laps: int | None
    rms_wall_error_m: float | None
    dt: float = 0.05
    controller: str = ""
    start_pose: list[float] = field(default_factory=list)  # [x, y, theta] actually used
    trajectory: list[list[float]] = field(default_factory=list)  # [[t, x, y, theta], ...]
    collision_points: list[list[float]] = field(default_factory=list)  # [[x, y], ...]
    invalid_commands: int = 0  # commands that were not finite numbers (the robot stopped)
    metric_errors: dict[str, str] = field(default_factory=dict)  # metric -> why it is None
    effects: dict[str, float] | None = None  # the reality-gap effects in use (drawn if randomized)
    collisions_with_movers: int = 0  # the part of `collisions` with the world's movers
    mover_waits: list[list[list[float]]] = field(default_factory=list)  # per mover [t0, t1]s

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable dict (floats, ints, strings, lists, None)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "EpisodeResult":
        """The inverse of to_dict()."""
        return cls(**data)

    def summary(self) -> str:
        """One line with the setup and the metrics, for a terminal."""
        rms = "n/a" if self.rms_wall_error_m is None else f"{self.rms_wall_error_m:.3f} m"
        explored = "n/a" if self.explored_fraction is None else \
            f"{100 * self.explored_fraction:.0f} %"
        laps = "n/a" if self.laps is None else self.laps
        invalid = f", INVALID COMMANDS {self.invalid_commands}" if self.invalid_commands else ""
        return (f"{self.world} / {self.start} / {self.profile}: {self.sim_time_s:.1f} s simulated "
                f"in {self.wall_time_s:.2f} s ({self.steps} steps), collisions "
                f"{collisions_text(self.collisions, self.collisions_with_movers)}, "
                f"min clearance {self.min_clearance_m:.3f} m, distance {self.distance_m:.2f} m, "
                f"explored {explored}, laps {laps}, wall error RMS {rms}{invalid}")


def default_controller(dt: float, profile: SensorProfile | None = None):
    """The project's wall follower, told where the profile's LiDAR sits.

    Imported lazily: it lives in amr_control.
    """
    try:
        from amr_control.wall_follower import WallFollower
    except ImportError as exc:
        raise ImportError("run_episode needs a controller: amr_control.wall_follower.WallFollower "
                          f"is not importable ({exc}); pass controller= or "
                          f"controller_factory=") from exc
    return WallFollower(dt, **(robot_parameters(WallFollower, profile) if profile else {}))


def robot_parameters(controller_class: Any, profile: SensorProfile) -> dict[str, Any]:
    """What the simulated robot fixes for a controller class: its LiDAR's position and timing.

    Only parameters the class lists in `parameter_descriptions()`: `lidar_offset_x_m`, and
    `scan_revolution_s` (the time a scan's rays span when the profile skews its scans, else 0).
    The run scripts apply these unless the user set the parameter (-p or a params file).
    """
    names = described_parameters(controller_class) or {}
    values = {"lidar_offset_x_m": profile.lidar_offset_x,
              "scan_revolution_s": profile.lidar_model.revolution_s
              if scans_skewed(profile) else 0.0}
    return {name: value for name, value in values.items() if name in names}


def ranges_in_error(profile: SensorProfile) -> bool:
    """True if the profile's scanner adds its datasheet's range noise or bias (reality gap)."""
    effects = profile.effects
    return (profile.lidar_model is not None and effects is not None
            and bool(effects.range_noise_share or effects.range_bias_share))


def scans_skewed(profile: SensorProfile) -> bool:
    """True if the profile's scanner takes its rays over a revolution (the real LiDAR's skew)."""
    return (profile.lidar_model is not None and profile.effects is not None
            and bool(profile.effects.scan_skew))


def burger_mapper_limits() -> dict[str, Any]:
    """The Mapper's robot facts for a TurtleBot3 Burger: the fastest its odometry can move.

    Beyond these (3x the Burger's top speeds, amr_common.robot) the odometry is corrupt (the
    Mapper's defaults suit faster robots too). The simulated robot of every profile is a
    Burger, and so is run_robot.py's.
    """
    return {"max_linear_speed_mps": MAX_PLAUSIBLE_LINEAR_SPEED,
            "max_angular_speed_rps": MAX_PLAUSIBLE_ANGULAR_SPEED}


def mapper_parameters(profile: SensorProfile, mapper_class: Any = None,
                      seed: int | None = None) -> dict[str, Any]:
    """What the simulated robot fixes for a mapper: its LiDAR, `deskew`, range error, speeds.

    De-skew only what the simulator skews (the clean profiles' scans are instantaneous,
    though they carry a scan_time); where the simulator adds the datasheet's range error (the
    profiles with the reality gap), the LiDAR model's parameters (mapper_params.
    range_error_parameters) and, with a `seed`, the unit's `range_correction`, calibrated
    against a wall as its owner would (lidar_calibration); 'none' for ideal and the clean ones.
    The Burger's speed limits (burger_mapper_limits).
    `mapper_class`: only the parameters it takes, the LiDAR's position always
    (amr_common.plugins.interfaces.Mapper names it).
    """
    values = {"lidar_offset_x_m": profile.lidar_offset_x, "deskew": scans_skewed(profile),
              "lidar_model": "none", **burger_mapper_limits()}
    if ranges_in_error(profile):
        values.update(range_error_parameters(profile.lidar_model.name))
        if seed is not None:  # the unit calibrated against a wall, as an owner would
            values["range_correction"] = calibrate_in_simulation(profile, seed).as_list()
    takes = described_parameters(mapper_class) if mapper_class is not None else None
    return {name: value for name, value in values.items()
            if takes is None or name in takes or name == "lidar_offset_x_m"}


def filter_parameters(profile: SensorProfile, map_is_world: bool = False,
                      localizer: Any = None) -> dict[str, Any]:
    """What the simulated robot fixes for the particle filter: its LiDAR and how it scans.

    The LiDAR's position; the sensor model (`exact` for the clean profiles, the datasheet's
    LDS-01 or LDS-02 with the reality gap) and whether the scans are skewed (de-skew only
    what the simulator skews); where a map's walls are: on its free cells' edges when the
    simulated world is the filter's own map (map_is_world: the simulator puts them there),
    else inside the occupied cells, as in a real room. The run scripts apply these unless the
    user set them. `localizer` (a class): only those it takes, its LiDAR's position always (a
    user's localizer may know nothing else).
    """
    model = profile.lidar_model
    values = {"lidar_offset_x_m": profile.lidar_offset_x,
              "lidar_model": "exact" if model is None else model.name,
              "deskew": scans_skewed(profile),
              "map_walls": "edges" if map_is_world else "likely"}
    if localizer is None:
        return values
    takes = described_parameters(localizer) or {}
    return {name: value for name, value in values.items()
            if name in takes or name == "lidar_offset_x_m"}


def checked_duration(duration: Any) -> float:
    """An episode's duration in simulated seconds; ValueError unless finite and >= 0."""
    duration = float(duration)
    if not (math.isfinite(duration) and duration >= 0.0):
        raise ValueError(f"duration must be a finite number of seconds >= 0, got {duration}")
    return duration


def episode_start_label(start: Any, world: World, sim: Any) -> str | list[float]:
    """How a result names its start.

    The name given; the world's first start's name when none was given; else the pose the
    simulator started from.
    """
    if isinstance(start, str):
        return start
    if start is None and world.starts:
        return next(iter(world.starts))
    return [float(c) for c in sim.start]


def tell_scan_geometry(target: Any, geometry: tuple, with_rays: bool = False,
                       link: str = "controller") -> None:
    """target.set_scan_geometry(...) with a Simulator.scan_geometry, if target has it.

    Controllers take (angle_min, angle_increment, range_min, range_max); the particle filter
    (with_rays, link "localizer") also the ray count. What it raises is the link's failure
    (amr_common.plugins.link_failure), as in its node; the localizer's ValueError passes through.
    """
    if callable(getattr(target, "set_scan_geometry", None)):
        # As the nodes read it from a LaserScan (float32 fields).
        angle_min, increment, rays, range_min, range_max = as_sent_scan_geometry(*geometry)
        values = (angle_min, increment, rays, range_min, range_max) if with_rays else \
            (angle_min, increment, range_min, range_max)
        link_call(link, "set_scan_geometry", target.set_scan_geometry, *values,
                  allowed=(ValueError,) if with_rays else ())


def commanded(link: str, compute: Callable[..., Any], *args: Any) -> tuple[float, float]:
    """A link's compute_commands(*args) as its node sends it: clipped to the Burger's limits.

    What it raises, or a return that is not two finite numbers, is the link's failure
    (LinkFailure, amr_common.plugins.link_failure): its node commands zero and the run fails.
    """
    return limit_command(*checked_commands(link, link_call(link, "compute_commands", compute,
                                                           *args)))


@contextmanager
def failures_placed(sim: Simulator, links: dict[str, Any]) -> Iterator[None]:
    """A LinkFailure raised inside gets the simulated time and the failing link's class.

    `links`: link name -> the object (its class names it, as the node's parameter does).
    """
    try:
        yield
    except LinkFailure as failure:
        obj = links.get(failure.link)
        raise failure.placed(sim.time, None if obj is None else class_spec(obj)) from failure


def run_episode(world: World | str, start=None, profile: str | SensorProfile = "ideal",
                seed: int = 0, duration: float = 600.0, dt: float = 0.05, controller=None,
                controller_factory: Callable[[float], Any] | None = None,
                record_trajectory: bool = True) -> EpisodeResult:
    """Run a controller in the simulator for `duration` s of simulated time and measure it.

    `controller_factory(dt)` builds the controller (a class such as WallFollower works);
    `controller` passes a ready one. Neither: the default wall follower.
    """
    duration = checked_duration(duration)
    world_obj = world if isinstance(world, World) else World.load(world)
    prof = get_profile(profile)
    sim = Simulator(world_obj, start=start, dt=dt, profile=prof, seed=seed)
    if controller is None:
        controller = controller_factory(sim.dt) if controller_factory is not None else \
            default_controller(sim.dt, prof)
    n_steps = int(round(duration / sim.dt))
    positions = np.empty((n_steps + 1, 2))
    x, y, th = sim.pose
    positions[0] = (x, y)
    trajectory = [[0.0, x, y, th]] if record_trajectory else []
    wall_err_sq, wall_err_n = 0.0, 0
    z_scan, z_v, z_w = sim.measure()
    z_scan = as_sent_ranges(z_scan)  # what the node reads: a LaserScan's float32 ranges
    odometry = OdometryHold(prof.odom_period, z_v, z_w)
    wall_start = time.perf_counter()
    with failures_placed(sim, {"controller": controller}):
        tell_scan_geometry(controller, geometry := sim.scan_geometry)
        for k in range(1, n_steps + 1):
            v, w = commanded("controller", controller.compute_commands, z_scan, *odometry.twist)
            err = getattr(controller, "wall_distance_error", None)
            if isinstance(err, (int, float)) and math.isfinite(err):
                wall_err_sq += float(err) ** 2
                wall_err_n += 1
            z_scan, z_v, z_w = sim.step(v, w)
            z_scan = as_sent_ranges(z_scan)
            if sim.scan_geometry is not geometry:  # the LDS-02: every scan
                tell_scan_geometry(controller, geometry := sim.scan_geometry)
            odometry.update(sim.time, z_v, z_w)
            x, y, th = sim.pose
            positions[k] = (x, y)
            if record_trajectory:
                trajectory.append([sim.time, x, y, th])
    wall_time = time.perf_counter() - wall_start

    bundled_name = world_obj.name if _is_bundled(world_obj) else world_obj.source
    metrics = trajectory_metrics(world_obj, positions)
    return EpisodeResult(
        world=bundled_name, start=episode_start_label(start, world_obj, sim), profile=prof.name,
        seed=int(seed), steps=sim.steps,
        sim_time_s=sim.time, wall_time_s=wall_time, collisions=sim.collisions,
        first_collision_time_s=sim.first_collision_time, min_clearance_m=sim.min_clearance,
        distance_m=sim.distance, explored_fraction=metrics["explored_fraction"],
        laps=metrics["laps"],
        rms_wall_error_m=math.sqrt(wall_err_sq / wall_err_n) if wall_err_n else None,
        dt=sim.dt, controller=type(controller).__module__ + ":" + type(controller).__qualname__,
        start_pose=[float(c) for c in sim.start], trajectory=trajectory,
        collision_points=[[float(px), float(py)] for px, py in sim.collision_points],
        invalid_commands=sim.bad_commands, metric_errors=metrics["metric_errors"],
        effects=sim.effects.as_dict() if sim.effects else None,
        collisions_with_movers=sim.collisions_with_movers, mover_waits=sim.mover_waits)


def explored_fraction(world: World, positions: np.ndarray) -> float:
    """Share of the world's free cells whose centre some position passed within cell_size / 2 of.

    Raises GridTooLargeError if the world's coverage grid would be too large.
    """
    free = world.coverage_grid().free
    total = int(np.count_nonzero(free))
    if total == 0 or len(positions) == 0:
        return 0.0
    visited = world.coverage_grid().visited(positions)
    return int(np.count_nonzero(visited & free)) / total


def trajectory_metrics(world: World, positions: np.ndarray) -> dict[str, Any]:
    """explored_fraction and laps of a trajectory's (K, 2) positions, plus `metric_errors`.

    A metric that cannot be computed is None, with the reason in metric_errors, instead of
    losing the report (the run scripts and run_episode both use this).
    """
    metrics: dict[str, Any] = {"metric_errors": {}}
    for name, compute in (("explored_fraction", explored_fraction), ("laps", count_laps)):
        try:
            metrics[name] = compute(world, positions)
        except (GridTooLargeError, MemoryError) as exc:
            metrics[name] = None
            metrics["metric_errors"][name] = str(exc) or type(exc).__name__
    return metrics


def count_laps(world: World, positions: np.ndarray) -> int:
    """Full turns of the positions around the centroid of the world's free space."""
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    if len(pos) < 2:
        return 0
    cx, cy = world.free_space_centroid()
    bearings = np.arctan2(pos[:, 1] - cy, pos[:, 0] - cx)
    winding = wrap_angles(np.diff(bearings))
    return int(abs(float(np.sum(winding))) // (2.0 * math.pi))


def _is_bundled(world: World) -> bool:
    return Path(world.source).resolve().parent == WORLDS_DIR.resolve()
