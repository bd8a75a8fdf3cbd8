"""Monte Carlo localization of the Burger in a known World (no ROS).

    pf = ParticleFilter(World.load("lab02"), lidar_offset_x_m=-0.032)
    pf.set_scan_geometry(angle_min=0.0, angle_increment=2 * pi / 360, rays=360,
                         range_min=0.12, range_max=3.5)
    pf.predict(v, w, dt)          # every odometry twist
    pf.correct(ranges, age_s=0.0) # every NEW scan (weighed when the robot moved enough);
                                  # age_s: how long before the last predict() it was stamped
    pf.estimate, pf.localized, pf.covariance

Global localization (uniform over the free space, all headings) is the default; an initial pose
tracks from there. Predict: motion_model. Correct: the scan de-skewed with the odometry of the
last second (scan_deskew; `lidar_model` and `deskew`: range_sensor, which also sizes each
reading's tolerance and sigma), beam model on the expected-range table
(beam_model, expected_ranges, scan_beams; weights flattened while searching: weighting),
low-variance resampling when the effective sample size drops, with a KLD-sized particle count
(resampling). Particles are drawn by particle_sets. The localized flag: localization_check,
with the exhaustive pose search (pose_search) and the rival tracks (ambiguity). The exhaustive
searches (a global search's first scan, the check before declaring) are scored a slice per
correct() call, so none blocks for long on a big map (filter_searches).
On a map world (a Nav2 map, a SLAM map) the expected ranges come from the walls where the map
most likely has them (amr_common.world.map_raster.likely_wall_segments: inside the occupied cells,
not on their free edges), known to half a cell (range_sensor).
"""
from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from amr_common.robot import arc_step
from amr_common.sensors.scan_deskew import MotionHistory
from amr_common.world.world import World
from amr_localization.ambiguity import AmbiguityGuard
from amr_localization.beam_model import BeamModel
from amr_localization.expected_ranges import expected_range_table
from amr_localization.filter_searches import FilterSearches, PendingSearch
from amr_localization.localization_check import (
    CheckSettings,
    LocalizedDecision,
    ScanMatcher,
    dominant_cluster,
)
from amr_localization.motion_model import MotionNoise, sample_motion
from amr_localization.particle_filter_params import (
    PARAMETERS,
    WALL_SLACK_M,
    check_parameters,
    check_world,
    checked_initial_pose,
    filter_walls,
)
from amr_localization.particle_sets import gaussian_poses, sample_free_poses
from amr_localization.pose_search import PoseSearch, refine
from amr_localization.range_sensor import RangeSensor
from amr_localization.resampling import KldResampler, effective_sample_size
from amr_localization.scan_beams import ScanBeams
from amr_localization.scan_input import TakenScan, take_scan
from amr_localization.table_memory import search_stride
from amr_localization.weighting import updated_weights

log = logging.getLogger("amr_localization.particle_filter")


class ParticleFilter(FilterSearches):
    """Particles (N, 3) [x, y, theta] with weights; see the module docstring for the cycle.

    The exhaustive searches and what they decide: FilterSearches (filter_searches).
    Implements amr_common.plugins.interfaces.Localizer.
    """

    # Instance attributes of the Localizer interface (set in __init__ and the filter cycle).
    estimate: tuple[float, float, float]
    covariance: np.ndarray
    particles: np.ndarray
    global_searches: int

    def __init__(self, world: World | str, **params: Any) -> None:
        self.world = world if isinstance(world, World) else World.load(world)
        p = check_parameters(params)
        self.params = p
        self.rng = np.random.default_rng(p["seed"])
        self.plan = check_world(self.world, p)
        if self.plan.reduced:
            log.info("%s: a big map: expected-range table of %s to stay within max_memory_mb "
                     "%g", self.world.source, self.plan.describe(), p["max_memory_mb"])
        # Where the LiDAR sees walls: a map's walls inside its occupied cells (module docstring),
        # or on its free edges for a world the simulator built from this map (map_walls).
        self.walls = filter_walls(self.world, p)
        likely = self.world.raster is not None and p["map_walls"] != "edges"
        self._map_cell = self.world.raster.resolution if likely else None
        self.table = expected_range_table(self.world, self.plan.resolution, self.plan.angles,
                                          segments=self.walls)
        self._robot_ok = self.table.robot_cells(slack=WALL_SLACK_M)
        self.model = BeamModel(self.table, self._robot_ok, p["lidar_offset_x_m"],
                               p["sigma_hit_m"], p["z_random"])
        self.noise = MotionNoise(p["noise_v_per_v"], p["noise_v_per_w"], p["noise_w_per_w"],
                                 p["noise_w_per_v"])
        self.check = LocalizedDecision(CheckSettings(**{
            name: p[name] for name in CheckSettings.__dataclass_fields__}))
        t = self.table
        self.resampler = KldResampler(t.x0, t.y0, t.nx * t.resolution, t.ny * t.resolution,
                                      p["kld_bin_xy_m"], p["kld_bin_theta_rad"],
                                      p["kld_epsilon"], p["kld_z"], p["min_particles"],
                                      p["max_particles"])
        self.matcher: ScanMatcher | None = None
        self.beams: ScanBeams | None = None
        self.sensor: RangeSensor | None = None
        self.history = MotionHistory()
        self._scan: TakenScan | None = None  # the scan of the update under way
        self.search = PoseSearch(self.table, self._robot_ok, p["lidar_offset_x_m"],
                                 stride=search_stride(self.table.resolution))
        self.guard = AmbiguityGuard(p["ambiguity_match_fraction"], p["localize_match_fraction"])
        self.last_alternatives: list = []
        self._last_doubt = -10**9  # total_updates at the last search for a better pose
        self._pending: PendingSearch | None = None  # an exhaustive search in progress
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self.estimate: tuple[float, float, float] = (math.nan, math.nan, math.nan)
        self.covariance = np.full((3, 3), math.nan)
        self.cluster_share = 0.0
        self.match_fraction = 0.0
        self.updates = 0  # measurement updates since the last (re-)initialization
        self.total_updates = 0
        self.global_searches = 0
        self.events: list[tuple[str, int]] = []  # (event, total_updates) for logs and tests
        self._since_update = [math.inf, math.inf, math.inf]  # distance, angle, time
        if p["initial_pose"] is not None:
            self.initialize_pose(p["initial_pose"], p["initial_pose_sigma"])
        else:
            self.initialize_global()

    @staticmethod
    def parameter_descriptions() -> dict[str, Any]:
        """Each parameter: name -> (default, description, rule) (the node declares them)."""
        return dict(PARAMETERS)

    @property
    def map(self) -> World:
        """The World it localizes on."""
        return self.world

    @property
    def lidar_offset_x_m(self) -> float:
        """Where the LiDAR sits ahead of the robot centre (m)."""
        return float(self.params["lidar_offset_x_m"])

    def describe(self) -> str:
        """One line for logs: the start, particles, beams and the expected-range table."""
        t, p = self.table, self.params
        mode = "tracking from initial_pose" if p["initial_pose"] else "global localization"
        return (f"{mode}, {self.particle_count} particles, {p['beams']} beams, expected-range "
                f"table {100 * t.resolution:g} cm x {t.angles} directions, "
                f"{t.nbytes / 1e6:.1f} MB, LiDAR at x = {p['lidar_offset_x_m']} m")

    # --- (re-)initialization ---------------------------------------------------------------
    def initialize_global(self) -> None:
        """Uniform over the free space (clearance >= robot radius), all headings: not localized.

        The particles are re-seeded at the poses that fit the next scan (_seed), once the
        exhaustive search of that scan is done; until then they are only moved by odometry.
        """
        count = self.params["max_particles"]
        self._set_particles(sample_free_poses(self.world, self.table.grid, count, self.rng))
        self._seed_pending = True
        self.global_searches += 1
        self.events.append(("global", self.total_updates))

    def initialize_pose(self, pose, sigma=None) -> tuple[float, float, float]:
        """Re-initialize around a pose: Gaussian particles, not localized.

        Gaussian around pose (x, y, theta) with sigma [sx, sy, stheta] (default
        initial_pose_sigma), each clamped to the map (bounded_sigma): not localized until the
        scans confirm it. Returns the sigma used. ValueError, with the state unchanged, for
        values that are not finite or a pose where the robot cannot be (pose_problem).
        """
        sigma = self.params["initial_pose_sigma"] if sigma is None else sigma
        (x, y, theta), wanted = checked_initial_pose(self.world, pose, sigma)
        used = self.bounded_sigma(wanted)
        if used != wanted:
            log.warning("initial pose sigma %s clamped to the map: %s", _rounded(wanted),
                        _rounded(used))
        self._set_particles(gaussian_poses([(x, y, theta)], used,
                                           self.params["tracking_particles"], self.rng))
        self.estimate = (x, y, math.atan2(math.sin(theta), math.cos(theta)))
        self.events.append(("pose", self.total_updates))
        return used

    def bounded_sigma(self, sigma) -> tuple[float, float, float]:
        """The sigma (sx m, sy m, stheta rad) clamped to the map: its width, its height, pi.

        Wider Gaussians put nearly every particle off the map (a global search does better),
        and their spread only costs memory and time.
        """
        xmin, ymin, xmax, ymax = self.world.bounds
        limits = (xmax - xmin, ymax - ymin, math.pi)
        return tuple(min(float(s), limit) for s, limit in zip(sigma, limits))

    def _set_particles(self, particles: np.ndarray) -> None:
        self._seed_pending = False
        self._pending = None  # a search of another particle set's scan
        self.particles = np.ascontiguousarray(particles, dtype=np.float64)
        self.weights = np.full(len(particles), 1.0 / len(particles))
        self.check.reset()
        self.guard.clear()
        self.updates = 0
        self._since_update = [math.inf, math.inf, math.inf]
        self._estimate_from_cluster()

    def _estimate_from_cluster(self) -> None:
        """Estimate, cluster share and covariance from the particles' dominant cluster."""
        cluster = dominant_cluster(self.particles, self.weights, self.params["cluster_radius_m"],
                                   self.params["cluster_angle_rad"])
        self.estimate, self.cluster_share = cluster.pose, cluster.share
        self.covariance = cluster.covariance

    # --- scan geometry ---------------------------------------------------------------------
    def set_scan_geometry(self, angle_min: float, angle_increment: float, rays: int,
                          range_min: float, range_max: float) -> None:
        """Tell the filter where the scan's rays point and their valid limits.

        Where the scan's rays point (rad, counter-clockwise from angle_min), how many there
        are and the valid range limits (m). Call again whenever they change.
        """
        sensor = RangeSensor.from_parameters(self.params, range_max, self._map_cell)
        sensing_max = sensor.sensing_max(range_max)
        self.beams = ScanBeams.from_geometry(angle_min, angle_increment, rays, range_min,
                                             sensing_max, self.params["beams"],
                                             self.table.angles)
        self.sensor = sensor
        self._pending = None  # a search of a scan of the old geometry (a seed starts again)
        self._scan_geometry = (angle_min, angle_increment, rays, range_min, range_max)
        self.matcher = ScanMatcher(self.walls, angle_min, angle_increment, rays,
                                   range_min, sensing_max, self.params["lidar_offset_x_m"],
                                   allowed=self.robot_can_be_at,
                                   missing_unknown=sensor.missing_is_unknown)

    def set_lidar_offset(self, offset_m: float) -> None:
        """Place the LiDAR `offset_m` metres ahead of the robot centre (behind if negative).

        For a position learnt at run time (the node reads it from /tf_static): the models that
        depend on it are rebuilt; the particles and the expected-range table stay.
        """
        offset_m = float(offset_m)
        if not (math.isfinite(offset_m) and abs(offset_m) <= 1.0):
            raise ValueError(f"LiDAR offset must be within +-1 m of the centre, got {offset_m!r}")
        p = self.params
        if offset_m == p["lidar_offset_x_m"]:
            return
        p["lidar_offset_x_m"] = offset_m
        self.model = BeamModel(self.table, self._robot_ok, offset_m, p["sigma_hit_m"],
                               p["z_random"])
        self.search = PoseSearch(self.table, self._robot_ok, offset_m,
                                 stride=search_stride(self.table.resolution))
        self._pending = None
        if self.matcher is not None:
            self.set_scan_geometry(*self._scan_geometry)

    def robot_can_be_at(self, x: float, y: float) -> bool:
        """True if a particle's centre at (x, y) is where the robot can be.

        That is in the free space, clear of the walls (robot radius, less the grid's slack).
        """
        cell = self.table.cell_index(x, y)
        return cell >= 0 and bool(self._robot_ok[cell])

    # --- the filter cycle ------------------------------------------------------------------
    def predict(self, v: float, w: float, dt: float) -> None:
        """Move every particle by the odometry twist (v m/s, w rad/s) over dt s, with noise."""
        if not (math.isfinite(v) and math.isfinite(w) and math.isfinite(dt)) or dt <= 0.0:
            return
        sample_motion(self.particles, len(self.particles), v, w, dt, self.noise, self.rng)
        self.history.add(v, w, dt)
        # The estimate follows the same twist until the next measurement update.
        x, y, theta = arc_step(*self.estimate, v * dt, w * dt)
        self.estimate = (x, y, math.atan2(math.sin(theta), math.cos(theta)))
        self.guard.predict(v, w, dt)
        if self._pending is not None:
            self._pending.predict(v, w, dt)
        since = self._since_update
        since[0] += abs(v) * dt
        since[1] += abs(w) * dt
        since[2] += dt

    def update_due(self, new_scan: bool = True) -> bool:
        """True when a measurement update is due.

        For a new scan, once the robot moved or turned enough or update_max_interval_s passed since
        the last update; for a scan seen before (held between sensor updates, or a stationary
        robot's identical one) only by time.
        """
        p, (distance, angle, elapsed) = self.params, self._since_update
        if elapsed >= p["update_max_interval_s"]:
            return True
        return new_scan and (distance >= p["update_min_distance_m"]
                             or angle >= p["update_min_angle_rad"])

    def correct(self, ranges: np.ndarray, force: bool = False, new_scan: bool = True,
                age_s: float = 0.0) -> bool:
        """Weigh the particles with a scan, resample, re-check the localized flag.

        Only if update_due(new_scan) or force. age_s: how long before the last predict() the
        scan was stamped (the revolution's end; for de-skewing). Returns True if a measurement
        update happened. Steps: _scan_to_weigh, _weigh, _match_scan, _doubt, _switch_to_rival
        (filter_searches: the searches and rivals), _decide (check, re-seed or resample).
        """
        if self.matcher is None:
            raise RuntimeError("set_scan_geometry() before correct()")
        ranges = np.asarray(ranges, dtype=np.float64)
        if ranges.shape != (self.matcher.rays,):
            raise ValueError(f"scan has {ranges.size} rays, the scan geometry {self.matcher.rays}")
        age_s = float(age_s) if math.isfinite(age_s) else 0.0
        ranges = self._scan_to_weigh(ranges, age_s, force, new_scan)  # filter_searches
        if ranges is None:
            return False
        self._weigh(ranges)
        self._since_update = [0.0, 0.0, 0.0]
        self.updates += 1
        self.total_updates += 1
        self._estimate_from_cluster()
        self._match_scan(ranges)
        self._doubt(ranges)
        if self._switch_to_rival(ranges):
            return True
        self._decide(ranges)
        return True

    def _match_scan(self, ranges: np.ndarray) -> None:
        """match_fraction: how well the estimate explains the scan (scan matcher)."""
        p, tolerance = self.params, self._scan.tolerances
        self.match_fraction = self.matcher.match_fraction(self.estimate, ranges, tolerance)
        if not self.localized and self.cluster_share >= p["cluster_min_share"] and \
                0.9 * p["localize_match_fraction"] <= self.match_fraction \
                < p["localize_match_fraction"]:
            # Borderline: the filter's mean carries the table's 2 cm quantization; the best
            # pose within a couple of cm of it decides whether the cluster explains the scan.
            self.match_fraction = refine(self.estimate, self.matcher, ranges,
                                         tolerance).match_fraction

    def _decide(self, ranges: np.ndarray) -> None:
        """The localized check's step; a lost estimate starts a global search; else resample."""
        event = self.check.update(self.cluster_share, self.match_fraction)
        if event == "candidate":
            event = self._check_ambiguity(ranges)
        if event:
            self.events.append((event, self.total_updates))
        if event in ("lost", "reinit"):
            log.info("%s: scan match %.2f at (%.2f, %.2f, %.2f): global search", event,
                     self.match_fraction, *self.estimate)
            self.initialize_global()
            return
        if effective_sample_size(self.weights) < self.params["resample_ess_fraction"] * \
                len(self.weights):
            self._resample()

    def _take_scan(self, ranges: np.ndarray, age_s: float) -> np.ndarray:
        """Take this scan for the update (scan_input); returns its de-skewed ranges."""
        m = self.matcher
        self._scan = take_scan(ranges, age_s, self.sensor, self.beams, m.angles,
                               (m.range_min, m.range_max), self.history,
                               self.params["lidar_offset_x_m"], self.table.angles)
        m.set_ray_angles(self._scan.angles)
        return self._scan.ranges

    def _weigh(self, ranges: np.ndarray) -> None:
        scores = self.model.scores(self.particles, self._scan.readings(),
                                   self._scan.beams.limits_mm)
        weights = updated_weights(self.weights, scores, None if self.localized
                                  else self.params["search_ess_fraction"])
        if weights is None:  # every particle inside a wall or off the map
            log.info("every particle is in a wall or off the map (an impossible hypothesis): "
                     "global search")
            self.initialize_global()
            return
        self.weights = weights

    def _resample(self) -> None:
        self.particles = self.resampler(self.particles, self.weights, self.rng)
        self.weights = np.full(len(self.particles), 1.0 / len(self.particles))

    # --- results ---------------------------------------------------------------------------
    @property
    def localized(self) -> bool:
        """The trustworthy flag (localization_check): True only after the streak of checks."""
        return self.check.localized

    @property
    def particle_count(self) -> int:
        """Particles now (the adaptive count)."""
        return len(self.particles)


def _rounded(values) -> list:
    return [float(f"{v:.3g}") for v in values]


__all__ = ["ParticleFilter"]
