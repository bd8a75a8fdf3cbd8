"""TF without tf2_ros: tf2_msgs with Jazzy's type hash, the simulator's frames, the static tree.

The frames are REP 105's and the Burger bringup's: base_footprint -> base_scan (static, at the
profile's LiDAR position), odom -> base_footprint with each odometry message, plus the
simulator's truth (map -> base_footprint_truth) and, when asked, the perfect map -> odom. The
wall follower takes the LiDAR position from /tf_static.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from tf2_msgs.msg import TFMessage

from amr_common.robot import LIDAR_HEIGHT, LIDAR_OFFSET_X
from amr_common.ros import tf
from amr_common.ros.ros_conversions import pose_from_message, time_to_nanoseconds
from tests.tf_map_helpers import FrameProbe, by_child, planar, start_with_frames

JAZZY_TFMESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def test_tfmessage_has_jazzys_type_hash(ros):
    node = ros.node("tf_hash")
    node.create_publisher(TFMessage, "/tf_hash_probe", 10)
    infos = node.get_publishers_info_by_topic("/tf_hash_probe")
    assert [str(i.topic_type_hash) for i in infos] == [JAZZY_TFMESSAGE_HASH]


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
