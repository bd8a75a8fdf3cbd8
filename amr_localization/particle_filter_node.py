"""The `particle_filter` lifecycle node: /odometry + /scan -> /pose.

Outputs /pose (amr_msgs/PoseStamped with `localized`), /amcl_pose, /particles and map -> odom on
/tf, on the world map of the simulator (one loader); reads the LiDAR position from /tf_static
(localization_tf.py).

Thin: messages become predict / correct calls on the localizer (parameter `localizer`,
MODULE:CLASS of amr_common.plugins.interfaces.Localizer; default the ParticleFilter) and results
become messages; its tuning values (`parameter_descriptions()`) are parameters of this node.
- Every /odometry message moves the particles by its twist over the time since the previous one
  (so between the turtlebot3's 5 Hz scans the pose is predicted from odometry).
- Every approximately synchronized (/odometry, /scan) pair is answered with exactly one /pose,
  stamped with the scan's stamp, in frame `map` (the lockstep loop and the simulator's
  /cmd_vel-/pose synchronization must never stall). A scan whose readings differ from the
  previous one is weighed when the robot moved enough; one seen before (the lockstep simulator
  re-publishes the last 5 Hz scan every step; a standing robot's ideal scan repeats) only every
  update_max_interval_s (ParticleFilter.correct).
- /amcl_pose (geometry_msgs/PoseWithCovarianceStamped) after every measurement update;
  /particles (geometry_msgs/PoseArray) at most every `particles_period_s` of stamp time.
- /initialpose (RViz's and Foxglove's "2D Pose Estimate") re-initializes around that pose.
- No callback blocks the node for long: on a big map the filter's exhaustive pose searches
  are scored a slice per scan (amr_localization.filter_searches; on the 40 x 40 m floor at most
  ~0.15 s of CPU per call instead of ~3 s for a search in one go).
A localizer that raises (beyond its interface's ValueErrors) or returns what its interface
forbids has failed (amr_common.plugins.link_failure): logged once, /pose not localized from then
on, and the run scripts end the run.
Bad input (NaN or 0.0 everywhere, inconsistent scan geometry, non-finite odometry, stamps going
backwards) is skipped with a throttled message, never a crash (a jump back by more than
max_odometry_gap_s restarts the integration from there: one stamp far in the future cannot stop
it for good); without a usable scan for `max_scan_age_s` the node reports localized false. All
stamps come from the messages, so the node works the same in lockstep (simulated stamps) and in
real time; use_sim_time only changes its log clock.
"""
from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import LaserScan

from amr_common.navigation_behaviour import OdometryClock, ScanNovelty
from amr_common.plugins.interfaces import Localizer
from amr_common.plugins.link_failure import (
    checked_covariance,
    checked_localization,
    checked_particles,
)
from amr_common.ros import message_filters
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_link, declare_parameters, read_parameters
from amr_common.ros.qos import RELIABLE_10, scan_qos
from amr_common.ros.ros_conversions import (
    fill_pose,
    pose_array,
    pose_with_covariance,
    scan_ranges,
    time_to_nanoseconds,
)
from amr_common.sensors.scan_returns import return_mask
from amr_common.world.world import World
from amr_localization.expected_ranges import TableBuildInterrupted
from amr_localization.initial_pose_request import initial_pose_request
from amr_localization.localization_tf import LocalizationTf
from amr_localization.particle_filter_node_params import NODE_PARAMETERS as _NODE_PARAMETERS


class ParticleFilterNode(GuardedLifecycleNode):
    """Monte Carlo localization on the world map; see the module docstring for the I/O.

    Creates nothing until configured; the filter (with its expected-range table) is built in
    on_configure, so a missing or malformed map fails that transition with the loader's message.
    Configure also creates the /pose, /amcl_pose, /particles (and /tf) lifecycle publishers,
    the synchronized /odometry + /scan inputs, the /initialpose and /tf_static subscriptions;
    messages are processed while active (deactivate stops processing, the filter keeps its
    state); cleanup and shutdown release everything (release()). It commands nothing: nothing
    is sent on the way down.
    """

    def __init__(self, node_name: str = "particle_filter", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # Numbers take ints for doubles (-p slop:=1), checked in on_configure.
        declare_parameters(self, _NODE_PARAMETERS)
        self._localizer_class, self._tuning = declare_link(self, "localizer", _NODE_PARAMETERS)
        # Run scripts append callables here: each is called with (stamp_ns, (x, y, theta),
        # localized, node) after every /pose (in-process observation without a subscription).
        self.on_pose: list = []
        self._reset_runtime()

    # --- lifecycle -------------------------------------------------------------------------
    def _reset_runtime(self) -> None:
        self.filter: Localizer | None = None
        self._outputs: dict[str, Any] = {}
        self._subscribers: list = []
        self._initialpose_subscription = None
        self._synchronizer = None
        self._odometry_clock = OdometryClock()
        self._scan_novelty = ScanNovelty()
        self._last_scan_ns: int | None = None  # newest usable scan
        self._taken_ns: int | None = None  # stamp of the newest NEW scan (held ones: re-sent)
        self._last_particles_ns: int | None = None
        self._scan_key: tuple | None = None
        self._tf: LocalizationTf | None = None
        self.pose_count = 0  # /pose messages published (tests, run scripts)

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the world, build the filter, create the publishers and inputs.

        Load the world, build the filter, create the publishers, the synchronized
        /odometry + /scan inputs and the /initialpose subscription. FAILURE (with the reason
        logged) for bad parameters or a missing/malformed world file, and when a script's
        Ctrl-C or SIGTERM stops the build of a big map's expected-range table.
        """
        node, problems = read_parameters(self, _NODE_PARAMETERS)
        filter_params, filter_problems = read_parameters(self, self._tuning)
        problems += filter_problems
        if self._localizer_class is None:
            problems.append(f"localizer '{node['localizer']}' cannot be loaded (see the error "
                            "above)")
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        world = self._build_filter(node["world"], filter_params)
        if world is None:
            return TransitionCallbackReturn.FAILURE
        from amr_msgs.msg import PoseStamped
        self.node_params = node
        self._odometry_clock = OdometryClock(node["max_odometry_gap_s"])
        self._pose_message = PoseStamped()
        self._pose_message.header.frame_id = node["map_frame"]
        self._outputs = {
            "pose": self.create_lifecycle_publisher(PoseStamped, node["pose_topic"],
                                                    RELIABLE_10),
            "amcl_pose": self.create_lifecycle_publisher(
                PoseWithCovarianceStamped, node["amcl_pose_topic"], RELIABLE_10),
            "particles": self.create_lifecycle_publisher(PoseArray, node["particles_topic"],
                                                         RELIABLE_10),
        }
        odometry = message_filters.Subscriber(self, Odometry, node["odometry_topic"],
                                              qos_profile=RELIABLE_10)
        # Registered before the synchronizer: a pair is handled after its odometry moved the
        # particles, whichever of the two messages completes it.
        odometry.registerCallback(self._on_odometry)
        scan = message_filters.Subscriber(self, LaserScan, node["scan_topic"],
                                          qos_profile=scan_qos(10))
        self._subscribers = [odometry, scan]
        self._synchronizer = message_filters.ApproximateTimeSynchronizer(
            self._subscribers, int(node["queue_size"]), float(node["slop"]))
        self._synchronizer.registerCallback(self._on_pair)
        self._initialpose_subscription = self.create_subscription(
            PoseWithCovarianceStamped, node["initialpose_topic"], self._on_initial_pose,
            RELIABLE_10)
        if node["publish_tf"]:
            self._tf = LocalizationTf(self, {name: node[name] for name in (
                "map_frame", "odom_frame", "base_frame", "scan_frame")}, self._on_lidar_offset)
        self.get_logger().info(f"configured: world '{world.name}' ({world.source}), "
                               f"{node['localizer']}: {self.filter.describe()}")
        return TransitionCallbackReturn.SUCCESS

    def _build_filter(self, source: str, filter_params: dict[str, Any]) -> World | None:
        """Load the world and build `filter` on it; None (the reason logged) if that fails."""
        try:
            world = World.load(source)
            self.filter = self._localizer_class(world, **{
                name: list(value) if isinstance(value, (tuple, list)) or hasattr(value, "tolist")
                else value for name, value in filter_params.items()})
            return world
        except TableBuildInterrupted as exc:  # Ctrl-C or SIGTERM while a big map's table built
            self.get_logger().warning(f"configure stopped: {exc}")
        except Exception as exc:  # WorldError, bad values; a user's class may raise anything
            self.get_logger().error(f"configure failed: {exc}")
        self._reset_runtime()
        return None

    def release(self) -> None:
        """Destroy the subscriptions and publishers and drop the filter.

        Nothing to send on the way down: the node commands nothing.
        """
        for subscriber in self._subscribers:
            subscriber.close()
        if self._initialpose_subscription is not None:
            self.destroy_subscription(self._initialpose_subscription)
        if self._tf is not None:
            self._tf.close()
        for publisher in self._outputs.values():
            self.destroy_lifecycle_publisher(publisher)
        self._reset_runtime()

    # --- data path -------------------------------------------------------------------------
    def _on_odometry(self, message: Odometry) -> None:
        if not self.is_active:
            return
        stamp = time_to_nanoseconds(message.header.stamp)
        v, w = message.twist.twist.linear.x, message.twist.twist.angular.z
        if not (math.isfinite(v) and math.isfinite(w)):
            self.get_logger().warning("odometry twist is not finite: ignored",
                                      throttle_duration_sec=2.0)
            return
        # The stamp rules (late, jumped back, gap) are OdometryClock's, shared with the
        # headless episodes.
        dt, why = self._odometry_clock.advance(stamp)
        if why in ("back", "jumped back"):
            self.get_logger().warning(
                "odometry stamp went back or repeated: not integrated"
                + ("; integrating from this stamp on" if why == "jumped back" else ""),
                throttle_duration_sec=2.0)
        elif why == "gap":
            self.get_logger().warning(f"more than {self.node_params['max_odometry_gap_s']} s "
                                      "without odometry: the motion in the gap is lost",
                                      throttle_duration_sec=2.0)
        if dt is not None:
            self._use_filter("predict", lambda: self.filter.predict(float(v), float(w), dt),
                             stamp * 1e-9)

    def _on_pair(self, odometry: Odometry, scan: LaserScan) -> None:
        if not self.is_active:
            return
        stamp_ns = time_to_nanoseconds(scan.header.stamp)
        ranges = self._usable_ranges(scan, stamp_ns)
        if ranges is not None:
            new_scan = self._scan_novelty.is_new(ranges)  # not the held one again
            if new_scan or self._taken_ns is None:
                self._last_scan_ns = self._taken_ns = stamp_ns
            # The scan's age at the newest odometry the filter predicted to (for de-skewing):
            # a held scan (the lockstep simulator re-sends it with each step's stamp) was taken
            # when it was first seen, as the headless episodes count it.
            newest = self._odometry_clock.last_ns
            age_s = 0.0 if newest is None else (newest - self._taken_ns) * 1e-9
            if self._use_filter("correct", lambda: self.filter.correct(
                    ranges, new_scan=new_scan, age_s=age_s), stamp_ns * 1e-9):
                self._last_scan_ns = stamp_ns
                self._publish_amcl_pose(scan.header.stamp, stamp_ns)
        estimate = self._publish_pose(scan.header.stamp, stamp_ns)
        if self._tf is not None and self.link_failure is None:
            self._tf.publish_map_to_odom(estimate, odometry, scan.header.stamp)
        self._publish_particles(scan.header.stamp, stamp_ns)

    def _use_filter(self, member: str, function, time_s: float | None, **options) -> Any:
        """function() (a call or read of the localizer's `member`); None once it failed.

        Its failure (amr_common.plugins.link_failure) is kept and logged once; from then on /pose
        is not localized and the localizer is not used again (GuardedLifecycleNode.use_link).
        """
        return self.use_link("localizer", member, function, spec=self.node_params["localizer"],
                             time_s=time_s, then="/pose is not localized from now on",
                             **options)

    def _on_lidar_offset(self, offset_m: float) -> None:
        """Use the LiDAR position /tf_static gives (the parameter is the fallback)."""
        # (MapOdomTf passes only finite offsets within 1 m: the localizer must take them.)
        if self.filter is None or offset_m == self._use_filter(
                "lidar_offset_x_m", lambda: self.filter.lidar_offset_x_m, None):
            return
        self._use_filter("set_lidar_offset", lambda: self.filter.set_lidar_offset(offset_m), None)
        if self.link_failure is not None:
            return
        self.get_logger().info(f"LiDAR at x = {offset_m:+.3f} m from /tf_static "
                               f"({self.node_params['base_frame']} -> "
                               f"{self.node_params['scan_frame']})")

    def _usable_ranges(self, scan: LaserScan, stamp_ns: int) -> np.ndarray | None:
        """The scan's ranges if usable (geometry consistent, enough valid readings), else None.

        A new geometry is told to the filter first; an unusable scan is skipped with a warning.
        """
        n = len(scan.ranges)
        geometry = (scan.angle_min, scan.angle_increment, n, scan.range_min, scan.range_max)
        if n == 0 or not all(math.isfinite(v) for v in geometry) or scan.angle_increment == 0:
            self.warn_every("scan", f"scan has no rays or unusable angles/limits {geometry}: "
                            "skipped")
            return None
        expected = round((scan.angle_max - scan.angle_min) / scan.angle_increment) + 1 \
            if math.isfinite(scan.angle_max) else -1
        if expected != n:
            self.warn_every("scan", f"scan has {n} ranges but angle_min/angle_max/"
                            f"angle_increment describe {expected}: skipped")
            return None
        if geometry != self._scan_key:
            try:
                self._use_filter("set_scan_geometry", lambda: self.filter.set_scan_geometry(
                    scan.angle_min, scan.angle_increment, n, scan.range_min, scan.range_max),
                    stamp_ns * 1e-9, allowed=(ValueError,))
            except ValueError as exc:
                self.warn_every("scan", f"scan geometry rejected: {exc}")
                return None
            if self.link_failure is not None:
                return None
            self._scan_key = geometry
        ranges = scan_ranges(scan)
        valid = np.count_nonzero(return_mask(ranges, scan.range_min, scan.range_max))
        if valid < self.node_params["min_valid_share"] * n:
            self.warn_every("scan", f"scan has {valid} valid readings of {n} (NaN, inf, 0.0 or "
                            f"outside [{scan.range_min}, {scan.range_max}]): skipped")
            return None
        return ranges

    def _refuse_initial_pose(self, text: str) -> None:
        """Say why an /initialpose was ignored: every time (a user sent it and must know)."""
        self.warn_every("initialpose", text, period_s=0.0)

    # --- outputs ---------------------------------------------------------------------------
    def estimate(self, stamp_ns: int) -> tuple[tuple[float, float, float], bool]:
        """The localizer's estimate and whether it is localized now.

        Its flag, unless the newest usable scan is older than max_scan_age_s; checked
        (amr_common.plugins.link_failure): NaN and False once the localizer failed.
        """
        checked = self._use_filter("estimate", lambda: checked_localization(
            self.filter.estimate, self.filter.localized), stamp_ns * 1e-9)
        if checked is None:
            return (math.nan, math.nan, math.nan), False
        pose, flag = checked
        # abs(): a usable scan stamped after this pair (a bogus future stamp) is no evidence now
        return pose, flag and self._last_scan_ns is not None and abs(
            stamp_ns - self._last_scan_ns) * 1e-9 <= self.node_params["max_scan_age_s"]

    def _publish_pose(self, stamp, stamp_ns: int) -> tuple[float, float, float]:
        """/pose (and the on_pose hooks); the estimate published (NaN if none)."""
        (x, y, theta), localized = self.estimate(stamp_ns)
        finite = all(math.isfinite(v) for v in (x, y, theta))
        message = self._pose_message
        message.header.stamp = stamp
        fill_pose(message.pose, (x, y, theta) if finite else (0.0, 0.0, 0.0))
        message.localized = finite and localized
        self._outputs["pose"].publish(message)
        self.pose_count += 1
        for hook in list(self.on_pose):
            try:
                hook(stamp_ns, (x, y, theta), message.localized, self)
            except Exception as exc:  # an observer must not stop the filter
                self.get_logger().error(f"on_pose hook {hook!r} failed: {exc!r}",
                                        throttle_duration_sec=5.0)
        return x, y, theta

    def _publish_amcl_pose(self, stamp, stamp_ns: int) -> None:
        read = self._use_filter("covariance", lambda: (checked_localization(
            self.filter.estimate, False)[0], checked_covariance(self.filter.covariance)),
            stamp_ns * 1e-9)
        if read is None or not (all(math.isfinite(v) for v in read[0])
                                and np.all(np.isfinite(read[1]))):
            return
        self._outputs["amcl_pose"].publish(pose_with_covariance(
            *read, stamp, self.node_params["map_frame"]))

    def _publish_particles(self, stamp, stamp_ns: int) -> None:
        period_ns = int(self.node_params["particles_period_s"] * 1e9)
        if self._last_particles_ns is not None and 0 <= stamp_ns - self._last_particles_ns \
                < period_ns:
            return
        publisher = self._outputs["particles"]
        if publisher.get_subscription_count() == 0:
            return
        self._last_particles_ns = stamp_ns
        particles = self._use_filter("particles", lambda: checked_particles(
            self.filter.particles), stamp_ns * 1e-9)
        if particles is None:
            return
        step = max(1, len(particles) // int(self.node_params["particles_published"]))
        publisher.publish(pose_array(particles[::step], stamp, self.node_params["map_frame"]))

    def _on_initial_pose(self, message: PoseWithCovarianceStamped) -> None:
        """Re-initialize around a 2D pose estimate (sigmas from its covariance when usable).

        Sigmas wider than the map are clamped to it (the filter's bounded_sigma); a pose or
        covariance that is not finite, in another frame, or where the robot cannot be (on a
        wall, outside the map) is ignored with a logged reason: the filter keeps its state.
        Zero or negative variances mean "not given": initial_pose_sigma is used.
        """
        if self.filter is None:
            return
        request = initial_pose_request(message, self.node_params["map_frame"])
        if isinstance(request, str):
            self._refuse_initial_pose(request)
            return
        (x, y, theta), sigma = request
        try:
            used = self._use_filter("initialize_pose", lambda: self.filter.initialize_pose(
                (x, y, theta), sigma), None, allowed=(ValueError,))
        except ValueError as exc:
            self._refuse_initial_pose(f"/initialpose ignored: {exc}")
            return
        if self.link_failure is not None:
            return
        clamped = sigma is not None and not np.allclose(used, sigma, rtol=0.0, atol=0.0)
        note = f" (clamped to the map from {_rounded(sigma)})" if clamped else ""
        text = (f"re-initialized around ({x:.2f}, {y:.2f}, {theta:.2f}) from /initialpose, "
                f"sigma {_rounded(used)}{note}: not localized until the scans confirm it")
        if clamped:
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)


def _rounded(values) -> list[float]:
    return [float(f"{float(v):.3g}") for v in values]


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(ParticleFilterNode, args)


if __name__ == "__main__":
    sys.exit(main())
