"""Headless mapping episodes: the simulator, the wall follower exploring, and the SLAM Mapper.

    result = run_mapping_episode("lab02", profile="turtlebot3_clean", seed=0, duration=300.0)
    print(result.summary())          # trajectory RMSE / max, precision, recall, loop closures

Timing as amr_evaluation.episode: the wall follower runs every dt on the newest scan and the
newest odometry twist; the Mapper gets every NEW scan (5 Hz with the turtlebot3 profiles, every
step with `ideal`) with the odometry pose at that moment (the profile's /odom) and the scan's
stamp. The scan is what the slam node gets from /scan: the scan's own geometry (the LDS-02
changes it every scan) and, for a real scanner, its scan_time (the revolution: the rays were
measured over it before the stamp); the Mapper de-skews only what the simulator skews
(episode.mapper_parameters).

The clean profiles' odometry is exact (it sees only what the wheels did), which would make
SLAM look better than on a robot: `drift` adds the errors of a real Burger's /odom (wheel
radius and gyro scale errors, gyro bias, random walk) to it, seeded by the episode's seed.
The default, AUTO_DRIFT, adds `TYPICAL_DRIFT` to a clean profile and nothing to a profile with
the reality gap (turtlebot3, turtlebot3_lds02): its simulator already drifts its odometry
(wheel radius and track errors, slip, the IMU's heading drift; drawn per seed when
randomized), and adding TYPICAL_DRIFT on top would count a Burger's errors twice.
`drift=None` feeds the simulator's odometry as it is.

Figures (amr_evaluation.mapping_metrics): trajectory RMSE / max against the truth aligned at
the start, map precision and recall at 3 cm, loop closures, SLAM update times, and the speed
(simulated seconds per wall-clock second of the whole loop, simulator and controller included).

The mapper is any amr_common.plugins.interfaces.Mapper (`mapper`: MODULE:CLASS, a class or a ready
object; default amr_mapping.mapper:Mapper), used only through the interface's members: the
update times are measured around its update() calls; keyframes, loop closures and the loop
closures' times come from its statistics() when it reports them (None / NaN otherwise).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from amr_common.geometry import compose, inverse
from amr_common.navigation_behaviour import OdometryHold, ScanNovelty
from amr_common.plugins.link_failure import (
    checked_commands,
    checked_estimate,
    checked_raster,
    checked_statistics,
    link_call,
)
from amr_common.plugins.loader import DEFAULT_MAPPER, described_parameters, link_class
from amr_common.world.map_raster import Raster
from amr_common.world.world import World
from amr_evaluation.episode import (
    default_controller,
    episode_start_label,
    failures_placed,
    mapper_parameters,
)
from amr_evaluation.mapping_metrics import RayHits, mapping_figures, trajectory_errors
from amr_mapping.scan_points import Scan
from amr_sim.profiles import SensorProfile, get_profile
from amr_sim.simulator import Simulator


@dataclass(frozen=True)
class OdometryDrift:
    """Errors added to the simulator's exact odometry, per step of its motion.

    distance_scale: relative error of every distance (a wheel radius off by this share);
    turn_scale: relative error of every turn (gyro scale / track width); gyro_bias_rad_s:
    heading drift per second; noise_m / noise_rad: random walk per sqrt(m) driven.
    """

    distance_scale: float = 0.0
    turn_scale: float = 0.0
    gyro_bias_rad_s: float = 0.0
    noise_m: float = 0.0
    noise_rad: float = 0.0


# A Burger whose wheels are 1 % off, gyro 0.5 % off and drifting 1.7 deg per minute, plus a
# random walk of 5 mm and 0.3 deg per sqrt(m).
TYPICAL_DRIFT = OdometryDrift(distance_scale=0.01, turn_scale=0.005, gyro_bias_rad_s=0.0005,
                              noise_m=0.005, noise_rad=0.005)
AUTO_DRIFT = "auto"  # TYPICAL_DRIFT for a clean profile, none where the simulator drifts


def episode_drift(drift: OdometryDrift | str | None, profile: SensorProfile
                  ) -> OdometryDrift | None:
    """The drift an episode adds: `drift` itself, or for AUTO_DRIFT the profile's due.

    A profile with the reality gap drifts its own odometry (wheel errors, slip, IMU heading):
    nothing is added; a clean profile's exact odometry gets TYPICAL_DRIFT.
    """
    if isinstance(drift, str):
        if drift != AUTO_DRIFT:
            raise ValueError(f"drift must be an OdometryDrift, None or {AUTO_DRIFT!r}, "
                             f"not {drift!r}")
        return None if profile.effects is not None else TYPICAL_DRIFT
    return drift


class DriftingOdometry:
    """The simulator's odometry pose with OdometryDrift's errors integrated on top."""

    def __init__(self, drift: OdometryDrift | None, seed: int) -> None:
        self._drift = drift
        self._rng = np.random.default_rng([int(seed), 19])
        self._exact: tuple[float, float, float] | None = None
        self.pose = (0.0, 0.0, 0.0)

    def step(self, exact: tuple[float, float, float], dt: float) -> tuple[float, float, float]:
        """Advance with the simulator's new odometry pose; returns the drifting pose."""
        if self._exact is None or self._drift is None:
            self._exact = exact
            self.pose = exact if self._drift is None else self.pose
            return self.pose
        d = self._drift
        dx, dy, dth = compose(inverse(self._exact), exact)
        self._exact = exact
        distance = math.hypot(dx, dy)
        root = math.sqrt(distance)
        scale = 1.0 + d.distance_scale + d.noise_m * root * self._rng.standard_normal() / \
            max(distance, 1e-12)
        turn = dth * (1.0 + d.turn_scale) + d.gyro_bias_rad_s * dt + \
            d.noise_rad * root * self._rng.standard_normal()
        self.pose = compose(self.pose, (dx * scale, dy * scale, turn))
        return self.pose


@dataclass
class MappingResult:
    """What one mapping episode produced (JSON-serialisable with to_dict())."""

    world: str
    start: str | list[float]
    profile: str
    seed: int
    loop_closure: bool  # asked of the mapper (False for a mapper without a loop_closure param)
    drift: dict[str, float] | None
    sim_time_s: float
    wall_time_s: float  # the whole loop: simulator, controller, SLAM, truth bookkeeping
    cpu_time_s: float  # the same loop's CPU time (this process): steadier on a busy machine
    slam_wall_time_s: float
    collisions: int
    distance_m: float
    scans: int
    keyframes: int | None  # None: the mapper's statistics() does not report them
    loop_closures: int | None
    trajectory_rmse_m: float
    trajectory_max_m: float
    heading_rmse_rad: float
    odometry_max_error_m: float  # the drifting odometry's worst error: what SLAM corrected
    precision: float
    recall: float
    seen_wall_m: float
    # CPU ms of the mapper's update() calls (this thread), measured by the episode
    update_ms_median: float
    update_ms_p90: float
    update_ms_max: float
    # From statistics()["loop_closed_cpu_ms"] (the reference's closures: search +
    # optimization); NaN for a mapper that does not report it
    loop_closure_ms_median: float
    loop_closure_ms_max: float
    mapper: str = DEFAULT_MAPPER  # MODULE:CLASS of the mapper
    real_time_factor: float = 0.0  # simulated seconds per wall-clock second of the loop
    cpu_real_time_factor: float = 0.0  # ... per CPU second
    statistics: dict[str, Any] = field(default_factory=dict)
    estimate: list[list[float]] = field(default_factory=list)  # [t, x, y, theta] per scan
    # With record: the true pose at each estimate row, [t, x, y, theta], and the map built
    trajectory: list[list[float]] = field(default_factory=list)
    raster: Raster | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable dict (without the map)."""
        data = asdict(replace(self, raster=None))
        del data["raster"]
        return data

    def summary(self) -> str:
        """One line with the setup and the figures."""
        closure = "on" if self.loop_closure else "off"
        return (f"{self.world} seed {self.seed} loop closure {closure}: RMSE "
                f"{100 * self.trajectory_rmse_m:.2f} cm, max "
                f"{100 * self.trajectory_max_m:.2f} cm (odometry max "
                f"{100 * self.odometry_max_error_m:.1f} cm), precision "
                f"{100 * self.precision:.1f} %, recall {100 * self.recall:.1f} %, "
                f"{_count(self.loop_closures)} loop closures, {_count(self.keyframes)} "
                f"keyframes, update median "
                f"{self.update_ms_median:.2f} ms, {self.real_time_factor:.0f}x real time "
                f"({self.cpu_real_time_factor:.0f}x per CPU second)")


def run_mapping_episode(world: World | str, start=None,
                        profile: str | SensorProfile = "turtlebot3_clean", seed: int = 0,
                        duration: float = 300.0, dt: float = 0.05, loop_closure: bool = True,
                        drift: OdometryDrift | str | None = AUTO_DRIFT,
                        mapper_params: dict[str, Any] | None = None,
                        record: bool = False, mapper=None, controller=None,
                        world_frame: bool = False) -> MappingResult:
    """Explore `world` with the wall follower for `duration` s while the mapper maps it.

    record: the result also carries the SLAM poses, the true ones and the map (_recorded).
    mapper: the mapper's class as "MODULE:CLASS" or a class (amr_common.plugins.interfaces.Mapper;
    None: amr_mapping.mapper:Mapper), built with the profile's LiDAR offset, `loop_closure`
    (if the class has that parameter) and `mapper_params`; or a ready object with the
    interface's members.
    controller: the explorer (compute_commands(z_scan, z_v, z_w)); by default the project's
    wall follower told where the profile's LiDAR sits.
    world_frame: build the map in the world's frame (the Mapper's odometry moved by the start
    pose, as the slam node's map_start_pose does in run_sim.py --slam), so the map lies on the
    world; by default the map frame is the odometry frame at the start. The figures hold
    either way.
    """
    world_obj = world if isinstance(world, World) else World.load(world)
    prof = get_profile(profile)
    sim = Simulator(world_obj, start=start, dt=dt, profile=prof, seed=seed)
    if controller is None:
        controller = default_controller(sim.dt, prof)
    if callable(getattr(controller, "set_scan_geometry", None)):
        controller.set_scan_geometry(prof.angle_min, prof.angle_increment, prof.range_min,
                                     prof.range_max)
    mapper, closure = _built_mapper(mapper, prof, loop_closure, seed, mapper_params)
    drift = episode_drift(drift, prof)
    odometry = DriftingOdometry(drift, seed)
    hits = RayHits(world_obj, prof.angle_min, prof.angle_increment, prof.scan_rays,
                   prof.range_min, min(prof.range_max, mapper.max_range_m))
    frame = sim.start if world_frame else (0.0, 0.0, 0.0)
    with failures_placed(sim, {"controller": controller, "mapper": mapper}):
        run = _explore(sim, controller, mapper, odometry, hits, duration, frame)
        raster, stats = _map_and_statistics(mapper)
    rows = np.asarray(run.estimate, dtype=np.float64).reshape(-1, 4)
    # The map frame in the world: the start pose, or the world's own frame.
    origin = (0.0, 0.0, 0.0) if world_frame else sim.start
    figures = mapping_figures(world_obj, origin, np.asarray(run.truth), rows[:, 1:], raster,
                              hits)
    odom_errors = trajectory_errors(sim.start, np.asarray(run.truth), np.asarray(run.odometry))
    start_label = episode_start_label(start, world_obj, sim)
    return MappingResult(
        world=world_obj.name, start=start_label, profile=prof.name, seed=int(seed),
        loop_closure=closure, mapper=_spec_of(mapper),
        drift=None if drift is None else asdict(drift),
        sim_time_s=sim.time, wall_time_s=run.wall_time, cpu_time_s=run.cpu_time,
        slam_wall_time_s=run.slam_time,
        collisions=sim.collisions, distance_m=sim.distance, scans=len(rows),
        keyframes=stats.get("keyframes"), loop_closures=stats.get("loop_closures"),
        odometry_max_error_m=odom_errors["trajectory_max_m"], **figures,
        **_timings(run.update_cpu_ms, stats), statistics=stats,
        real_time_factor=sim.time / run.wall_time if run.wall_time > 0 else math.inf,
        cpu_real_time_factor=sim.time / run.cpu_time if run.cpu_time > 0 else math.inf,
        **(_recorded(rows, run.truth, raster) if record else {}))


def _recorded(rows: np.ndarray, truth: list, raster: Raster) -> dict[str, Any]:
    """What record adds to a MappingResult: estimate, trajectory and raster.

    estimate: [t, x, y, theta] of the SLAM pose per mapped scan; trajectory: the true pose at
    each of their stamps; raster: the map built.
    """
    return {"estimate": rows.tolist(), "raster": raster,
            "trajectory": [[float(t), *map(float, pose)] for t, pose in zip(rows[:, 0], truth)]}


def _map_and_statistics(mapper: Any) -> tuple[Any, dict[str, Any]]:
    """The mapper's occupancy_raster() and statistics(), checked as the slam node checks them.

    What it raises or returns that the Mapper interface forbids: LinkFailure.
    """
    raster = link_call("mapper", "occupancy_raster",
                       lambda: checked_raster(mapper.occupancy_raster()))
    stats = link_call("mapper", "statistics", lambda: checked_statistics(mapper.statistics()))
    return raster, dict(stats)


def _count(value: int | None) -> str:
    """A count for a summary line: 'n/a' when the mapper does not report it."""
    return "n/a" if value is None else str(value)


def _built_mapper(mapper, prof: SensorProfile, loop_closure: bool, seed: int,
                  mapper_params: dict[str, Any] | None) -> tuple[Any, bool]:
    """(the mapper, whether loop closure was asked of it) for run_mapping_episode's `mapper`."""
    params = dict(mapper_params or {})
    if mapper is not None and not isinstance(mapper, (str, type)):  # a ready one
        return mapper, bool(params.get("loop_closure", loop_closure))
    cls = link_class(mapper or DEFAULT_MAPPER, "mapper")
    takes = described_parameters(cls)
    values: dict[str, Any] = mapper_parameters(prof, cls, seed)
    if takes is None or "loop_closure" in takes:
        values["loop_closure"] = bool(loop_closure)
    values.update(params)
    return cls(values), bool(values.get("loop_closure", False))


def _spec_of(mapper: Any) -> str:
    """MODULE:CLASS of a mapper object."""
    cls = type(mapper)
    return f"{cls.__module__}:{cls.__qualname__}"


def _timings(update_cpu_ms: list[float], stats: dict[str, Any]) -> dict[str, float]:
    """MappingResult's update_ms_* (the episode's measures) and loop_closure_ms_* (statistics).

    Updates: median, p90 and max (0.0 for none); closures NaN unless the mapper reports them.
    """
    array = np.asarray(update_cpu_ms if update_cpu_ms else [0.0])
    closed = stats.get("loop_closed_cpu_ms") or {}
    return {"update_ms_median": float(np.median(array)),
            "update_ms_p90": float(np.percentile(array, 90)),
            "update_ms_max": float(array.max()),
            "loop_closure_ms_median": float(closed.get("median", math.nan)),
            "loop_closure_ms_max": float(closed.get("max", math.nan))}


@dataclass
class _Recording:
    """Per accepted scan: the true pose, [stamp, x, y, theta] of the estimate, the odometry."""

    truth: list = field(default_factory=list)
    estimate: list = field(default_factory=list)
    odometry: list = field(default_factory=list)
    slam_time: float = 0.0  # wall seconds inside Mapper.update
    update_cpu_ms: list = field(default_factory=list)  # this thread's CPU ms of each update
    wall_time: float = 0.0
    cpu_time: float = 0.0


def _explore(sim: Simulator, controller, mapper, odometry: DriftingOdometry, hits: RayHits,
             duration: float, frame=(0.0, 0.0, 0.0)) -> _Recording:
    """The episode's loop: control every dt, the newest odometry, every new scan mapped.

    The Mapper gets the odometry moved by `frame` (the map's pose of the odometry frame).
    """
    prof = sim.profile
    run = _Recording()
    n_steps = int(round(float(duration) / sim.dt))
    z_scan, z_v, z_w = sim.measure()
    held = OdometryHold(prof.odom_period, z_v, z_w, odometry.step(sim.odometry_pose, sim.dt))
    novelty = ScanNovelty()  # a new scan as the slam node counts it (skip_repeated_scans)
    novelty.is_new(z_scan, sim.scan_geometry[:2])

    # A real scanner's scan took its revolution (the simulator skews it if the profile says).
    scan_time = prof.lidar_model.revolution_s if prof.lidar_model is not None else 0.0

    def feed(ranges: np.ndarray, stamp: float) -> None:
        angle_min, increment, _, range_min, range_max = sim.scan_geometry  # the LDS-02's change
        scan = Scan(ranges, angle_min, increment, range_min, range_max, scan_time)
        odom = compose(frame, held.held[2])
        started, cpu_started = time.perf_counter(), time.thread_time()
        result = link_call("mapper", "update", lambda: checked_estimate(
            mapper.update(scan, odom, stamp)))
        run.update_cpu_ms.append(1e3 * (time.thread_time() - cpu_started))
        run.slam_time += time.perf_counter() - started
        if not result.status.startswith("rejected"):
            run.truth.append(sim.pose)
            run.estimate.append((stamp, *result.pose))
            run.odometry.append(held.held[2])
            hits.add(*sim.lidar_position, sim.pose[2])

    wall_start, cpu_start = time.perf_counter(), time.process_time()
    feed(z_scan, 0.0)
    for _ in range(n_steps):
        v, w = checked_commands("controller", link_call(
            "controller", "compute_commands", controller.compute_commands, z_scan, *held.twist))
        z_scan, z_v, z_w = sim.step(v, w)
        held.update(sim.time, z_v, z_w, odometry.step(sim.odometry_pose, sim.dt))
        if novelty.is_new(z_scan, sim.scan_geometry[:2]):
            feed(z_scan, sim.scan_time)
    run.wall_time = time.perf_counter() - wall_start
    run.cpu_time = time.process_time() - cpu_start
    return run


__all__ = ["AUTO_DRIFT", "DriftingOdometry", "MappingResult", "OdometryDrift", "TYPICAL_DRIFT",
           "episode_drift", "run_mapping_episode"]
