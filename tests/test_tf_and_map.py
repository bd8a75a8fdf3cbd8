"""/tf, /tf_static, /map and /map_markers of the simulator and of amr_map_publisher, over DDS.

TF as REP 105 and the Burger's bringup: base_footprint -> base_scan (static, at the profile's
LiDAR position), odom -> base_footprint with each odometry message, plus the simulator's truth
(map -> base_footprint_truth) and, when asked, the perfect map -> odom. The map must match the
world: free cells free, wall cells occupied.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from amr_common import tf
from amr_common.map_messages import grid_values
from amr_common.map_publisher import MapPublisherNode
from amr_common.map_raster import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    Raster,
    points_in_polygon,
    rasterize_world,
)
from amr_common.qos import LATCHED
from amr_common.robot import LIDAR_HEIGHT, LIDAR_OFFSET_X
from amr_common.ros_conversions import pose_from_message, time_to_nanoseconds
from amr_common.world import World
from tests.test_simulator_node import Probe, start_simulator

JAZZY_TFMESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def planar(t: TransformStamped) -> tuple[float, float, float]:
    q = t.transform.rotation
    return (t.transform.translation.x, t.transform.translation.y,
            math.atan2(2.0 * q.w * q.z, 1.0 - 2.0 * q.z * q.z))


def by_child(message: TFMessage) -> dict[str, TransformStamped]:
    return {t.child_frame_id: t for t in message.transforms}


class FrameProbe:
    def __init__(self, ros) -> None:
        self.node = ros.node("frame_probe")
        self.tf: list[TFMessage] = []
        self.static: list[TFMessage] = []
        self.maps: list[OccupancyGrid] = []
        self.markers: list[MarkerArray] = []
        self.node.create_subscription(TFMessage, "/tf", self.tf.append, tf.TF_QOS)
        self.node.create_subscription(TFMessage, "/tf_static", self.static.append,
                                      tf.TF_STATIC_LISTENER_QOS)
        self.node.create_subscription(OccupancyGrid, "/map", self.maps.append, LATCHED)
        self.node.create_subscription(MarkerArray, "/map_markers", self.markers.append, LATCHED)


def test_tfmessage_has_jazzys_type_hash(ros):
    node = ros.node("tf_hash")
    node.create_publisher(TFMessage, "/tf_hash_probe", 10)
    infos = node.get_publishers_info_by_topic("/tf_hash_probe")
    assert [str(i.topic_type_hash) for i in infos] == [JAZZY_TFMESSAGE_HASH]


def start_with_frames(ros, **parameters):
    probe, frames = Probe(ros), FrameProbe(ros)
    node = start_simulator(ros, probe, activate=False, **parameters)
    ros.spin_until(lambda: node._tf._tf.get_subscription_count() > 0,
                   message="the /tf subscriber to be matched")
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    return node, probe, frames


def check_static_lidar(frames: FrameProbe, lidar_x: float) -> None:
    assert len(frames.static) == 1
    (static,) = frames.static[0].transforms
    assert (static.header.frame_id, static.child_frame_id) == ("base_footprint", "base_scan")
    translation = static.transform.translation
    assert (translation.x, translation.y, translation.z) == pytest.approx(
        (lidar_x, 0.0, LIDAR_HEIGHT))
    assert static.transform.rotation.w == pytest.approx(1.0)


def test_lockstep_tf_moves_with_each_step_and_matches_odometry_and_truth(ros):
    node, probe, frames = start_with_frames(ros, profile="turtlebot3",
                                            map_to_odom_from_truth=True)
    ros.spin_until(lambda: frames.tf, message="the /tf of the first measurement")
    for _ in range(15):
        before = len(frames.tf)
        probe.send(0.2, 0.8)
        ros.spin_until(lambda: len(frames.tf) > before, timeout=5.0, message="a /tf per step")
    ros.spin_until(lambda: frames.static and len(probe.received["odometry"]) == 16
                   and len(probe.received["ground_truth"]) == 16)
    ros.spin_for(0.1)  # nothing more may come
    check_static_lidar(frames, LIDAR_OFFSET_X)
    # One /tf per odometry message (the first measurement included), same stamps and poses.
    assert len(frames.tf) == len(probe.received["odometry"]) == 16
    for message, odometry, truth in zip(frames.tf, probe.received["odometry"],
                                        probe.received["ground_truth"]):
        transforms = by_child(message)
        assert set(transforms) == {"base_footprint", "base_footprint_truth", "odom"}
        stamps = {time_to_nanoseconds(t.header.stamp) for t in message.transforms}
        assert stamps == {time_to_nanoseconds(odometry.header.stamp)}
        odom_base, map_truth = transforms["base_footprint"], transforms["base_footprint_truth"]
        assert odom_base.header.frame_id == "odom" and map_truth.header.frame_id == "map"
        assert planar(odom_base) == pytest.approx(pose_from_message(odometry.pose.pose), abs=1e-9)
        assert planar(map_truth) == pytest.approx(pose_from_message(truth.pose.pose), abs=1e-9)
        # map -> odom -> base_footprint lands on the true pose.
        chained = tf.compose(planar(transforms["odom"]), planar(odom_base))
        assert chained == pytest.approx(planar(map_truth), abs=1e-9)
    assert planar(map_truth)[:2] != pytest.approx(planar(by_child(frames.tf[0])[
        "base_footprint_truth"])[:2], abs=0.05)  # the robot moved


@pytest.mark.slow
def test_real_time_tf_follows_odom_at_its_rate_and_wall_clock(ros):
    import time
    node, probe, frames = start_with_frames(ros, profile="turtlebot3", mode="realtime")
    start = time.monotonic()
    ros.spin_until(lambda: len(frames.tf) >= 21, timeout=10.0, message="a second of /tf")
    wall = time.monotonic() - start
    check_static_lidar(frames, LIDAR_OFFSET_X)
    assert all(set(by_child(m)) == {"base_footprint", "base_footprint_truth"}
               for m in frames.tf)  # no map -> odom unless asked
    tf_stamps = [time_to_nanoseconds(m.transforms[0].header.stamp) for m in frames.tf]
    odom_stamps = [time_to_nanoseconds(m.header.stamp) for m in probe.received["odom"]]
    assert tf_stamps[:len(odom_stamps)] == odom_stamps[:len(tf_stamps)]
    periods = np.diff(tf_stamps) * 1e-9
    assert np.all(periods == pytest.approx(0.05, abs=1e-6))  # /odom's 20 Hz in sim time
    # Real time: 20 messages of 50 ms took about 1 s of wall clock (loaded machine: generous).
    assert 0.8 <= wall <= 3.0


def test_map_matches_the_world_and_markers_draw_its_walls(ros):
    node, probe, frames = start_with_frames(ros, world="lab02", map_resolution=0.04)
    ros.spin_until(lambda: frames.maps and frames.markers, message="/map and /map_markers")
    grid = frames.maps[0]
    assert grid.header.frame_id == "map" and grid.info.resolution == pytest.approx(0.04)
    world = World.load("lab02")
    raster = Raster(grid_values(grid), grid.info.resolution,
                    (grid.info.origin.position.x, grid.info.origin.position.y))
    check_raster_matches_world(raster, world)
    (walls,) = [m for m in frames.markers[0].markers if m.ns == "walls"]
    assert walls.type == Marker.TRIANGLE_LIST and len(walls.points) == 6 * len(world.segments)
    # A late subscriber still gets the latched map.
    late = ros.node("late_map_reader")
    got = []
    late.create_subscription(OccupancyGrid, "/map", got.append, LATCHED)
    ros.spin_until(lambda: got, message="the latched /map for a late subscriber")
    assert grid_values(got[0]).tolist() == grid_values(grid).tolist()


def _in(polygon, x: float, y: float) -> bool:
    return bool(points_in_polygon(polygon, np.array([x]), np.array([y]))[0])


def check_raster_matches_world(raster: Raster, world: World) -> None:
    values = raster.values
    cx, cy = raster.centres()
    centres = np.column_stack([cx.ravel(), cy.ravel()])
    clearance = world.clearances(centres).reshape(values.shape)
    inside = np.array([world.contains(x, y) for x, y in centres]).reshape(values.shape)
    res = raster.resolution
    outside = np.array([not _in(world.boundary, x, y) for x, y in centres]).reshape(values.shape)
    # Free space at least a cell from any wall is free; outside the boundary is unknown, inside
    # an obstacle occupied.
    assert np.all(values[inside & (clearance > res)] == FREE)
    assert np.all(values[outside & (clearance > res)] == UNKNOWN)
    assert np.all(values[~inside & ~outside & (clearance > res)] == OCCUPIED)
    # Every point on every wall lies in an occupied cell.
    for x1, y1, x2, y2 in world.segments:
        for t in np.linspace(0.0, 1.0, 25):
            row, col = raster.cell_of(x1 + t * (x2 - x1), y1 + t * (y2 - y1))
            assert values[row, col] == OCCUPIED
    assert 0 < np.count_nonzero(values == OCCUPIED) < np.count_nonzero(values == FREE)


@pytest.mark.parametrize("world", ["room_obstacles", "maze_deadends"])
def test_raster_of_bundled_worlds(world):
    loaded = World.load(world)
    raster = rasterize_world(loaded, 0.05)
    check_raster_matches_world(raster, loaded)
    # Obstacles (holes) are solid: their inside is occupied too.
    if loaded.holes:
        hole = loaded.holes[0]
        row, col = raster.cell_of(*hole.mean(axis=0))
        assert raster.values[row, col] == OCCUPIED


def test_raster_rejects_a_bad_resolution():
    for bad in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError):
            rasterize_world(World.load("lab02"), bad)


def test_map_publisher_serves_a_course_map_json(ros, tmp_path):
    path = tmp_path / "course_map.json"
    path.write_text(json.dumps({"metric": {
        "boundary": [[0, 0], [2, 0], [2, 1], [0, 1]],
        "holes": [[[0.8, 0.4], [1.2, 0.4], [1.2, 0.6], [0.8, 0.6]]]}}))
    node = ros.add(MapPublisherNode(context=ros.context, parameter_overrides=[
        Parameter("world", value=str(path)), Parameter("resolution", value=0.1)]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    frames = FrameProbe(ros)
    ros.spin_until(lambda: frames.maps and frames.markers, message="the latched map")
    grid = frames.maps[0]
    assert grid.info.resolution == pytest.approx(0.1)
    raster = Raster(grid_values(grid), 0.1,
                    (grid.info.origin.position.x, grid.info.origin.position.y))
    check_raster_matches_world(raster, World.load(path))


@pytest.mark.parametrize("parameters, reason", [
    ({"world": "/no/such/map.json"}, "missing file"),
    ({"resolution": 0.0}, "zero resolution"),
    ({"resolution": "fine"}, "not a number"),
])
def test_map_publisher_refuses_bad_input(ros, parameters, reason):
    overrides = [Parameter(name, value=value) for name, value in parameters.items()]
    try:
        node = MapPublisherNode(context=ros.context, parameter_overrides=overrides)
    except Exception:  # a string for a double parameter is refused at declaration
        assert reason == "not a number"
        return
    ros.add(node)
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE, reason


def burger_static_transforms(stamp, lidar_x: float = -0.032) -> TFMessage:
    """The Burger's robot_state_publisher: base_footprint -> base_link -> base_scan."""
    return TFMessage(transforms=[
        tf.planar_transform(stamp, "base_footprint", "base_link", 0.0, 0.0, 0.0, 0.010),
        tf.planar_transform(stamp, "base_link", "base_scan", lidar_x, 0.0, 0.0, 0.172)])


def test_static_tree_resolves_chains_and_ignores_broken_transforms():
    tree = tf.StaticTransformTree()
    tree.add(burger_static_transforms(None).transforms)
    offset = tree.offset("base_footprint", "base_scan")
    assert (offset.x, offset.y, offset.z, offset.yaw) == pytest.approx((-0.032, 0, 0.182, 0))
    assert tree.offset("base_scan", "base_footprint") is None  # only parent -> child
    assert tree.offset("map", "base_scan") is None
    rotated = tf.planar_transform(None, "base_link", "base_scan", 0.1, 0.0, math.pi / 2)
    broken = tf.planar_transform(None, "base_link", "laser", float("nan"), 0.0, 0.0)
    tree.add([rotated, broken])
    assert tree.offset("base_footprint", "laser") is None
    assert tree.offset("base_footprint", "base_scan").yaw == pytest.approx(math.pi / 2)
    # compose / inverse / map_to_odom agree.
    a, b = (1.0, 2.0, 0.5), (-0.3, 0.4, -2.0)
    assert tf.compose(tf.inverse(a), tf.compose(a, b)) == pytest.approx(b)
    assert tf.compose(tf.map_to_odom(a, b), b) == pytest.approx(a)


def test_wall_follower_takes_the_lidar_position_from_tf_static(ros):
    from amr_control.wall_follower_node import WallFollowerNode
    robot = ros.node("burger_state_publisher")
    static = tf.StaticTransformBroadcaster(robot)
    static.send(burger_static_transforms(robot.get_clock().now().to_msg()).transforms)
    node = ros.add(WallFollowerNode(context=ros.context, parameter_overrides=[
        Parameter("lidar_offset_x_m", value=0.05)]))  # a wrong fallback: /tf_static wins
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.controller.lidar_offset_x_m == 0.05
    ros.spin_until(lambda: node.controller.lidar_offset_x_m == pytest.approx(-0.032),
                   message="the LiDAR position from the latched /tf_static")
    # Once the controller has computed, a moved LiDAR applies from the next configure only.
    node._compute([1.0] * 360, 0.0, 0.0)
    static.send([tf.planar_transform(None, "base_link", "base_scan", -0.05, 0.0, 0.0, 0.172)])
    ros.spin_until(lambda: node._lidar_offset_from_tf == pytest.approx(-0.05),
                   message="the moved LiDAR")
    assert node.controller.lidar_offset_x_m == pytest.approx(-0.032)
    assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.controller.lidar_offset_x_m == pytest.approx(-0.05)


def test_wall_follower_keeps_its_parameter_without_tf_static(ros):
    from amr_control.wall_follower_node import WallFollowerNode
    node = ros.add(WallFollowerNode(context=ros.context, parameter_overrides=[
        Parameter("lidar_offset_x_m", value=-0.032)]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    ros.spin_for(0.3)
    assert node.controller.lidar_offset_x_m == -0.032


def test_generated_type_descriptions_carry_jazzys_hashes():
    import sys
    from pathlib import Path
    share = Path(sys.prefix) / "share" / "tf2_msgs" / "msg"
    tf2_error = "RIHS01_db2485e7d6a0ec75bf087e058ee45df682acc3a621ca7780503d10aac141809a"
    expected = {"TFMessage": JAZZY_TFMESSAGE_HASH, "TF2Error": tf2_error}
    for name, hash_string in expected.items():
        description = json.loads((share / f"{name}.json").read_text())
        assert description["type_hashes"][0] == {"type_name": f"tf2_msgs/msg/{name}",
                                                 "hash_string": hash_string}


def test_build_skips_tf2_msgs_an_apt_ros_provides(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path
    repo = Path(__file__).resolve().parent.parent
    fake = tmp_path / "opt_ros" / "tf2_msgs"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    env = dict(os.environ, PYTHONPATH=str(fake.parent))
    result = subprocess.run([sys.executable, str(repo / "tools" / "build_amr_msgs.py"),
                             str(repo / "third_party" / "tf2_msgs"), "--unless-provided"],
                            env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0
    assert f"tf2_msgs is provided by {fake}" in result.stdout
