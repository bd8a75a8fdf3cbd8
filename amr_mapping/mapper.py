"""Online 2D graph SLAM: scans and odometry in, the robot's pose and an occupancy grid out.

    mapper = Mapper({"lidar_offset_x_m": -0.032})
    estimate = mapper.update(scan, odom_pose, stamp)   # scan: LaserScan-like; odom: (x, y, th)
    mapper.pose, mapper.map_to_odom                    # map frame; map -> odom for /tf
    mapper.occupancy_raster()                          # amr_common.world.map_raster.Raster (/map)
    mapper.statistics()                                # keyframes, loop closures, timings

Each update predicts the pose from the odometry since the last one (the motion prior), moves
each ray to the robot's pose at the stamp with that odometry (`deskew`: a real LiDAR measures
its rays over the scan's scan_time before the stamp; amr_common.sensors.scan_deskew, as the
particle filter) and matches the scan against the local map, a log-odds grid of the latest
keyframes (scan_matcher.CorrelativeMatcher). A scan becomes a keyframe after the robot moved
`keyframe_distance_m` or turned `keyframe_angle_rad`: it joins the local map (the oldest leaves
it, exactly: counts are integers), the global map, and the pose graph with a link to the keyframe
before. Every few keyframes the loop closer looks for an earlier keyframe near the current one
(loop_closure.LoopCloser), and failing that, near the start, matches the keyframe against the
map of the first keyframes (its heading anchor); a verified closure goes into the graph, iSAM2
re-solves it, and every keyframe that moved is redrawn: at once in the local map, on the next
occupancy_raster() call in the global map (taken out at its old pose and drawn at its new one,
or all redrawn if most moved). The map frame is the odometry frame at the first scan.

Bad input never raises and never puts a NaN into the pose or the map: a scan that is not a scan,
a non-finite odometry pose or stamp, and a stamp not after the last one are skipped (counted in
`statistics()["rejected"]`, logged at most every 5 s); a scan with too few usable returns or a
poor match moves the pose by the odometry only; an odometry jump (faster than the Burger can
move) is not trusted: the scan is matched around the last pose over the loop-closure window.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from amr_common.geometry import compose, inverse, wrap_angle
from amr_common.python_logging import ThrottledLogger
from amr_common.robot import MAX_PLAUSIBLE_ANGULAR_SPEED, MAX_PLAUSIBLE_LINEAR_SPEED
from amr_common.sensors.lidar_models import revolution_ages
from amr_common.sensors.scan_deskew import MotionHistory, points_now
from amr_common.world.map_raster import Raster
from amr_mapping.log_odds_grid import UNITS, LogOddsGrid
from amr_mapping.loop_closure import LoopCloser, draw
from amr_mapping.mapper_params import check_parameters, parameter_descriptions
from amr_mapping.pose_graph import PoseGraph
from amr_mapping.scan_matcher import CorrelativeMatcher
from amr_mapping.scan_points import ScanError, scan_points, scan_revolution_s
from amr_mapping.scan_smoothing import ranges_filter
from amr_mapping.timings import clocks, elapsed_ms, timing_summary

_LOG = ThrottledLogger(logging.getLogger(__name__))
_JUMP_SLACK = (0.05, 0.1)  # m, rad beyond the plausible motion before odometry counts as a jump
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
        self._odom: list[tuple[float, float, float]] = []  # per keyframe
        self._travelled: list[float] = []
        self._drawn_global: list[tuple[float, float, float] | None] = []
        self._local_members: dict[int, tuple[float, float, float]] = {}  # keyframe -> drawn pose
        self._history = MotionHistory()  # the odometry's motion over the last scans (de-skew)
        self._pose = (0.0, 0.0, 0.0)
        self._last_odom: tuple[float, float, float] | None = None
        self._last_stamp = -math.inf
        self._distance = 0.0
        self._since_loop_try = 0
        self._stats: dict[str, Any] = {"updates": 0, "matched": 0, "odometry_only": 0,
                                       "loop_closures": 0, "loop_attempts": 0, "bad_scan_time": 0,
                                       "anchor_closures": 0,
                                       "odometry_jumps": 0, "map_full": 0, "rejected": {}}
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
        if stamp <= self._last_stamp:
            return self._reject("out_of_order", f"stamp {stamp:.3f} s is not after the last "
                                f"one ({self._last_stamp:.3f} s)", stamp)
        try:
            points, angles = scan_points(scan, self.p["lidar_offset_x_m"], self.p["max_range_m"],
                                         self._ranges_filter)
        except ScanError as exc:
            return self._reject("bad_scan", str(exc), stamp)
        self._stats["updates"] += 1
        dt = stamp - self._last_stamp
        self._last_stamp = stamp
        if self._last_odom is None:  # the first scan: the map frame is the odom frame
            self._last_odom = odom
            self._pose = odom
            self._add_keyframe(points, odom, None, True)
            return MappingEstimate(odom, stamp, "first", 0.0, True, False)
        motion = compose(inverse(self._last_odom), odom)
        self._last_odom = odom
        jump = (math.hypot(motion[0], motion[1]) > MAX_PLAUSIBLE_LINEAR_SPEED * dt + _JUMP_SLACK[0]
                or abs(motion[2]) > MAX_PLAUSIBLE_ANGULAR_SPEED * dt + _JUMP_SLACK[1])
        if jump:
            self._stats["odometry_jumps"] += 1
            _LOG.warning("jump", "slam: odometry moved %.2f m / %.2f rad in %.2f s: not trusted, "
                         "matching around the last pose", math.hypot(motion[0], motion[1]),
                         motion[2], dt)
        points = self._deskewed(scan, points, angles, None if jump else motion, dt)
        predicted = self._pose if jump else compose(self._pose, motion)
        pose, score = self._match(points, predicted, None if jump else motion)
        status = "matched" if score > 0.0 else "odometry"
        self._stats["matched" if score > 0.0 else "odometry_only"] += 1
        self._distance += math.hypot(pose[0] - self._pose[0], pose[1] - self._pose[1])
        self._pose = pose
        keyframe = loop_closed = False
        if self._is_keyframe(pose):
            keyframe = True
            loop_closed = self._add_keyframe(points, odom, pose, score > 0.0)
        return MappingEstimate(self._pose, stamp, status, score, keyframe, loop_closed)

    def _deskewed(self, scan: Any, points: np.ndarray, angles: np.ndarray, motion,
                  dt: float) -> np.ndarray:
        """The points moved to the robot's frame at the stamp (`deskew`), or as measured.

        The rays were measured over the scan's scan_time before the stamp, clockwise
        (lidar_models.revolution_ages); the motion then is the odometry's since the last scan
        (None after a jump: not trusted, the history restarts at rest). A scan_time that is
        not a number, negative or over 1 s: as measured (counted in bad_scan_time, logged).
        """
        if not self.p["deskew"]:
            return points
        if motion is None:
            self._history.clear()
        else:
            self._history.add_motion(motion, dt)
        revolution = scan_revolution_s(scan)
        if revolution is None:
            self._stats["bad_scan_time"] += 1
            _LOG.warning("bad_scan_time", "slam: scan_time %r is not 0-1 s: scan not "
                         "de-skewed", getattr(scan, "scan_time", None))
        if not revolution or len(points) == 0:
            return points
        return points_now(points, revolution_ages(angles, revolution), self._history)

    def _match(self, points: np.ndarray, predicted, motion) -> tuple[tuple, float]:
        """The matched pose and its score, or (predicted, 0.0) without a trustworthy match.

        motion: the odometry's since the last scan (None after a jump: a wide search without
        a prior).
        """
        p = self.p
        if len(points) < p["min_points"]:
            return predicted, 0.0
        if motion is None:
            result = self._tracker.match(self._local, self._occupied_units, points, predicted,
                                         p["loop_window_m"], p["loop_window_rad"])
        else:
            sigmas = (p["odometry_sigma_m"] + p["odometry_sigma_per_m"] *
                      math.hypot(motion[0], motion[1]),
                      p["odometry_sigma_rad"] + p["odometry_sigma_per_rad"] * abs(motion[2]),
                      p["point_sigma_m"])
            result = self._tracker.match(
                self._local, self._occupied_units, points, predicted, p["search_linear_m"],
                p["search_angular_rad"], prior_sigma=(p["prior_sigma_m"], p["prior_sigma_rad"]),
                refine_sigmas=sigmas)
        if result is None or result.score < p["min_match_score"]:
            return predicted, 0.0
        return result.pose, result.score

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
        self._odom.append(odom)
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
        closure = self._closer.close(poses, np.asarray(self._travelled), self._points, index)
        if closure is None:
            closure = self._closer.anchor(poses, self._points, index)
            self._stats["anchor_closures"] += closure is not None
        if closure is not None:
            self._graph.add_loop(closure.earlier, closure.later, closure.relative)
            self._stats["loop_closures"] += 1
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
        if self._last_odom is None:
            return (0.0, 0.0, 0.0)
        return compose(self._pose, inverse(self._last_odom))

    def keyframe_poses(self) -> np.ndarray:
        """(K, 3) the keyframes' optimized poses [x, y, theta] (map frame)."""
        return self._graph.poses

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
