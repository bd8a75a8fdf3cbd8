"""Online 2D graph SLAM: scans and odometry in, the robot's pose and an occupancy grid out.

    mapper = Mapper({"lidar_offset_x_m": -0.032})
    estimate = mapper.update(scan, odom_pose, stamp)   # scan: LaserScan-like; odom: (x, y, th)
    mapper.pose, mapper.map_to_odom                    # map frame; map -> odom for /tf
    mapper.occupancy_raster()                          # amr_common.world.map_raster.Raster (/map)
    mapper.statistics()                                # keyframes, loop closures, timings

Each update predicts the pose from the odometry since the last scan (odometry_motion: scans
stamped out of order are mapped too, counted), de-skews the rays with that motion (`deskew`,
amr_common.sensors.scan_deskew) and matches the scan against the local map, a log-odds grid of the
latest keyframes (scan_matcher), over a window the odometry's error model sizes; a match that
is poor or on the window's edge is searched again wider before the pose follows the odometry.
A scan becomes a keyframe after `keyframe_distance_m` or `keyframe_angle_rad`: it joins the
local map (the oldest leaves it, exactly: counts are integers), the global map and the pose
graph. Every few keyframes the loop closer (loop_closure) looks for an earlier keyframe near the
current one, and failing that, near the start, matches against the first keyframes (the heading
anchor); a verified closure goes into the graph, iSAM2 re-solves it, and every keyframe that
moved is redrawn (the local map at once, the global map on the next occupancy_raster()). Every
scan's pose follows its keyframe (trajectory()). The map frame is the odometry frame at the
first scan.

Bad input never raises and never puts a NaN into the pose or the map: a scan that is not a scan
and a non-finite odometry pose or stamp are skipped (counted in `statistics()["rejected"]`,
logged at most every 5 s); a scan with too few usable returns or no trustworthy match moves the
pose by the odometry only; an odometry jump (faster than max_linear_speed_mps or
max_angular_speed_rps) is not trusted: the scan is searched for around the last pose.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from amr_common.geometry import compose, inverse, wrap_angle
from amr_common.python_logging import ThrottledLogger
from amr_common.world.map_raster import Raster
from amr_mapping.log_odds_grid import UNITS, LogOddsGrid
from amr_mapping.loop_closure import LoopCloser, draw
from amr_mapping.mapper_params import check_parameters, parameter_descriptions
from amr_mapping.odometry_motion import OdometryMotion, OdometryStep
from amr_mapping.pose_graph import PoseGraph
from amr_mapping.scan_matcher import CorrelativeMatcher
from amr_mapping.scan_points import ScanError, scan_points
from amr_mapping.scan_smoothing import ranges_filter
from amr_mapping.scan_trajectory import ScanTrajectory
from amr_mapping.timings import clocks, elapsed_ms, timing_summary

_LOG = ThrottledLogger(logging.getLogger(__name__))
_WEAK_LINK = (0.05, 0.05)  # m, rad: sigmas of a keyframe link that no match confirmed
_STALE_FIELD_VERSIONS = 3
_RECENTRE_MARGIN_M = 1.0


@dataclass(frozen=True)
class MappingEstimate:
    """What one update gave: the pose (map frame) at `stamp` and how it was obtained."""

    pose: tuple[float, float, float]
    stamp: float
    status: str  # "matched", "odometry" (no usable match), "first", or "rejected: <why>"
    score: float  # match score (0..1), 0 when not matched
    keyframe: bool
    loop_closed: bool


class Mapper:
    """Online graph SLAM (see the module docstring); parameters: mapper_params.PARAMETERS.

    Implements amr_common.plugins.interfaces.Mapper.
    """

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        self.p = p = check_parameters(params)
        self._occupied_units = p["occupied_log_odds"] * UNITS
        self._ranges_filter = ranges_filter(p)  # calibration and smoothing, or None
        self._global = self._new_grid(hit_moments=False)
        self._local = self._new_grid(hit_moments=True)
        # The local map changes by one keyframe in local_map_keyframes (two grid versions: one
        # drawn, one taken out); its field is rebuilt after two keyframes, not after each.
        self._tracker = CorrelativeMatcher(
            p["resolution_m"], p["smear_sigma_m"],
            use_reference=p["correlative_search"] == "exhaustive",
            stale_versions=_STALE_FIELD_VERSIONS)
        self._closer = LoopCloser(p)
        self._graph = PoseGraph((p["sequential_sigma_m"], p["sequential_sigma_rad"]),
                                (p["loop_sigma_m"], p["loop_sigma_rad"]))
        self._points: list[np.ndarray] = []  # per keyframe, robot frame
        self._travelled: list[float] = []
        self._drawn_global: list[tuple[float, float, float] | None] = []
        self._local_members: dict[int, tuple[float, float, float]] = {}  # keyframe -> drawn pose
        self._trajectory = ScanTrajectory()  # every mapped scan, following the keyframes
        self._pose = (0.0, 0.0, 0.0)
        self._motion = OdometryMotion(p)
        self._distance = 0.0
        self._closure_travelled = 0.0  # travel at the last loop closure (or the start)
        self._since_loop_try = 0
        self._stats: dict[str, Any] = dict.fromkeys((
            "updates", "matched", "odometry_only", "loop_closures", "loop_attempts",
            "bad_scan_time", "anchor_closures", "odometry_jumps", "out_of_order",
            "search_retries", "map_full"), 0) | {"rejected": {}}
        # (wall ms, this thread's CPU ms) of every update, loop-closure attempt and closure
        self._times: dict[str, list[tuple[float, float]]] = {"update": [], "loop": [],
                                                             "loop_closed": []}

    @staticmethod
    def parameter_descriptions() -> dict[str, tuple[Any, str]]:
        """Name -> (default, description) of every parameter."""
        return parameter_descriptions()

    # ------------------------------------------------------------------ inputs
    def update(self, scan: Any, odom_pose, stamp: float) -> MappingEstimate:
        """Take one scan with the odometry pose (odom frame) at its stamp (s); the new estimate."""
        started = clocks()
        try:
            estimate = self._update(scan, odom_pose, stamp)
        finally:
            self._times["update"].append(elapsed_ms(started))
        return estimate

    def _reject(self, reason: str, detail: str, stamp) -> MappingEstimate:
        rejected = self._stats["rejected"]
        rejected[reason] = rejected.get(reason, 0) + 1
        _LOG.warning(reason, "slam: skipping a scan: %s", detail)
        stamp = float(stamp) if isinstance(stamp, (int, float)) else math.nan
        return MappingEstimate(self._pose, stamp, f"rejected: {reason}", 0.0, False, False)

    def _update(self, scan: Any, odom_pose, stamp) -> MappingEstimate:
        try:
            stamp = float(stamp)
            odom = tuple(float(v) for v in odom_pose)
        except (TypeError, ValueError):
            return self._reject("bad_input", f"stamp {stamp!r} or odometry {odom_pose!r} is "
                                "not numeric", stamp)
        if len(odom) != 3 or not all(math.isfinite(v) for v in odom) or \
                not math.isfinite(stamp):
            return self._reject("non_finite", f"stamp {stamp} or odometry pose {odom} is not "
                                "finite", stamp)
        try:
            points, angles = scan_points(scan, self.p["lidar_offset_x_m"], self.p["max_range_m"],
                                         self._ranges_filter)
        except ScanError as exc:
            return self._reject("bad_scan", str(exc), stamp)
        self._stats["updates"] += 1
        step = self._motion.step(odom, stamp)
        if step is None:  # the first scan: the map frame is the odom frame
            self._pose = odom
            self._add_keyframe(points, odom, None, True)
            self._record_scan(stamp)
            return MappingEstimate(odom, stamp, "first", 0.0, True, False)
        if step.out_of_order:
            self._stats["out_of_order"] += 1
            _LOG.warning("out_of_order", "slam: scan stamped %.3f s, at or before the one "
                         "before: mapped with the odometry pose it came with", stamp)
        if step.motion is None:
            self._stats["odometry_jumps"] += 1
            _LOG.warning("jump", "slam: odometry moved %.2f m / %.2f rad in %.2f s: not trusted, "
                         "matching around the last pose",
                         math.hypot(step.measured[0], step.measured[1]), step.measured[2],
                         step.dt)
        points = self._deskewed(scan, points, angles, step)
        predicted = self._pose if step.motion is None else compose(self._pose, step.motion)
        pose, score = self._match(points, predicted, step.motion)
        status = "matched" if score > 0.0 else "odometry"
        self._stats["matched" if score > 0.0 else "odometry_only"] += 1
        self._distance += math.hypot(pose[0] - self._pose[0], pose[1] - self._pose[1])
        self._pose = pose
        keyframe = loop_closed = False
        if self._is_keyframe(pose):
            keyframe = True
            loop_closed = self._add_keyframe(points, odom, pose, score > 0.0)
        self._record_scan(stamp)
        return MappingEstimate(self._pose, stamp, status, score, keyframe, loop_closed)

    def _record_scan(self, stamp: float) -> None:
        self._trajectory.add(stamp, len(self._graph) - 1, self._graph.pose(-1), self._pose)

    def _deskewed(self, scan: Any, points: np.ndarray, angles: np.ndarray,
                  step: OdometryStep) -> np.ndarray:
        """The points moved to the robot's frame at the stamp (`deskew`), or as measured."""
        if not self.p["deskew"]:
            return points
        points, scan_time_ok = self._motion.deskew(scan, points, angles, step)
        if not scan_time_ok:
            self._stats["bad_scan_time"] += 1
            _LOG.warning("bad_scan_time", "slam: scan_time %r is not 0-1 s: scan not "
                         "de-skewed", getattr(scan, "scan_time", None))
        return points

    def _match(self, points: np.ndarray, predicted, motion) -> tuple[tuple, float]:
        """The matched pose and its score, or (predicted, 0.0) without a trustworthy match.

        motion: the odometry's since the last scan (None after a jump: no prior, the widest
        search). The search covers the odometry's error over the motion (OdometryMotion.
        windows); a match that scores too low or lies on the window's edge (the best pose may
        lie beyond) is searched again over twice the window, up to the widest.
        """
        p = self.p
        if len(points) < p["min_points"]:
            return predicted, 0.0
        linear, angular = self._motion.windows(motion)
        if motion is None:
            prior_sigma = refine_sigmas = None
        else:
            sigma_m, sigma_rad = self._motion.sigmas(motion)
            prior_sigma = (max(p["prior_sigma_m"], sigma_m), max(p["prior_sigma_rad"], sigma_rad))
            refine_sigmas = (sigma_m, sigma_rad, p["point_sigma_m"])
        while True:
            result = self._tracker.match(self._local, self._occupied_units, points, predicted,
                                         linear, angular, prior_sigma=prior_sigma,
                                         refine_sigmas=refine_sigmas)
            widest = linear >= p["max_search_linear_m"] and angular >= p["max_search_angular_rad"]
            if result is not None and result.score >= p["min_match_score"] and \
                    (widest or not result.on_edge(predicted, linear, angular)):
                return result.pose, result.score
            if widest:
                return predicted, 0.0
            self._stats["search_retries"] += 1
            linear = min(2.0 * linear, p["max_search_linear_m"])
            angular = min(2.0 * angular, p["max_search_angular_rad"])

    def _is_keyframe(self, pose) -> bool:
        last = self._graph.pose(-1)
        return (math.hypot(pose[0] - last[0], pose[1] - last[1]) >= self.p["keyframe_distance_m"]
                or abs(wrap_angle(pose[2] - last[2])) >= self.p["keyframe_angle_rad"])

    # ------------------------------------------------------------------ keyframes and maps
    def _new_grid(self, hit_moments: bool) -> LogOddsGrid:
        p = self.p
        return LogOddsGrid(p["resolution_m"], p["max_map_cells"], p["log_odds_hit"],
                           p["log_odds_miss"], p["miss_stop_m"], hit_moments=hit_moments)

    def _draw(self, grid: LogOddsGrid, index: int, pose, sign: int = 1) -> None:
        if not draw(grid, pose, self._points[index], self.p["lidar_offset_x_m"], sign):
            self._stats["map_full"] += 1
            _LOG.error("map_full", "slam: the map reached max_map_cells (%d cells): rays beyond "
                       "it are dropped", self.p["max_map_cells"])

    def _add_keyframe(self, points: np.ndarray, odom, pose, matched: bool) -> bool:
        """Insert a keyframe (pose None: the first, at odom); True if a loop was closed."""
        graph = self._graph
        if pose is None:
            index = graph.add_keyframe(odom)
        else:
            link = compose(inverse(graph.pose(-1)), pose)
            index = graph.add_keyframe(pose, link, None if matched else _WEAK_LINK)
        self._points.append(points)
        self._travelled.append(self._distance)
        self._drawn_global.append(None)
        pose = graph.pose(index)
        self._draw(self._local, index, pose)
        self._local_members[index] = pose
        while len(self._local_members) > self.p["local_map_keyframes"]:
            oldest = min(self._local_members)
            self._draw(self._local, oldest, self._local_members.pop(oldest), -1)
        self._recentre_local()
        closed = False
        self._since_loop_try += 1
        if self.p["loop_closure"] and self._since_loop_try >= self.p["loop_interval_keyframes"]:
            self._since_loop_try = 0
            closed = self._try_loop_closure(index)
        return closed

    def _recentre_local(self) -> None:
        """Redraw the local map in a fresh grid once it spans far more than its keyframes.

        Taking old keyframes out leaves their cells at zero but the array as large: without
        this the local map would grow with everything explored, as the global map does.
        """
        poses = np.array(list(self._local_members.values()))
        reach = self.p["max_range_m"] + 2 * _RECENTRE_MARGIN_M
        width = np.ptp(poses[:, 0]) + 2 * reach
        height = np.ptp(poses[:, 1]) + 2 * reach
        if self._local.counts.size * self.p["resolution_m"] ** 2 <= 4.0 * width * height:
            return
        self._local = self._new_grid(hit_moments=True)
        for member, drawn in self._local_members.items():
            self._draw(self._local, member, drawn)

    def _try_loop_closure(self, index: int) -> bool:
        started = clocks()
        self._stats["loop_attempts"] += 1
        poses = self._graph.poses
        travelled = np.asarray(self._travelled)
        closure = self._closer.close(poses, travelled, self._points, index,
                                     travelled[index] - self._closure_travelled)
        if closure is None:
            closure = self._closer.anchor(poses, self._points, index)
            self._stats["anchor_closures"] += closure is not None
        if closure is not None:
            self._graph.add_loop(closure.earlier, closure.later, closure.relative)
            self._stats["loop_closures"] += 1
            self._closure_travelled = travelled[index]
            poses = self._graph.poses
            for member, drawn in list(self._local_members.items()):
                new = tuple(poses[member])
                if self._moved(drawn, new):
                    self._draw(self._local, member, drawn, -1)
                    self._draw(self._local, member, new)
                    self._local_members[member] = new
            self._pose = tuple(poses[index])
        self._times["loop"].append(elapsed_ms(started))
        if closure is not None:
            self._times["loop_closed"].append(self._times["loop"][-1])
        return closure is not None

    def _moved(self, drawn, new) -> bool:
        return (math.hypot(new[0] - drawn[0], new[1] - drawn[1]) > self.p["rerender_tolerance_m"]
                or abs(wrap_angle(new[2] - drawn[2])) > self.p["rerender_tolerance_rad"])

    def _refresh_global(self) -> None:
        """Draw new keyframes and redraw moved ones in the global map."""
        poses = self._graph.poses
        moved = [k for k, drawn in enumerate(self._drawn_global)
                 if drawn is not None and self._moved(drawn, tuple(poses[k]))]
        if len(moved) > len(poses) // 2:
            self._global.clear()
            self._drawn_global = [None] * len(poses)
        else:
            for k in moved:
                self._draw(self._global, k, self._drawn_global[k], -1)
                self._drawn_global[k] = None
        for k, drawn in enumerate(self._drawn_global):
            if drawn is None:
                pose = tuple(poses[k])
                self._draw(self._global, k, pose)
                self._drawn_global[k] = pose

    # ------------------------------------------------------------------ outputs
    @property
    def lidar_offset_x_m(self) -> float:
        """Where the LiDAR sits ahead of the robot centre (m)."""
        return float(self.p["lidar_offset_x_m"])

    @property
    def max_range_m(self) -> float:
        """Readings beyond this are not mapped (m)."""
        return float(self.p["max_range_m"])

    @property
    def pose(self) -> tuple[float, float, float]:
        """The latest pose estimate (x, y, theta) of base_footprint in the map frame."""
        return self._pose

    @property
    def map_to_odom(self) -> tuple[float, float, float]:
        """The map -> odom transform (x, y, yaw) that puts the odometry pose on the estimate."""
        if self._motion.last_odom is None:
            return (0.0, 0.0, 0.0)
        return compose(self._pose, inverse(self._motion.last_odom))

    def keyframe_poses(self) -> np.ndarray:
        """(K, 3) the keyframes' optimized poses [x, y, theta] (map frame)."""
        return self._graph.poses

    def trajectory(self) -> np.ndarray:
        """(N, 4) rows [stamp, x, y, theta] of every mapped scan, in the order given.

        Each scan's pose relative to the keyframe it was placed from, on that keyframe's
        optimized pose (scan_trajectory): the trajectory as the pose graph now has it.
        """
        return self._trajectory.rows(self._graph.poses)

    def occupancy_raster(self) -> Raster:
        """The map so far (FREE 0 / OCCUPIED 100 / UNKNOWN -1) at the optimized poses."""
        self._refresh_global()
        return self._global.raster(self.p["occupied_log_odds"], self.p["free_log_odds"],
                                   self.p["occupied_min_hit_share"],
                                   max(1, round(self.p["occupied_peak_radius_m"]
                                                / self.p["resolution_m"])),
                                   self.p["occupied_min_hits"])

    def statistics(self) -> dict[str, Any]:
        """Counts (updates, keyframes, loop closures, rejected scans by reason ...) and timings.

        loop_closures counts the heading anchor's closures too (anchor_closures of them).
        Timings (ms: count, median, p90, max, total): update_ms of every update (loop
        closures included), loop_ms of every loop-closure attempt (search, and for a closure
        the optimization and the local map's redraw), loop_closed_ms of the closures alone;
        each in wall-clock time and, as *_cpu_ms, in this thread's CPU time (steadier when
        other programs share the CPUs).
        """
        stats = dict(self._stats, rejected=dict(self._stats["rejected"]))
        stats["keyframes"] = len(self._graph)
        stats["map_cells"] = int(self._global.counts.size)  # as drawn so far
        stats["local_map_cells"] = int(self._local.counts.size)
        stats["distance_m"] = self._distance
        for name, times in self._times.items():
            stats[f"{name}_ms"] = timing_summary([wall for wall, _ in times])
            stats[f"{name}_cpu_ms"] = timing_summary([cpu for _, cpu in times])
        return stats


__all__ = ["Mapper", "MappingEstimate"]
