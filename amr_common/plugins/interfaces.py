"""The links of the chain as interfaces: what a class must provide to replace the project's own.

explore -> localize -> plan -> follow -> goal, plus mapping: each link is one typing.Protocol
here, documented like a Nav2 plugin header. The nodes (amr_*_node.py), the headless episodes
(amr_evaluation) and the run scripts use only these members, and load the class by
"MODULE:CLASS" (amr_common.plugins.loader.load_class; `--localizer`, `--planner`,
`--follower`, `--mapper`, `--controller`), so a student's class replaces the project's without
editing anything else. The reference implementations: amr_control.wall_follower.WallFollower,
amr_localization.particle_filter.ParticleFilter, amr_planning.planner.Planner,
amr_control.pure_pursuit.PurePursuit, amr_mapping.mapper.Mapper; small course-style ones in
examples/.

Conventions for every link: SI units (m, rad, s, m/s, rad/s); poses (x, y, theta) in the map
frame (REP 105; theta counter-clockwise from +x, any range); scans as sensor_msgs/LaserScan
ranges (NaN, inf, 0.0 or outside [range_min, range_max] mean "no return": use
amr_common.sensors.scan_returns). A class may offer `parameter_descriptions()` (a static method:
name -> (default, description)): its node declares each as a ROS parameter and the run
scripts' `-p` / `--*-param` options check names against it. Constructors are called with
keywords only, as each interface says. A call that raises where its interface allows no
exception, or returns what it forbids (None, NaN where numbers are due, a wrong shape), is the
link's failure (amr_common.plugins.link_failure): its node stops using it and the run fails.
"""
from __future__ import annotations

from typing import Any, Protocol, Sequence, runtime_checkable

import numpy as np

Pose = tuple[float, float, float]


@runtime_checkable
class Controller(Protocol):
    """The wall follower (link "controller"): explores until the robot is localized.

    Built as `cls(dt, **params)`: dt the control period (s); params its tuning values (the
    run scripts pass `lidar_offset_x_m` when the class describes it). Optional members, used
    when present: `set_scan_geometry(angle_min, angle_increment, range_min, range_max)` (called
    before the first command and whenever the scan's geometry changes), `wall_distance_error`
    (m, a float while following a wall: the episodes' RMS figure), `parameter_descriptions()`.
    """

    def compute_commands(self, z_scan: np.ndarray, z_v: float, z_w: float) -> tuple[float, float]:
        """(v m/s, w rad/s) from the newest scan's ranges and the odometry twist.

        Called once per control step (dt) while the robot is not localized. z_scan: ranges in
        m, counter-clockwise from angle_min; z_v, z_w: the measured twist. Must return finite
        numbers (anything else is the controller's failure: the robot stops, the run fails).
        """
        ...


@runtime_checkable
class Localizer(Protocol):
    """Localization on a known map (link "localizer"): odometry and scans in, a pose out.

    Built as `cls(map, seed=..., lidar_offset_x_m=..., **params)`: map an
    amr_common.world.world.World (the walls as segments, `bounds`, `contains(x, y)`, a raster via
    amr_common.world.map_raster); seed for its random numbers; lidar_offset_x_m where the LiDAR
    sits ahead of the robot centre (m); params from `parameter_descriptions()` (ROS parameters of
    the particle_filter node; list seed and lidar_offset_x_m there too: the run scripts set them as
    node parameters). It starts with a global localization (not localized) unless its params give
    an initial pose. Call order: set_scan_geometry() first; then for every odometry twist
    predict(), for every scan correct(); the flag `localized` is read after every scan.
    """

    def set_scan_geometry(self, angle_min: float, angle_increment: float, rays: int,
                          range_min: float, range_max: float) -> None:
        """The scan's geometry, before the first correct() and whenever it changes.

        First ray angle and step (rad, counter-clockwise, LiDAR frame), ray count, valid range
        limits (m). Called before the first correct() and whenever the
        geometry changes (the LDS-02's increment varies per scan).
        """
        ...

    def set_lidar_offset(self, offset_m: float) -> None:
        """Place the LiDAR offset_m ahead of the robot centre (m; from /tf_static at run time).

        ValueError for a non-finite or absurd value (|offset| > 1 m).
        """
        ...

    @property
    def lidar_offset_x_m(self) -> float:
        """Where the localizer believes the LiDAR is (m ahead of the robot centre)."""
        ...

    def predict(self, v: float, w: float, dt: float) -> None:
        """Move the belief by the odometry twist (v m/s, w rad/s) over dt s (> 0).

        Called for every odometry message. Non-finite input or dt <= 0 must be ignored.
        """
        ...

    def correct(self, ranges: np.ndarray, force: bool = False, new_scan: bool = True,
                age_s: float = 0.0) -> bool:
        """Weigh the belief with a scan's ranges (m, the geometry's ray count); True if updated.

        Called for every scan (the lockstep simulator repeats the newest one between sensor
        updates: new_scan False then). force: update even if the robot has not moved.
        age_s: how long before the newest predict() the scan was stamped (s, >= 0; a
        localizer may use it to de-skew the scan, or ignore it). ValueError for a scan of the
        wrong length.
        """
        ...

    def initialize_pose(self, pose: Sequence[float],
                        sigma: Sequence[float] | None = None) -> Sequence[float]:
        """Restart around pose (x, y, theta) with spread sigma (m, m, rad; None: its default).

        Not localized until the scans confirm it (/initialpose). Returns the sigma used;
        ValueError (state unchanged) for a non-finite pose or one where the robot cannot be.
        """
        ...

    def initialize_global(self) -> None:
        """Restart a global localization: anywhere on the map, any heading, not localized."""
        ...

    @property
    def map(self) -> Any:
        """The World it localizes on."""
        ...

    @property
    def estimate(self) -> Pose:
        """The pose estimate (x m, y m, theta rad), map frame; NaN while it has none."""
        ...

    @property
    def covariance(self) -> np.ndarray:
        """3 x 3 covariance of (x, y, theta) (m^2, rad^2) for /amcl_pose; NaN if unknown."""
        ...

    @property
    def localized(self) -> bool:
        """True only when the estimate can be trusted: the planner and the pursuit then drive.

        A wrong pose declared localized is the worst failure (false localization).
        """
        ...

    @property
    def particles(self) -> np.ndarray:
        """(N, 3) hypotheses [x, y, theta] for /particles and plots ((0, 3) if it has none)."""
        ...

    @property
    def global_searches(self) -> int:
        """How many global localizations it has started (the first one included)."""
        ...

    def describe(self) -> str:
        """One line for the node's configure log (what it built, its main settings)."""
        ...


@runtime_checkable
class PlannedPath(Protocol):
    """What Planner.plan returns."""

    @property
    def points(self) -> np.ndarray:
        """(K, 2) path from the start to the goal, metres, map frame (K >= 1)."""
        ...


@runtime_checkable
class Planner(Protocol):
    """A global planner on the map (link "planner"), as a Nav2 planner plugin.

    Built as `cls(map, **params)`: map an amr_common.world.world.World
    (amr_common.world.occupancy_grid gives a grid with each cell's distance to the nearest wall);
    params from `parameter_descriptions()` (ROS parameters of the planner node). Called once on the
    first localized pose, again on a new goal and after each relocalization.
    """

    def plan(self, start: Sequence[float], goal: Sequence[float]) -> PlannedPath:
        """A path from start (x, y) to goal (x, y), metres, map frame.

        Raises ValueError (amr_planning.planner.PlanningError is one) with a message naming the
        problem when there is none: a point outside the map, in or too close to a wall,
        unreachable. The caller measures its time; the path's length and clearance are
        measured from its points.
        """
        ...

    def warm_up(self) -> None:
        """Do the one-off work (compiling kernels) now, not inside the first plan()."""
        ...

    def describe(self) -> str:
        """One line for the node's configure log (grid, algorithm, inflation)."""
        ...


@runtime_checkable
class PathFollower(Protocol):
    """A local controller following the planned path (link "follower"), as a Nav2 controller.

    Built as `cls(dt, lidar_offset_x_m=..., **params)`: dt the control period (s); params from
    `parameter_descriptions()` (ROS parameters of the pure_pursuit node; list lidar_offset_x_m
    there too: the run scripts set it). Commands while the robot is localized; the wall
    follower commands otherwise.
    """

    def set_path(self, points: np.ndarray) -> None:
        """Follow a new path (K, 2) (m, map frame) from its start.

        ValueError if empty or not finite. Called for every new /path.
        """
        ...

    def clear_path(self) -> None:
        """Forget the path: zero commands until the next set_path() (localization lost)."""
        ...

    def compute_commands(self, x: float, y: float, theta: float,
                         obstacle_clearance_m: float | None = None,
                         free_ahead_m: float | None = None) -> tuple[float, float]:
        """(v m/s, w rad/s) for the robot at the localized pose (x, y, theta), map frame.

        Called once per control step while localized. obstacle_clearance_m: the footprint's
        clearance from the newest scan (m; None unknown); free_ahead_m: how far the footprint
        can drive straight ahead before touching a scan point (m; inf: nothing in the way; None
        unknown) - both from amr_control.pure_pursuit's scan_clearance / scan_free_ahead with
        this follower's robot_radius_m and lidar_offset_x_m. Zero without a path and once
        arrived. Must return finite numbers.
        """
        ...

    @property
    def path(self) -> np.ndarray | None:
        """The followed path (K, 2), or None."""
        ...

    @property
    def arrived(self) -> bool:
        """True once stopped at the path's end (until the next set_path)."""
        ...

    @property
    def state(self) -> str:
        """What it does now, for logs and figures.

        "idle" (no path), "rotate" or "track" (driving), "arrived", "blocked" (waiting for
        something in the way), "off_path" (too far from it: zero).
        """
        ...

    @property
    def robot_radius_m(self) -> float:
        """Footprint radius (m) the scan clearances are computed for."""
        ...

    @property
    def lidar_offset_x_m(self) -> float:
        """Where the LiDAR sits ahead of the robot centre (m), for the scan clearances."""
        ...


@runtime_checkable
class MappingEstimate(Protocol):
    """What Mapper.update returns.

    Optional members, used when present: `keyframe` and `loop_closed` (bool: the map changed
    with this scan; the slam node then republishes /map; without them, after every scan).
    """

    pose: Pose  # map frame, at the scan's stamp
    status: str  # "matched", "odometry", "first", or "rejected: <why>"


@runtime_checkable
class Mapper(Protocol):
    """Online SLAM (link "mapper"): scans and odometry in, a pose and an occupancy grid out.

    Built as `cls(params)`: params a dict of names from `parameter_descriptions()` (the slam
    node's --slam-param), `lidar_offset_x_m` among them. The map frame is the odometry frame at
    the first scan.
    """

    def update(self, scan: Any, odom_pose: Pose, stamp: float) -> MappingEstimate:
        """Take one scan with the odometry pose at its stamp; the new estimate.

        The scan LaserScan-like (ranges, angle_min, angle_increment, range_min,
        range_max; its geometry may change from scan to scan, as the LDS-02's), with the
        odometry pose (odom frame) at its stamp (s); the new estimate. A real LiDAR's scan also
        carries `scan_time` (s, LaserScan's): its rays were measured clockwise over that time
        BEFORE the stamp, as the Burger's drivers stamp (amr_common.sensors.lidar_models
        .revolution_ages); a mapper may de-skew them with the odometry poses it gets (the
        project's does: its `deskew` parameter) or ignore it. Called for every new scan; bad
        input is skipped (status "rejected: ..."), never raised.
        """
        ...

    @property
    def pose(self) -> Pose:
        """The newest pose estimate (map frame)."""
        ...

    @property
    def map_to_odom(self) -> Pose:
        """The map -> odom transform (x, y, theta) for /tf."""
        ...

    @property
    def lidar_offset_x_m(self) -> float:
        """Where it believes the LiDAR is (m ahead of the robot centre)."""
        ...

    @property
    def max_range_m(self) -> float:
        """Readings beyond this are not mapped (m)."""
        ...

    def occupancy_raster(self) -> Any:
        """The map now: an amr_common.world.map_raster.Raster (/map, Nav2 map files)."""
        ...

    def statistics(self) -> dict[str, Any]:
        """Counts and timings for reports; every key optional.

        Read when present: `keyframes`, `loop_closures` (ints), `rejected` ({reason: count}),
        `loop_closed_cpu_ms` ({median, max} CPU ms of the closures), `update_ms` and
        `loop_closed_ms` (wall ms) for run_sim's report. The episodes measure update() times
        themselves.
        """
        ...


def interface_members(interface: type) -> dict[str, bool]:
    """The members a class must have: name -> True for a method, False for a data member.

    Properties and annotated attributes are data members (an instance attribute may stand for
    them: a class declares it with an annotation in its body).
    """
    members: dict[str, bool] = {}
    for name, value in vars(interface).items():
        if name.startswith("_"):
            continue
        if isinstance(value, property):
            members[name] = False
        elif callable(value) or isinstance(value, staticmethod):
            members[name] = True
    for name in getattr(interface, "__annotations__", {}):
        if not name.startswith("_"):
            members.setdefault(name, False)
    return members


def missing_members(cls: type, interface: type) -> list[str]:
    """The interface's members `cls` lacks.

    A method must be callable, a data member an attribute of the class or annotated in its
    body (or a base's).
    """
    declared = {name for klass in getattr(cls, "__mro__", (cls,))
                for name in getattr(klass, "__annotations__", {})}
    missing = []
    for name, is_method in interface_members(interface).items():
        value = getattr(cls, name, None)
        if is_method:
            if not callable(value):
                missing.append(name)
        elif not hasattr(cls, name) and name not in declared:
            missing.append(name)
    return missing


__all__ = ["Controller", "Localizer", "Planner", "PlannedPath", "PathFollower", "Mapper",
           "MappingEstimate", "Pose", "interface_members", "missing_members"]
