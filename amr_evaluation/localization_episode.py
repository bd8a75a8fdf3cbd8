"""Headless localization episodes: simulator, wall follower and particle filter.

Headless localization episodes: Simulator + wall follower + ParticleFilter, the same classes
as the ROS nodes, with the figures that say whether the filter can be trusted.

    result = run_localization_episode("lab02", "outer", profile="turtlebot3", seed=3,
                                      duration=60.0, kidnap=(30.0, 0.6, -0.6, 3 * pi / 2))
    print(result.time_to_localized_s, result.false_localizations, result.tracking_error_mean_m)

Timing as amr_evaluation.episode: `ideal` is the course's lockstep (a new scan every step);
the turtlebot3 profiles run the controller and the filter every dt on the newest odometry
twist. The filter is fed as its node feeds it (navigation_episode.ParticleFilterPose: a scan
is new when its readings differ from the previous one's), so the run is the ROS lockstep graph's
(tests/test_headless_is_the_ros_graph.py). The wall follower keeps exploring once localized
(stop_when_localized false, as in run_sim.py --localize); with stop_when_localized true it
commands zero from then on (no planner here).

Metrics (errors of the estimate against the true pose, every step):
- time_to_localized_s / distance_to_localized_m: first step with localized true.
- false_localizations: times the flag was true while the error exceeded 10 cm or 10 degrees
  (each run of such steps counts once), outside the window right after a kidnapping where the
  truth jumped and the filter has not yet seen it (up to the loss report, at most 2 s);
  false_localized_s: the simulated time spent so.
- tracking_error_*: position error while localized (mean, p95, max, m), heading p95 (deg).
- relocalization_times_s: each later false -> true transition.
- kidnap: loss_reported_after_s (first localized false after it) and relocalized_after_s.

`map` (default the world): the map the filter uses while the simulator drives in the world
(amr_common.world.map_vs_world): the metrics above then say what an unmapped box, a moved wall or a
SLAM map does to localization - against the truth, so a confident wrong pose counts as false.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from amr_common.geometry import wrap_angles
from amr_common.navigation_behaviour import (
    Handover,
    KidnapSchedule,
    OdometryHold,
    as_sent_ranges,
)
from amr_common.plugins.loader import DEFAULT_LOCALIZER
from amr_common.world.map_vs_world import load_map
from amr_common.world.world import World
from amr_evaluation.episode import (
    commanded,
    default_controller,
    episode_start_label,
    failures_placed,
    tell_scan_geometry,
)
from amr_evaluation.pose_sources import ParticleFilterPose
from amr_sim.profiles import SensorProfile, get_profile
from amr_sim.simulator import Simulator

FALSE_POSITION_M = 0.10
FALSE_HEADING_RAD = math.radians(10.0)
KIDNAP_GRACE_S = 2.0  # the loss must be reported within this; meanwhile the flag may be stale


@dataclass
class LocalizationResult:
    """What one localization episode produced (JSON-serialisable with to_dict())."""

    world: str
    start: str | list[float]
    profile: str
    seed: int
    steps: int
    sim_time_s: float
    wall_time_s: float
    filter_wall_time_s: float
    map: str  # the name of the map the filter used (the world's by default)
    collisions: int
    distance_m: float
    time_to_localized_s: float | None
    distance_to_localized_m: float | None
    false_localizations: int
    false_localized_s: float
    localized_share: float  # of the time after the first localization
    tracking_error_mean_m: float | None
    tracking_error_p95_m: float | None
    tracking_error_max_m: float | None
    heading_error_p95_deg: float | None
    relocalization_times_s: list[float] = field(default_factory=list)
    global_searches: int = 1
    particles_max: int = 0
    particles_final: int = 0
    kidnap: list[float] | None = None  # [t, x, y, theta]
    loss_reported_after_s: float | None = None
    relocalized_after_s: float | None = None
    start_pose: list[float] = field(default_factory=list)
    trajectory: list[list[float]] = field(default_factory=list)  # [t, x, y, theta]
    estimate: list[list[float]] = field(default_factory=list)  # [t, x, y, theta, localized]
    particles_snapshot: list[list[float]] = field(default_factory=list)  # [x, y, theta]
    effects: dict[str, float] | None = None  # the reality-gap effects in use (drawn if randomized)
    collisions_with_movers: int = 0  # the part of `collisions` with the world's movers

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable dict."""
        return asdict(self)

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second of the whole loop."""
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def summary(self) -> str:
        """One line for a terminal."""
        def fmt(value, unit="", scale=1.0, digits=1):
            return "n/a" if value is None else f"{value * scale:.{digits}f}{unit}"
        kidnap = "" if self.kidnap is None else (
            f", kidnap at {self.kidnap[0]:g} s: loss reported after "
            f"{fmt(self.loss_reported_after_s, ' s', digits=2)}, relocalized after "
            f"{fmt(self.relocalized_after_s, ' s')}")
        to_localized = fmt(self.distance_to_localized_m, " m", digits=2)
        on_map = f" (map {self.map})" if self.map != self.world else ""
        return (f"{self.world}{on_map} / {self.start} / {self.profile} / seed {self.seed}: "
                f"localized "
                f"after {fmt(self.time_to_localized_s, ' s')} ({to_localized}), "
                f"false {self.false_localizations}, error mean "
                f"{fmt(self.tracking_error_mean_m, ' cm', 100)} p95 "
                f"{fmt(self.tracking_error_p95_m, ' cm', 100)} max "
                f"{fmt(self.tracking_error_max_m, ' cm', 100)}, heading p95 "
                f"{fmt(self.heading_error_p95_deg, ' deg')}, relocalizations "
                f"{len(self.relocalization_times_s)}{kidnap}; {self.real_time_factor:.0f}x "
                f"real time")


def run_localization_episode(world: World | str, start=None,
                             profile: str | SensorProfile = "ideal", seed: int = 0,
                             duration: float = 60.0, dt: float = 0.05,
                             kidnap: tuple[float, float, float, float] | None = None,
                             filter_params: dict[str, Any] | None = None, controller=None,
                             stop_when_localized: bool = False, record: bool = True,
                             map: World | str | None = None,
                             localizer: str | type = DEFAULT_LOCALIZER) -> LocalizationResult:
    """Run the wall follower with the particle filter for `duration` simulated seconds.

    kidnap (t, x, y, theta): teleport the robot at simulated time t (Simulator.teleport).
    localizer: the class (or its MODULE:CLASS) of amr_common.plugins.interfaces.Localizer, default
    the ParticleFilter. filter_params: its parameters (seed defaults to the episode's; the LiDAR's
    position, lidar_model, deskew and map_walls to the profile's: episode.filter_parameters,
    those the class takes). map: the filter's map (None: the world; see the module docstring).
    """
    world_obj = world if isinstance(world, World) else World.load(world)
    map_obj = load_map(map, world_obj)
    prof = get_profile(profile)
    sim = Simulator(world_obj, start=start, dt=dt, profile=prof, seed=seed)
    if controller is None:
        controller = default_controller(sim.dt, prof)
    tell_scan_geometry(controller, sim.scan_geometry)
    source = ParticleFilterPose(map_obj, sim, seed, localizer, **(filter_params or {}))
    with failures_placed(sim, {"controller": controller, "localizer": source.filter}):
        series, costs = _run_steps(sim, source, controller,
                                   int(round(float(duration) / sim.dt)), kidnap,
                                   stop_when_localized, record)
    return _result(sim, source.filter, seed, world_obj.name, map_obj.name,
                   episode_start_label(start, world_obj, sim), kidnap, record,
                   series, costs)


def _run_steps(sim: Simulator, source: ParticleFilterPose, controller: Any, n_steps: int,
               kidnap, stop_when_localized: bool, record: bool) -> tuple[tuple, tuple]:
    """The episode's steps, as the nodes take them.

    ((truth, estimate, distances, particles snapshot), (wall time, the filter's wall time, the
    most particles)).
    """
    pf = source.filter
    geometry = sim.scan_geometry
    # (t, x, y, theta) true and (t, x, y, theta, localized) estimated per step; distance driven
    truth, estimate, distances = (np.empty((n_steps + 1, 4)), np.empty((n_steps + 1, 5)),
                                  np.zeros(n_steps + 1))
    truth[0] = (0.0, *sim.pose)
    particles_max = len(pf.particles)
    snapshot: list[list[float]] = []
    # The rules the nodes follow (amr_common.navigation_behaviour); the filter is fed as its
    # node feeds it (ParticleFilterPose), the wall follower computes on every measurement.
    handover = Handover()
    kidnapping = KidnapSchedule(kidnap)
    z_scan, z_v, z_w = sim.measure()
    z_scan = as_sent_ranges(z_scan)
    odometry = OdometryHold(sim.profile.odom_period, z_v, z_w)
    started = time.perf_counter()
    estimate[0] = (0.0, *source.update(sim, z_scan, *odometry.twist)[0], float(pf.localized))
    filter_time = time.perf_counter() - started
    wall_start = time.perf_counter()
    for k in range(1, n_steps + 1):
        handover.update(pf.localized)
        v, w = commanded("controller", controller.compute_commands, z_scan, *odometry.twist)
        if stop_when_localized and not handover.explorer_in_charge:
            v, w = 0.0, 0.0
        teleport = kidnapping.due(sim.time)
        if teleport is not None:
            sim.teleport(teleport)
        z_scan, z_v, z_w = sim.step(v, w)
        z_scan = as_sent_ranges(z_scan)
        odometry.update(sim.time, z_v, z_w)
        if sim.scan_geometry is not geometry:  # the LDS-02: every scan
            tell_scan_geometry(controller, geometry := sim.scan_geometry)
        started = time.perf_counter()
        pose, localized = source.update(sim, z_scan, *odometry.twist)  # checked
        filter_time += time.perf_counter() - started
        particles_max = max(particles_max, len(pf.particles))
        truth[k] = (sim.time, *sim.pose)
        estimate[k] = (sim.time, *pose, float(localized))
        distances[k] = sim.distance
        if record and not snapshot and pf.localized:
            snapshot = np.asarray(pf.particles)[::max(1, len(pf.particles) // 500)].tolist()
    wall_time = time.perf_counter() - wall_start
    return (truth, estimate, distances, snapshot), (wall_time, filter_time, particles_max)


def _result(sim: Simulator, pf: Any, seed: int, world_name: str, map_name: str,
            start_label: Any, kidnap, record: bool, series: tuple,
            costs: tuple) -> LocalizationResult:
    """The episode's LocalizationResult.

    series: (truth, estimate, distances, particles snapshot); costs: (wall time, the filter's
    wall time, the most particles).
    """
    truth, estimate, distances, snapshot = series
    wall_time, filter_time, particles_max = costs
    metrics = localization_metrics(truth, estimate, distances, kidnap)
    return LocalizationResult(
        world=world_name, map=map_name, start=start_label, profile=sim.profile.name,
        seed=int(seed), steps=sim.steps, sim_time_s=sim.time, wall_time_s=wall_time,
        filter_wall_time_s=filter_time, collisions=sim.collisions, distance_m=sim.distance,
        global_searches=pf.global_searches, particles_max=particles_max,
        particles_final=len(pf.particles), kidnap=list(kidnap) if kidnap else None,
        start_pose=[float(c) for c in sim.start],
        trajectory=truth.tolist() if record else [],
        estimate=estimate.tolist() if record else [],
        particles_snapshot=snapshot if record else [],
        effects=sim.effects.as_dict() if sim.effects else None,
        collisions_with_movers=sim.collisions_with_movers, **metrics)


def metrics_from_rows(trajectory, estimate, kidnap=None) -> dict[str, Any]:
    """The metrics of the module docstring from a run's rows, as run_sim.py records them.

    trajectory: [t, x, y, theta] of the truth at every simulation step; estimate: [t, x, y,
    theta, localized] at every /pose (t = its stamp; in real time fewer rows than steps). Each
    estimate is compared with the truth at its stamp.
    """
    truth = np.asarray(trajectory, dtype=np.float64).reshape(-1, 4)
    rows = np.asarray(estimate, dtype=np.float64).reshape(-1, 5)
    if len(rows) == 0 or len(truth) == 0:
        return localization_metrics(np.zeros((0, 4)), np.zeros((0, 5)), np.zeros(0), kidnap)
    index = np.clip(np.searchsorted(truth[:, 0], rows[:, 0] - 1e-6), 0, len(truth) - 1)
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(truth[:, 1:3], axis=0).T))])
    at_stamps = truth[index].copy()
    at_stamps[:, 0] = rows[:, 0]
    return localization_metrics(at_stamps, rows, travelled[index], kidnap)


def pose_errors(truth: np.ndarray, estimate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and absolute heading (rad) errors of estimate rows against truth rows."""
    position = np.hypot(estimate[:, 1] - truth[:, 1], estimate[:, 2] - truth[:, 2])
    heading = np.abs(wrap_angles(estimate[:, 3] - truth[:, 3]))
    return position, heading


def localization_metrics(truth: np.ndarray, estimate: np.ndarray, distances: np.ndarray,
                         kidnap=None) -> dict[str, Any]:
    """The metrics of the module docstring from per-step rows.

    Truth [t, x, y, theta], estimate [t, x, y, theta, localized], distance travelled (m).
    """
    t = truth[:, 0]
    if len(t) == 0:
        return {"time_to_localized_s": None, "distance_to_localized_m": None,
                "false_localizations": 0, "false_localized_s": 0.0, "localized_share": 0.0,
                "relocalization_times_s": [], "loss_reported_after_s": None,
                "relocalized_after_s": None, "tracking_error_mean_m": None,
                "tracking_error_p95_m": None, "tracking_error_max_m": None,
                "heading_error_p95_deg": None}
    localized = estimate[:, 4] > 0.5
    position, heading = pose_errors(truth, estimate)
    wrong = (position > FALSE_POSITION_M) | (heading > FALSE_HEADING_RAD)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    excused = np.zeros(len(t), dtype=bool)
    loss_after = relocalized_after = None
    if kidnap is not None:
        after = t >= kidnap[0] - 1e-9
        lost = np.flatnonzero(after & ~localized)
        if lost.size:
            loss_after = float(t[lost[0]] - kidnap[0])
            back = np.flatnonzero(after & localized & (t > t[lost[0]]))
            if back.size:
                relocalized_after = float(t[back[0]] - kidnap[0])
        grace_end = kidnap[0] + (min(loss_after, KIDNAP_GRACE_S) if loss_after is not None
                                 else KIDNAP_GRACE_S)
        excused = after & (t <= grace_end + 1e-9)
    false_steps = localized & wrong & ~excused
    false_runs = int(np.count_nonzero(false_steps[1:] & ~false_steps[:-1]) + false_steps[0])
    durations = np.diff(t, prepend=t[0] - dt)  # rows may be uneven (a real-time /pose)
    first = np.flatnonzero(localized)
    rises = np.flatnonzero(localized[1:] & ~localized[:-1]) + 1
    tracked = localized & ~excused
    result: dict[str, Any] = {
        "time_to_localized_s": float(t[first[0]]) if first.size else None,
        "distance_to_localized_m": float(distances[first[0]]) if first.size else None,
        "false_localizations": false_runs,
        "false_localized_s": float(durations[false_steps].sum()),
        "localized_share": float(np.mean(localized[first[0]:])) if first.size else 0.0,
        "relocalization_times_s": [float(t[i]) for i in rises if first.size and i > first[0]],
        "loss_reported_after_s": loss_after,
        "relocalized_after_s": relocalized_after,
        "tracking_error_mean_m": None, "tracking_error_p95_m": None,
        "tracking_error_max_m": None, "heading_error_p95_deg": None,
    }
    if tracked.any():
        result.update({
            "tracking_error_mean_m": float(position[tracked].mean()),
            "tracking_error_p95_m": float(np.percentile(position[tracked], 95)),
            "tracking_error_max_m": float(position[tracked].max()),
            "heading_error_p95_deg": float(np.degrees(np.percentile(heading[tracked], 95))),
        })
    return result
