"""The slam node: /map, map -> odom, /slam_pose, save service, saves on the way down, bad input."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

from amr_common.geometry import compose
from amr_common.ros.map_messages import grid_values
from amr_common.ros.ros_conversions import (
    laser_scan_from_profile,
    odometry_message,
    pose_from_message,
    seconds_to_time,
)
from amr_common.ros.tf import TF_QOS, planar_transform
from amr_common.world.map_file import read_map
from amr_evaluation.episode import default_controller
from amr_mapping.slam_node import SlamNode
from amr_sim.simulator import Simulator

BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
LATCHED_SUBSCRIBER = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)


def make_node(ros, name="slam", **params):
    overrides = [Parameter(key, value=value) for key, value in params.items()]
    return ros.add(SlamNode(name, context=ros.context, parameter_overrides=overrides))


class Robot:
    """The test's side: a Simulator driven by the wall follower.

    It publishes as the lockstep simulator node does (/odometry and /scan every step, the held
    5 Hz scan again).
    """

    def __init__(self, ros, world="lab02", start="outer", profile="turtlebot3_clean"):
        self.sim = Simulator(world, start=start, profile=profile, seed=2)
        self.controller = default_controller(self.sim.dt, self.sim.profile)
        self.node = ros.node("fake_robot")
        self.odometry = self.node.create_publisher(Odometry, "/odometry", 10)
        self.scan = self.node.create_publisher(LaserScan, "/scan", BEST_EFFORT)
        self.poses, self.transforms = [], []
        from amr_msgs.msg import PoseStamped
        self.node.create_subscription(PoseStamped, "/slam_pose", self.poses.append, 100)
        self.node.create_subscription(TFMessage, "/tf", self._on_tf, TF_QOS)
        self.truth: dict[int, tuple] = {}  # scan stamp (ns) -> true pose

    def _on_tf(self, message):
        self.transforms += [t for t in message.transforms if t.child_frame_id == "odom"]

    def publish(self, odometry_pose=None, stamp_offset=0.0, scan=True, **scan_fields):
        sim = self.sim
        stamp = seconds_to_time(sim.time + stamp_offset)
        self.odometry.publish(odometry_message(
            stamp, "odom", "base_footprint",
            sim.odometry_pose if odometry_pose is None else odometry_pose))
        if scan:
            message = laser_scan_from_profile(sim.last_scan, sim.profile, stamp=stamp,
                                              frame_id="base_scan", scan_time=sim.dt)
            for name, value in scan_fields.items():
                setattr(message, name, value)
            self.scan.publish(message)
        return stamp

    def drive(self, ros, node, steps, **publish_kwargs):
        """Lockstep: publish, wait until the node took a new scan in, step by the controller."""
        for _ in range(steps):
            scan_ns = round(self.sim.scan_time * 1e9)
            new_scan = scan_ns not in self.truth
            before = node.mapped_scans
            self.publish(**publish_kwargs)
            if new_scan and not publish_kwargs:
                ros.spin_until(lambda: node.mapped_scans > before, 5.0, "the scan to be mapped")
                self.truth[scan_ns] = self.sim.pose
            else:
                ros.spin_for(0.003)
            z_scan, z_v, z_w = self.sim.measure()
            self.sim.step(*self.controller.compute_commands(z_scan, z_v, z_w))


def bring_up(ros, node, robot):
    assert node.trigger_configure().name == "SUCCESS"
    assert node.trigger_activate().name == "SUCCESS"
    ros.spin_until(lambda: robot.node.count_subscribers("/scan") >= 1 and
                   robot.node.count_subscribers("/odometry") >= 1 and
                   robot.node.count_publishers("/slam_pose") >= 1, 10.0, "discovery")
    ros.spin_for(0.2)


def start_pose(robot):
    return [float(v) for v in robot.sim.start]


def test_maps_a_drive_map_latched_at_most_1_hz_tf_and_pose(ros):
    robot = Robot(ros)
    node = make_node(ros, map_start_pose=start_pose(robot), lidar_offset_x_m=-0.032)
    bring_up(ros, node, robot)
    maps = []  # (wall time, message)
    robot.node.create_subscription(OccupancyGrid, "/map",
                                   lambda m: maps.append((time.monotonic(), m)),
                                   LATCHED_SUBSCRIBER)
    for _ in range(3):  # drive, then let the 1 s timer publish, three times
        robot.drive(ros, node, 120)
        ros.spin_for(1.1)
    assert node.mapped_scans == len(robot.truth) >= 80, "every new scan, no repeated one"
    assert len(maps) >= 2
    gaps = np.diff([t for t, _ in maps])
    assert gaps.min() >= 0.9, f"/map more often than 1 Hz: {gaps}"
    # Transient local: a subscriber that comes now still gets the newest map.
    late = []
    robot.node.create_subscription(OccupancyGrid, "/map", late.append, LATCHED_SUBSCRIBER)
    ros.spin_until(lambda: late, 5.0, "the latched /map")
    values = grid_values(late[0])
    raster = node.mapper.occupancy_raster()
    assert np.array_equal(values, raster.values) and late[0].header.frame_id == "map"
    # /slam_pose: one per mapped scan, the scan's stamp, in the world frame (map_start_pose).
    ros.spin_for(0.2)
    assert len(robot.poses) == node.mapped_scans
    errors = [math.hypot(p.pose.position.x - robot.truth[_ns(p.header.stamp)][0],
                         p.pose.position.y - robot.truth[_ns(p.header.stamp)][1])
              for p in robot.poses]
    assert max(errors) < 0.03, "the SLAM pose within 3 cm of the truth (exact odometry)"
    assert sum(p.localized for p in robot.poses) >= 0.9 * len(robot.poses)
    # map -> odom: with the odometry it gives the SLAM pose; stamped like the scans.
    last = robot.transforms[-1]
    transform = pose_from_message(_as_pose(last.transform))
    assert last.header.frame_id == "map"
    pose = compose(transform, robot.sim.odometry_pose)
    assert math.hypot(pose[0] - robot.sim.pose[0], pose[1] - robot.sim.pose[1]) < 0.03
    assert all(math.isfinite(t.transform.translation.x) for t in robot.transforms)
    timings = node.timings()
    assert timings["scan_ms"]["count"] == node.mapped_scans and timings["map_ms"]["count"] >= 2


def test_save_service_writes_the_mappers_raster(ros, tmp_path):
    from amr_msgs.srv import SaveMap
    robot = Robot(ros)
    node = make_node(ros, map_start_pose=start_pose(robot))
    bring_up(ros, node, robot)
    client = robot.node.create_client(SaveMap, "/slam/save_map")
    ros.spin_until(client.service_is_ready, 5.0, "the save_map service")

    def call(**fields):
        future = client.call_async(SaveMap.Request(**fields))
        ros.spin_until(future.done, 10.0, "the save_map answer")
        return future.result()

    answer = call(name=str(tmp_path / "early"))
    assert not answer.success and "no scan" in answer.message
    robot.drive(ros, node, 200)
    answer = call(name=str(tmp_path / "maps" / "lab02.yaml"))
    assert answer.success, answer.message
    assert answer.message == str(tmp_path / "maps" / "lab02.yaml")
    saved = read_map(answer.message)
    raster = node.mapper.occupancy_raster()
    assert np.array_equal(saved.raster.values, raster.values)
    assert saved.raster.resolution == raster.resolution
    assert saved.raster.origin == pytest.approx(raster.origin, abs=1e-9)
    assert saved.starts["slam_start"] == pytest.approx(start_pose(robot))
    answer = call(name=str(tmp_path / "png"), image_format="png")
    assert answer.success and (tmp_path / "png.png").is_file()
    (tmp_path / "early").write_text("a file where a folder is asked for")
    for fields, reason in (({}, "output_prefix"), ({"name": "x", "image_format": "jpg"},
                                                   "pgm or png"),
                           ({"name": str(tmp_path / "early" / "x")}, "early")):
        answer = call(**fields)
        assert not answer.success and reason in answer.message, answer.message


def test_map_saved_on_deactivate_and_on_shutdown(ros, tmp_path):
    robot = Robot(ros)
    prefix = tmp_path / "session" / "map"
    node = make_node(ros, map_start_pose=start_pose(robot), output_prefix=str(prefix))
    bring_up(ros, node, robot)
    robot.drive(ros, node, 80)
    assert node.trigger_deactivate().name == "SUCCESS"
    first = read_map(f"{prefix}.yaml").raster.values
    assert np.array_equal(first, node.mapper.occupancy_raster().values)
    assert node.trigger_activate().name == "SUCCESS"
    robot.drive(ros, node, 120)
    raster = node.mapper.occupancy_raster()
    # Ctrl-C of amr_slam / a run script: shutdown straight from active.
    assert node.trigger_shutdown().name == "SUCCESS"
    second = read_map(f"{prefix}.yaml").raster.values
    assert np.array_equal(second, raster.values) and second.shape != first.shape
    assert node.saved_maps == [prefix.with_suffix(".yaml")] * 2


def test_a_map_that_could_not_be_saved_on_the_way_down_is_remembered(ros, tmp_path):
    """The run scripts' exit code says it (it was only logged)."""
    robot = Robot(ros)
    folder = tmp_path / "session"
    node = make_node(ros, map_start_pose=start_pose(robot), output_prefix=str(folder / "map"))
    bring_up(ros, node, robot)
    robot.drive(ros, node, 40)
    folder.rmdir()
    folder.write_text("")  # the folder became a file during the run
    assert node.trigger_shutdown().name == "SUCCESS"
    assert node.saved_maps == [] and "cannot write the map" in node.map_save_error


def test_nothing_mapped_nothing_saved_and_a_bad_prefix_fails_configure(ros, tmp_path):
    prefix = tmp_path / "empty" / "map"
    node = make_node(ros, output_prefix=str(prefix))
    assert node.trigger_configure().name == "SUCCESS"
    assert node.trigger_activate().name == "SUCCESS"
    assert node.trigger_shutdown().name == "SUCCESS"
    assert not prefix.with_suffix(".yaml").exists()
    blocker = tmp_path / "file"
    blocker.write_text("")
    errors = []
    for name, params, reason in (
            ("bad1", {"output_prefix": str(blocker / "map")}, "output_prefix"),
            ("bad2", {"map_update_interval_s": 0.0, "image_format": "jpg"},
             "map_update_interval_s"),
            ("bad3", {"map_start_pose": [0.0, math.nan, 0.0]}, "map_start_pose"),
            ("bad4", {"resolution_m": -0.02, "loop_closure": True}, "resolution_m")):
        bad = make_node(ros, name, **params)
        bad.get_logger().error = lambda text, **kw: errors.append(text)
        assert bad.trigger_configure().name == "FAILURE"
        assert reason in errors[-1], errors[-1]


def test_out_of_order_lifecycle_requests_are_refused(ros):
    node = make_node(ros)
    assert node.trigger_activate().name == "FAILURE"
    assert node.trigger_deactivate().name == "FAILURE"
    assert node.trigger_configure().name == "SUCCESS"
    assert node.trigger_configure().name == "FAILURE"
    assert node.trigger_activate().name == "SUCCESS"
    assert node.trigger_cleanup().name == "FAILURE"
    assert node.trigger_deactivate().name == "SUCCESS"
    assert node.trigger_cleanup().name == "SUCCESS"
    assert node.mapper is None
    assert node.trigger_shutdown().name == "SUCCESS"
    assert node.trigger_shutdown().name == "FAILURE"
    assert node.current_state_label() == "finalized"


def test_bad_input_is_skipped_and_nothing_nan_is_published(ros):
    robot = Robot(ros, profile="ideal")
    node = make_node(ros, map_start_pose=start_pose(robot))
    bring_up(ros, node, robot)
    robot.drive(ros, node, 20)
    mapped = node.mapped_scans
    n = robot.sim.profile.scan_rays
    bad_scans = [{"ranges": [math.nan] * n}, {"ranges": [0.0] * n}, {"ranges": [math.inf] * n},
                 {"angle_increment": math.nan}, {"angle_increment": 0.0}]
    for fields in bad_scans:
        robot.drive(ros, node, 2, **fields)
    # A ray count that changes from scan to scan (LDS-02): mapped, not refused.
    ranges = robot.sim.last_scan
    robot.drive(ros, node, 1, ranges=[float(r) for r in ranges[::2]],
                angle_increment=2 * robot.sim.profile.angle_increment)
    # Odometry: NaN, a broken quaternion, a jump of 2 m, stamps going back.
    robot.drive(ros, node, 1, odometry_pose=(math.nan, 0.0, 0.0))
    robot.drive(ros, node, 1, odometry_pose=(robot.sim.odometry_pose[0] + 2.0,
                                             *robot.sim.odometry_pose[1:]))
    robot.drive(ros, node, 2, stamp_offset=-0.3)
    message = odometry_message(seconds_to_time(robot.sim.time), "odom", "base_footprint")
    message.pose.pose.orientation.w = 0.0
    robot.odometry.publish(message)
    robot.drive(ros, node, 40)  # and good input works again
    ros.spin_for(0.3)
    assert node.current_state_label() == "active"
    stats = node.mapper.statistics()
    assert stats["out_of_order"] >= 1, stats  # mapped at the odometry of their stamp, counted
    assert node.mapped_scans > mapped + 30
    for p in robot.poses:
        values = (p.pose.position.x, p.pose.position.y, p.pose.orientation.z,
                  p.pose.orientation.w)
        assert all(math.isfinite(v) for v in values)
    assert all(math.isfinite(t.transform.translation.x) and
               math.isfinite(t.transform.rotation.w) for t in robot.transforms)
    raster = node.mapper.occupancy_raster()
    assert set(np.unique(raster.values)) <= {-1, 0, 100}
    assert math.hypot(robot.poses[-1].pose.position.x - robot.sim.pose[0],
                      robot.poses[-1].pose.position.y - robot.sim.pose[1]) < 0.05


def test_a_scan_waits_for_the_odometry_of_its_stamp_and_is_placed_between_messages(ros):
    """The robot's rates: /odom at 20 Hz, the scan stamped between two odometry messages.

    Arriving before the later one, it waits, then is mapped at the interpolated pose.
    """
    robot = Robot(ros, profile="ideal")
    node = make_node(ros)
    bring_up(ros, node, robot)
    stamp = lambda t: seconds_to_time(t)  # noqa: E731
    scan = laser_scan_from_profile(robot.sim.last_scan, robot.sim.profile, stamp=stamp(1.0),
                                   frame_id="base_scan", scan_time=0.2)
    robot.odometry.publish(odometry_message(stamp(0.95), "odom", "base_footprint",
                                            (0.0, 0.0, 0.0)))
    ros.spin_for(0.1)
    robot.scan.publish(scan)
    ros.spin_for(0.2)
    assert node.mapped_scans == 0, "no odometry at its stamp yet: waiting"
    robot.odometry.publish(odometry_message(stamp(1.05), "odom", "base_footprint",
                                            (0.1, 0.0, 0.2)))
    ros.spin_until(lambda: node.mapped_scans == 1, 5.0, "the waiting scan to be mapped")
    ros.spin_until(lambda: robot.poses, 5.0, "/slam_pose")
    pose = pose_from_message(robot.poses[0].pose)
    assert pose == pytest.approx((0.05, 0.0, 0.1), abs=1e-6), "halfway between the two"
    # Two scans ahead of the odometry (the executor took them before it): both wait, both
    # are mapped, in order, when the odometry reaches them.
    for t in (1.1, 1.2):
        scan.header.stamp = stamp(t)
        scan.ranges = [r + 0.001 for r in scan.ranges]  # not a repeated scan
        robot.scan.publish(scan)
        ros.spin_for(0.1)
    robot.odometry.publish(odometry_message(stamp(1.25), "odom", "base_footprint",
                                            (0.2, 0.0, 0.2)))
    ros.spin_until(lambda: node.mapped_scans == 3, 5.0, "both waiting scans to be mapped")


def test_lidar_position_from_tf_static(ros):
    from amr_common.ros.tf import StaticTransformBroadcaster
    node = make_node(ros)
    broadcaster = StaticTransformBroadcaster(ros.node("robot_state_publisher"))
    broadcaster.send([planar_transform(seconds_to_time(0.0), "base_footprint", "base_scan",
                                       -0.032, 0.0, 0.0, 0.172)])
    assert node.trigger_configure().name == "SUCCESS"
    ros.spin_until(lambda: node.mapper.p["lidar_offset_x_m"] == -0.032, 5.0, "/tf_static")


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _as_pose(transform):
    from geometry_msgs.msg import Pose
    pose = Pose()
    pose.position.x, pose.position.y = transform.translation.x, transform.translation.y
    pose.orientation = transform.rotation
    return pose
