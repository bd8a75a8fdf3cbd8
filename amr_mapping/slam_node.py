"""The `slam` lifecycle node (`amr_slam`): /scan + the odometry pose -> /map, map -> odom, pose.

Online graph SLAM (amr_mapping.mapper.Mapper) for users coming from slam_toolbox (docs/slam.md,
"The slam node and the mapping runs", has the why of each choice):

    .venv/bin/amr_slam --ros-args -p autostart:=true -p output_prefix:=$HOME/maps/room
    ros2 service call /slam/save_map amr_msgs/srv/SaveMap "{name: $HOME/maps/room}"

Thin: messages become update calls on the `mapper` parameter's class (MODULE:CLASS of
amr_common.plugins.interfaces.Mapper, default the Mapper), results become messages.
- In: every new /scan (best effort; a scan repeating the previous one's ranges is skipped: the
  lockstep simulator re-sends its held scan) with the odometry POSE interpolated at its stamp
  (amr_common.pose_history) from `odometry_topic` (nav_msgs/Odometry, default /odometry); a
  scan newer than the newest odometry waits for it. The message goes to the mapper as it is
  (its scan_time: the rays' times for the Mapper's de-skew). The LiDAR position from
  /tf_static (lidar_offset_x_m until it arrives, if no scan was mapped yet).
- Out: /map (transient local) when changed, at most every map_update_interval_s of the node's
  clock and on deactivate; map -> odom on /tf with every mapped scan and, between scans, with
  the odometry; /slam_pose (amr_msgs/PoseStamped; localized: matched to the map; not /pose,
  the particle filter's); ~/save_map (amr_msgs/srv/SaveMap: Nav2 map files); with
  output_prefix, the map saved on deactivate and shutdown (Ctrl-C included).
- The map frame is the odometry frame at the first scan moved by `map_start_pose`.
Bad input (NaN/inf/0 ranges, a changing ray count, odometry jumps): the Mapper and the odometry
history skip or distrust it and log (throttled per kind); a scan stamped before the last one is
mapped at the odometry of its stamp (counted); nothing NaN is published, no callback raises. A
mapper that raises or returns what its interface forbids has failed
(amr_mapping.slam_node_mapper): mapping stops, and the run scripts end the run.
"""
from __future__ import annotations

import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import LaserScan

from amr_common.geometry import compose
from amr_common.navigation_behaviour import ScanNovelty
from amr_common.plugins.interfaces import Mapper, MappingEstimate
from amr_common.plugins.link_failure import checked_estimate
from amr_common.pose_history import LATER, OLDER, PoseHistory
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.map_messages import occupancy_grid
from amr_common.ros.map_odom_tf import MapOdomTf
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_link, declare_parameters, read_parameters
from amr_common.ros.qos import LATCHED, RELIABLE_10, scan_qos
from amr_common.ros.ros_conversions import (
    pose_from_message,
    time_to_nanoseconds,
    yaw_to_quaternion,
)
from amr_mapping.slam_map_files import read_save_request, write_slam_map
from amr_mapping.slam_node_mapper import MapperCalls
from amr_mapping.slam_node_params import NODE_PARAMETERS as _NODE_PARAMETERS
from amr_mapping.slam_node_params import configured_line, node_parameter_problems
from amr_mapping.timings import timing_summary

_ODOMETRY_HISTORY_S = 5.0  # how far back a scan's stamp may lie behind the newest odometry
_MAX_WAITING_SCANS = 10  # 2 s of 5 Hz scans


class SlamNode(MapperCalls, GuardedLifecycleNode):
    """Online SLAM on /scan and the odometry pose; see the module docstring for the I/O.

    Configure builds the Mapper and creates the /map, /slam_pose (and /tf) lifecycle publishers,
    the /scan, odometry and /tf_static subscriptions, the ~/save_map service and the /map timer;
    scans are mapped while active. Deactivate publishes the last map and saves it (with
    output_prefix); the Mapper keeps its map for a later activate. Cleanup releases everything
    (the map is gone); shutdown saves the map (with output_prefix), then releases. The node
    commands nothing: nothing else is sent on the way down.
    """

    def __init__(self, node_name: str = "slam", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # Numbers take ints for doubles (-p map_update_interval_s:=2), checked in on_configure.
        declare_parameters(self, _NODE_PARAMETERS)
        # The `mapper` class (amr_common.plugins.interfaces.Mapper) and its parameters.
        self._mapper_class, self._tuning = declare_link(self, "mapper", _NODE_PARAMETERS)
        # Run scripts append callables: each is called with (stamp_ns, MappingEstimate, node)
        # after every mapped scan (in-process observation without a subscription).
        self.on_estimate: list = []
        self.saved_maps: list[Path] = []  # every map file written, kept after shutdown
        self.map_save_error: str | None = None  # why the way down's save failed, kept too
        self._reset_runtime()

    # --- lifecycle -------------------------------------------------------------------------
    def _reset_runtime(self) -> None:
        self.mapper: Mapper | None = None
        self.node_params: dict[str, Any] = {}
        self._mapper_params: dict[str, Any] = {}
        self._outputs: dict[str, Any] = {}
        self._subscriptions: list = []
        self._service = None
        self._timer = None
        self._tf: MapOdomTf | None = None
        self._stop_log_forwarding = None
        self._history: PoseHistory | None = None
        # Scans waiting for the odometry of their stamp (it may come after them).
        self._pending: deque[tuple[int, LaserScan]] = deque()
        self._scan_novelty = ScanNovelty()  # the rule the mapping episode follows too
        self._last_scan_stamp = None  # header stamp of the newest mapped scan
        self._last_tf_ns: int | None = None
        self._start = (0.0, 0.0, 0.0)
        self._map_version = 0  # keyframes and loop closures so far: the map changed
        self._published_version = -1
        self._saved_version = -1
        self.mapped_scans = 0
        # Wall-clock ms of each mapped scan's work (Mapper update, loop closure, messages) and
        # of each /map (raster + message): no callback may hold the executor for long.
        self.scan_ms: list[float] = []
        self.map_ms: list[float] = []

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build the Mapper; create the publishers, subscriptions, save service and map timer.

        FAILURE (with the reason logged) for bad parameters or an output_prefix whose folder
        cannot be written.
        """
        node, problems = read_parameters(self, _NODE_PARAMETERS)
        values, mapper_problems = read_parameters(self, self._tuning)
        problems += mapper_problems
        if self._mapper_class is None:
            problems.append(f"mapper '{node['mapper']}' cannot be loaded (see the error above)")
        if not problems:
            problems += node_parameter_problems(node)
        if not problems:
            try:
                self.mapper = self._mapper_class(values)
                self._mapper_params = values
            except Exception as exc:  # its checks (ValueError); a user's class may raise any
                problems.append(str(exc))
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        from amr_msgs.msg import PoseStamped
        from amr_msgs.srv import SaveMap
        self.node_params = node
        self._start = tuple(float(v) for v in node["map_start_pose"])
        self._history = PoseHistory(_ODOMETRY_HISTORY_S, node["max_odometry_gap_s"])
        self._stop_log_forwarding = self.forward_python_logging("amr_mapping")
        self._pose_message = PoseStamped()
        self._pose_message.header.frame_id = node["map_frame"]
        self._outputs = {
            "map": self.create_lifecycle_publisher(OccupancyGrid, node["map_topic"], LATCHED),
            "pose": self.create_lifecycle_publisher(PoseStamped, node["pose_topic"],
                                                    RELIABLE_10)}
        self._subscriptions = [
            self.create_subscription(LaserScan, node["scan_topic"], self._on_scan,
                                     scan_qos(10)),
            self.create_subscription(Odometry, node["odometry_topic"], self._on_odometry,
                                     RELIABLE_10)]
        self._tf = MapOdomTf(self, {name: node[name] for name in (
            "map_frame", "odom_frame", "base_frame", "scan_frame")}, self._on_lidar_offset)
        self._service = self.create_service(SaveMap, "~/save_map", self._on_save_request)
        self._timer = self.create_timer(node["map_update_interval_s"],
                                        lambda: self.is_active and self._publish_map())
        self.get_logger().info(configured_line(node, self._mapper_params,
                                               self.mapper.lidar_offset_x_m, self._start))
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Publish the last map, save it (with output_prefix); then stop mapping.

        The Mapper keeps its map for a later activate.
        """
        self._publish_map()
        self._save_on_the_way_down("deactivate")
        self._pending.clear()
        return super().on_deactivate(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Save the map (with output_prefix: Ctrl-C included), then release everything."""
        self._save_on_the_way_down("shutdown")
        return super().on_shutdown(state)

    def release(self) -> None:
        """Destroy the subscriptions, service, timer and publishers; drop the Mapper.

        Nothing to send on the way down: the node commands nothing.
        """
        for subscription in self._subscriptions:
            self.destroy_subscription(subscription)
        if self._service is not None:
            self.destroy_service(self._service)
        if self._timer is not None:
            self.destroy_timer(self._timer)
        if self._tf is not None:
            self._tf.close()
        for publisher in self._outputs.values():
            self.destroy_lifecycle_publisher(publisher)
        if self._stop_log_forwarding is not None:
            self._stop_log_forwarding()
        self._reset_runtime()

    # --- inputs ----------------------------------------------------------------------------
    def _on_scan(self, scan: LaserScan) -> None:
        """Map a new scan once the odometry reaches its stamp (now, or with a later message)."""
        if not self.is_active:
            return
        new = self._scan_novelty.is_new(scan.ranges, (scan.angle_min, scan.angle_increment))
        if self.node_params["skip_repeated_scans"] and not new:
            return
        if len(self._pending) == _MAX_WAITING_SCANS:
            newest = self._history.newest_stamp
            self.warn_every("no_odometry",
                            f"scan at t={self._pending[0][0] * 1e-9:.3f} s skipped: no "
                            f"odometry reached its stamp (newest odometry: "
                            f"{'none' if newest is None else f't={newest * 1e-9:.3f} s'})")
            self._pending.popleft()
        self._pending.append((time_to_nanoseconds(scan.header.stamp), scan))
        self._map_pending()

    def _on_odometry(self, message: Odometry) -> None:
        """Keep the pose for the scans' stamps; map a waiting scan; map -> odom between scans."""
        if not self.is_active:
            return
        stamp_ns = time_to_nanoseconds(message.header.stamp)
        try:
            pose = pose_from_message(message.pose.pose)
        except ValueError as exc:
            self.warn_every("odometry", f"odometry pose ignored: {exc}")
            return
        refused = self._history.add(stamp_ns, pose)
        if refused is not None:
            self.warn_every("odometry", f"odometry at t={stamp_ns * 1e-9:.3f} s ignored: "
                            + ("its pose is not finite" if refused == "non_finite" else
                               "its stamp is not after the previous one"))
            return
        self._map_pending()
        self._publish_tf_between_scans(message.header.stamp, stamp_ns)

    def _map_pending(self) -> None:
        """Map the waiting scans, oldest first, that the odometry has reached."""
        while self._pending:
            stamp_ns, scan = self._pending[0]
            odom = self._history.pose_at(stamp_ns)
            if odom == LATER:
                return  # the odometry of its stamp comes with a later message
            self._pending.popleft()
            if odom == OLDER and not self.mapped_scans:
                continue  # a scan from before the odometry started (amr_odometry skips its first)
            if isinstance(odom, str):
                self.warn_every("no_odometry", f"scan at t={stamp_ns * 1e-9:.3f} s skipped: "
                                + ("it is older than the odometry kept" if odom == "older" else
                                   f"no odometry within "
                                   f"{self.node_params['max_odometry_gap_s']} s around its stamp"))
                continue
            started = time.perf_counter()
            self._map_scan(scan, stamp_ns, odom)
            self.scan_ms.append(1e3 * (time.perf_counter() - started))

    def _map_scan(self, scan: LaserScan, stamp_ns: int, odom: tuple[float, float, float]
                  ) -> None:
        # The Mapper's map frame is the odometry frame at its first scan: moving the
        # odometry by the start pose puts the map where map_start_pose says.
        estimate = self._use_mapper("update", self.mapper.update, scan,
                                    compose(self._start, odom), stamp_ns * 1e-9,
                                    check=checked_estimate, time_s=stamp_ns * 1e-9)
        if estimate is None or estimate.status.startswith("rejected"):
            return  # the Mapper said why (throttled), or it failed (logged)
        self.mapped_scans += 1
        # A mapper that says when its map changed (the Mapper: keyframes and loop closures
        # only) is redrawn then; any other after every mapped scan.
        if getattr(estimate, "keyframe", True) or getattr(estimate, "loop_closed", False):
            self._map_version += 1
        self._last_scan_stamp = scan.header.stamp
        self._publish_pose(estimate)
        if self.node_params["publish_tf"]:
            self._publish_tf(scan.header.stamp, stamp_ns)
        for hook in list(self.on_estimate):
            try:
                hook(stamp_ns, estimate, self)
            except Exception as exc:  # an observer must not stop the mapping
                self.warn_every("hook", f"on_estimate hook {hook!r} failed: {exc!r}",
                                error=True)

    def _on_lidar_offset(self, offset_m: float) -> None:
        """Use the LiDAR position /tf_static gives, if no scan was mapped yet."""
        if self.mapper is None or offset_m == self.mapper.lidar_offset_x_m:
            return
        if self.mapped_scans:
            self.get_logger().warning(
                f"/tf_static places the LiDAR at x = {offset_m:+.3f} m after mapping started: "
                f"keeping x = {self.mapper.lidar_offset_x_m:+.3f} m (the map's scans "
                "must agree)", throttle_duration_sec=10.0)
            return
        self._mapper_params = {**self._mapper_params, "lidar_offset_x_m": offset_m}
        mapper = self._use_mapper("the constructor", self._mapper_class, self._mapper_params)
        if mapper is None:
            return
        self.mapper = mapper
        self.get_logger().info(f"LiDAR at x = {offset_m:+.3f} m from /tf_static "
                               f"({self.node_params['base_frame']} -> "
                               f"{self.node_params['scan_frame']})")

    # --- outputs ---------------------------------------------------------------------------
    def _publish_pose(self, estimate: MappingEstimate) -> None:
        message = self._pose_message
        message.header.stamp = self._last_scan_stamp
        x, y, theta = estimate.pose
        message.pose.position.x, message.pose.position.y = float(x), float(y)
        yaw_to_quaternion(float(theta), message.pose.orientation)
        message.localized = estimate.status in ("matched", "first")
        self._outputs["pose"].publish(message)

    def _publish_tf_between_scans(self, stamp, stamp_ns: int) -> None:
        if not self.node_params["publish_tf"] or self._last_tf_ns is None:
            return  # nothing mapped yet: no map frame
        if stamp_ns < self._last_tf_ns:  # time went back: start again from here
            self._last_tf_ns = stamp_ns
        if stamp_ns - self._last_tf_ns < self.node_params["transform_publish_period_s"] * 1e9 \
                or self._tf.publisher.get_subscription_count() == 0:
            return  # (nobody listens in a lockstep run: ~30 us a step saved)
        self._publish_tf(stamp, stamp_ns)

    def _publish_map(self) -> None:
        """/map if it changed since the last one (and anything was mapped)."""
        if self.mapper is None or self.mapped_scans == 0 or \
                self._map_version == self._published_version:
            return
        started = time.perf_counter()
        raster = self.map_raster()
        if raster is None:
            return
        self._outputs["map"].publish(occupancy_grid(
            raster.values, raster.resolution, raster.origin, self.node_params["map_frame"],
            self._last_scan_stamp))
        self._published_version = self._map_version
        self.map_ms.append(1e3 * (time.perf_counter() - started))

    # --- saving ----------------------------------------------------------------------------
    def save_map(self, prefix: str | Path, image_format: str | None = None) -> Path:
        """Write the map so far as PREFIX.yaml + PREFIX.pgm (png); the YAML's path.

        ValueError (MapFileError included) with the reason when nothing was mapped yet, the
        mapper failed, or the map has no free cell or cannot be written (write_slam_map).
        """
        if self.mapper is None or self.mapped_scans == 0:
            raise ValueError("nothing to save: no scan has been mapped yet")
        raster, stats = self.map_raster(), self.mapper_statistics()
        if self.link_failure is not None:  # its map is not trusted: an earlier save stays
            raise ValueError(f"the mapper failed: {self.link_failure.reason}")
        yaml_path, no_start = write_slam_map(raster, stats, prefix,
                                             image_format or self.node_params["image_format"],
                                             self._start, self.mapped_scans)
        if no_start is not None:
            self.get_logger().warning(f"{yaml_path} names no start pose: {no_start} on its "
                                      f"{raster.resolution:g} m cells; give one to drive in it")
        self._saved_version = self._map_version
        self.saved_maps.append(yaml_path)
        return yaml_path

    def _on_save_request(self, request, response):
        """~/save_map: the map so far to request.name (or output_prefix); never raises."""
        prefix, image_format, problem = read_save_request(
            request, self.node_params.get("output_prefix", ""))
        response.success, response.message = False, problem or ""
        if problem is None:
            try:
                response.message = str(self.save_map(prefix, image_format))
                response.success = True
            except (ValueError, OSError) as exc:
                response.message = str(exc)
        if response.success:  # (rclpy refuses two severities from one call site)
            self.get_logger().info(f"save_map: saved {response.message}")
        else:
            self.get_logger().warning(f"save_map: not saved: {response.message}")
        return response

    def _save_on_the_way_down(self, transition: str) -> None:
        prefix = self.node_params.get("output_prefix", "")
        if not prefix or self.mapper is None:
            return
        if self.mapped_scans == 0:
            self.get_logger().warning(f"{transition}: no map saved to {prefix}: no scan was "
                                      "mapped")
            return
        if self._saved_version == self._map_version:
            return  # saved already, and unchanged since
        try:
            path = self.save_map(prefix)
            self.map_save_error = None
            self.get_logger().info(f"{transition}: map saved to {path}")
        except (ValueError, OSError) as exc:
            self.map_save_error = str(exc)
            self.get_logger().error(f"{transition}: the map could not be saved: {exc}")

    # --- figures ---------------------------------------------------------------------------
    def timings(self) -> dict[str, dict[str, float]]:
        """Wall-clock ms (count, median, max, ...) of the mapped scans' work and /map builds."""
        return {"scan_ms": timing_summary(self.scan_ms), "map_ms": timing_summary(self.map_ms)}


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(SlamNode, args)


if __name__ == "__main__":
    sys.exit(main())
