"""The pure_pursuit node with a fake /pose and /path publisher.

The lockstep handover rule (one /cmd_vel per localized /pose, none otherwise), robot-mode timer
and staleness, and the zeros.
"""
from __future__ import annotations

import math

import pytest
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Path
from rclpy.parameter import Parameter

from amr_common.ros.qos import LATCHED
from amr_common.ros.ros_conversions import path_message, seconds_to_time, yaw_to_quaternion
from amr_control.pure_pursuit_node import PurePursuitNode

L_PATH = [[0.0, 0.0], [1.2, 0.0], [1.2, 0.8]]


def make_node(ros, node_name="pure_pursuit", **params):
    overrides = [Parameter(name, value=value) for name, value in params.items()]
    return ros.add(PurePursuitNode(node_name, context=ros.context, parameter_overrides=overrides))


class Graph:
    """The test's side: a particle filter (/pose), a planner (/path) and the robot (/cmd_vel)."""

    def __init__(self, ros, stamped=True):
        from amr_msgs.msg import PoseStamped
        self.PoseStamped = PoseStamped
        self.node = ros.node("fake_filter")
        self.pose = self.node.create_publisher(PoseStamped, "/pose", 10)
        self.path = self.node.create_publisher(Path, "/path", LATCHED)
        self.commands = []
        self.node.create_subscription(TwistStamped if stamped else Twist, "/cmd_vel",
                                      self.commands.append, 10)

    def send_pose(self, t, x=0.0, y=0.0, theta=0.0, localized=True):
        message = self.PoseStamped()
        message.header.stamp = seconds_to_time(t)
        message.header.frame_id = "map"
        message.pose.position.x, message.pose.position.y = x, y
        yaw_to_quaternion(theta, message.pose.orientation)
        message.localized = localized
        self.pose.publish(message)

    def send_path(self, points, t=0.0, frame_id="map"):
        self.path.publish(path_message(points, seconds_to_time(t), frame_id))


def twist(message):
    return message.twist if isinstance(message, TwistStamped) else message


def command(message):
    return twist(message).linear.x, twist(message).angular.z


def bring_up(ros, node, graph, path=None, poses=0):
    """Activate; then optionally send a path and `poses` localized poses, one by one.

    The poses are at (0, 0, 0), 50 ms apart; each waits for its answer.
    """
    ros.bring_up(node, lambda: graph.node.count_subscribers("/pose") >= 1 and
                 graph.node.count_subscribers("/path") >= 1 and
                 node.count_subscribers("/cmd_vel") >= 1)
    if path is not None:
        graph.send_path(path)
        ros.spin_until(lambda: node.pursuit.path is not None, 5.0, "the path")
    for k in range(1, poses + 1):
        graph.send_pose(0.05 * k)
        ros.spin_until(lambda: len(graph.commands) == k, 5.0, f"answer {k}")


def robot_mode_with_a_path(ros):
    """A robot-mode node (data_timeout 0.3 s, dt 0.05 s), active, with L_PATH."""
    node = make_node(ros, simulation=False, cmd_vel_stamped=False, data_timeout=0.3, dt=0.05)
    graph = Graph(ros, stamped=False)
    bring_up(ros, node, graph)
    graph.send_path(L_PATH)
    ros.spin_until(lambda: node.pursuit.path is not None, 5.0, "the path")
    return node, graph


def test_lockstep_answers_every_localized_pose_once_and_no_other(ros):
    node = make_node(ros)
    graph = Graph(ros)
    bring_up(ros, node, graph)
    for k in range(1, 4):  # not localized: the wall follower's turn
        graph.send_pose(0.05 * k, localized=False)
    ros.spin_for(0.3)
    assert graph.commands == []
    graph.send_pose(0.20)  # localized, no path yet: a zero command
    ros.spin_until(lambda: len(graph.commands) == 1, 5.0, "the first answer")
    assert command(graph.commands[0]) == (0.0, 0.0)
    graph.send_path(L_PATH, t=0.2)
    ros.spin_until(lambda: node.pursuit.path is not None, 5.0, "the path")
    for k in range(5, 25):
        graph.send_pose(0.05 * k)
        ros.spin_until(lambda: len(graph.commands) == k - 3, 5.0, f"answer {k}")
    ros.spin_for(0.2)
    assert len(graph.commands) == 21, "exactly one command per localized pose"
    stamps = [c.header.stamp.sec + c.header.stamp.nanosec * 1e-9 for c in graph.commands]
    assert stamps == pytest.approx([0.05 * k for k in range(4, 25)])
    assert command(graph.commands[-1])[0] > 0.1, "driving along the path"


def test_stops_with_zero_commands_at_the_end_of_the_path(ros):
    node = make_node(ros)
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_path([[0.0, 0.0], [0.5, 0.0]])
    ros.spin_until(lambda: node.pursuit.path is not None, 5.0, "the path")
    graph.send_pose(0.05, x=0.499)
    graph.send_pose(0.10, x=0.499)
    ros.spin_until(lambda: len(graph.commands) == 2, 5.0, "two answers")
    assert [command(c) for c in graph.commands] == [(0.0, 0.0), (0.0, 0.0)]
    assert node.pursuit.arrived


def test_out_of_order_and_unusable_poses_get_a_zero_answer(ros):
    node = make_node(ros)
    graph = Graph(ros)
    bring_up(ros, node, graph, L_PATH, poses=10)
    assert command(graph.commands[-1])[0] > 0.0
    graph.send_pose(0.2)  # older than the last answered pose
    ros.spin_until(lambda: len(graph.commands) == 11, 5.0, "the answer to a late pose")
    assert command(graph.commands[-1]) == (0.0, 0.0)
    message = graph.PoseStamped()
    message.header.stamp = seconds_to_time(1.0)
    message.localized = True
    message.pose.orientation.w = 0.0  # an all-zero quaternion: no heading
    graph.pose.publish(message)
    ros.spin_until(lambda: len(graph.commands) == 12, 5.0, "the answer to a bad pose")
    assert command(graph.commands[-1]) == (0.0, 0.0)
    graph.send_pose(1.05, x=float("nan"))
    ros.spin_until(lambda: len(graph.commands) == 13, 5.0, "the answer to a NaN pose")
    assert command(graph.commands[-1]) == (0.0, 0.0)


def test_deactivate_and_shutdown_send_zero(ros):
    node = make_node(ros)
    graph = Graph(ros)
    bring_up(ros, node, graph, L_PATH, poses=10)
    node.trigger_deactivate()
    ros.spin_until(lambda: len(graph.commands) == 11, 5.0, "the zero on deactivate")
    assert command(graph.commands[-1]) == (0.0, 0.0)
    assert graph.commands[-1].header.stamp == seconds_to_time(0.5), "the last pose's stamp"
    graph.send_pose(0.55)  # inactive: no answer
    ros.spin_for(0.3)
    assert len(graph.commands) == 11
    node.trigger_shutdown()
    ros.spin_until(lambda: len(graph.commands) == 12, 5.0, "the zero on shutdown")
    assert command(graph.commands[-1]) == (0.0, 0.0)


def test_robot_mode_zero_on_stale_pose_and_silence_after_losing_localization(ros):
    node, graph = robot_mode_with_a_path(ros)
    for k in range(10):  # fresh localized poses at 20 Hz: the timer drives
        graph.send_pose(0.05 * k)
        ros.spin_for(0.05)
    assert any(command(c)[0] > 0.0 for c in graph.commands)
    moving = len(graph.commands)
    ros.spin_for(0.8)  # no /pose: stale after 0.3 s
    after = [command(c) for c in graph.commands[moving:]]
    first_zero = after.index((0.0, 0.0))
    assert first_zero * 0.05 <= 0.3 + 0.3, "zero within data_timeout (+ timer slack)"
    assert all(c == (0.0, 0.0) for c in after[first_zero:]) and len(after) - first_zero >= 5
    graph.send_pose(1.5)
    ros.spin_until(lambda: command(graph.commands[-1]) != (0.0, 0.0), 5.0, "driving again")
    graph.send_pose(1.6, localized=False)  # lost: one zero, then the wall follower's turn
    ros.spin_until(lambda: not node._handover.localized, 5.0, "the loss")
    ros.spin_for(0.2)
    assert command(graph.commands[-1]) == (0.0, 0.0)
    count = len(graph.commands)
    ros.spin_for(0.5)
    assert len(graph.commands) == count, "silent while not localized"
    assert node.pursuit.path is None, "forgets the path: the planner replans"


def test_a_path_in_another_frame_is_ignored_and_an_empty_one_stops(ros):
    node = make_node(ros)
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_path(L_PATH, frame_id="odom")
    ros.spin_for(0.3)
    assert node.pursuit.path is None
    graph.send_path(L_PATH)
    ros.spin_until(lambda: node.pursuit.path is not None, 5.0, "the path")
    graph.send_path([])
    ros.spin_until(lambda: node.pursuit.path is None, 5.0, "the empty path")


@pytest.mark.parametrize("params", [{"dt": -1.0}, {"angular_sign": 2},
                                    {"min_lookahead_m": 0.5}, {"data_timeout": 0.0}])
def test_bad_parameters_fail_configure(ros, params):
    assert make_node(ros, **params).trigger_configure().name == "FAILURE"


def test_integer_values_are_accepted_for_float_parameters(ros):
    node = make_node(ros, max_linear_speed_mps=1, dt=1)
    assert node.trigger_configure().name == "SUCCESS"
    assert node.pursuit.params["max_linear_speed_mps"] == pytest.approx(0.22)
    assert math.isclose(node.dt, 1.0)


def scan_publisher(graph):
    """The test's /scan publisher (best effort, as a LiDAR driver's)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import LaserScan
    return graph.node.create_publisher(LaserScan, "/scan", QoSProfile(
        depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))


def publish_scan(publisher, ranges) -> None:
    """A 360-ray scan from ray 0 straight ahead, counter-clockwise (the LDS-01's)."""
    from amr_common.ros.ros_conversions import laser_scan
    publisher.publish(laser_scan(ranges, stamp=seconds_to_time(0.0), frame_id="base_scan",
                                 angle_min=0.0, angle_increment=2 * math.pi / 360,
                                 range_min=0.12, range_max=3.5, scan_time=0.2))


def test_a_close_obstacle_on_the_scan_slows_the_robot(ros):
    fast = make_node(ros, scan_topic="/no_scan")  # sees no scan: no slow-down
    slow = make_node(ros, "pure_pursuit_slow", cmd_vel_topic="/cmd_slow")
    graph = Graph(ros)
    slowed = []
    graph.node.create_subscription(TwistStamped, "/cmd_slow", slowed.append, 10)
    scans = scan_publisher(graph)
    bring_up(ros, fast, graph, L_PATH)
    ros.bring_up(slow, lambda: slow.count_publishers("/scan") >= 1)
    ros.spin_until(lambda: slow.pursuit.path is not None, 5.0, "the latched path")
    # 12.5 cm to a wall on the left: 2 cm footprint clearance for the second node only.
    publish_scan(scans, [3.0] * 89 + [0.125] + [3.0] * 270)
    ros.spin_until(lambda: slow._scan[0] is not None, 5.0, "the scan")
    for k in range(1, 21):
        graph.send_pose(0.05 * k)
        ros.spin_until(lambda: len(graph.commands) == k and len(slowed) == k, 5.0, f"answer {k}")
    v_fast, v_slow = command(graph.commands[-1])[0], command(slowed[-1])[0]
    assert v_fast == pytest.approx(0.22)
    assert v_slow == pytest.approx(0.22 * 0.02 / 0.06, rel=0.05)


def test_one_pose_stamped_far_in_the_future_does_not_stop_the_pursuit_for_good(ros):
    """Lockstep: after a pose stamped 11 days ahead, valid poses are followed again.

    The pose after it is answered with zero (older than the previous one by more than
    data_timeout: a jump back in time, or the previous stamp was bogus), the next ones
    normally; a new /path is followed too. The old node answered zero for good.
    """
    node = make_node(ros)
    graph = Graph(ros)
    bring_up(ros, node, graph, L_PATH, poses=10)
    graph.send_pose(1e6)
    ros.spin_until(lambda: len(graph.commands) == 11, 5.0, "the answer to the future pose")
    graph.send_path(L_PATH, t=0.5)
    ros.spin_until(lambda: node.pursuit.path is not None, 5.0, "the new path")
    for k in range(11, 16):
        graph.send_pose(0.05 * k)
        ros.spin_until(lambda: len(graph.commands) == k + 1, 5.0, f"answer {k}")
    after = [command(c) for c in graph.commands[11:]]
    assert after[0] == (0.0, 0.0), "the first pose after the jump: zero (it could be stale)"
    assert all(v > 0.0 for v, _ in after[1:]), after


def test_a_pose_far_in_the_past_gets_zero_and_the_stream_goes_on(ros):
    node = make_node(ros, data_timeout=0.3)
    graph = Graph(ros)
    bring_up(ros, node, graph, L_PATH, poses=10)
    graph.send_pose(0.1)  # 0.4 s older than the newest: stale
    graph.send_pose(0.55)
    ros.spin_until(lambda: len(graph.commands) == 12, 5.0, "two answers")
    assert command(graph.commands[10]) == (0.0, 0.0)
    assert command(graph.commands[11])[0] > 0.0


def test_robot_mode_recovers_from_a_future_stamp_and_ignores_stale_poses(ros):
    node, graph = robot_mode_with_a_path(ros)
    graph.send_pose(0.05)
    ros.spin_until(lambda: graph.commands and command(graph.commands[-1])[0] > 0.0, 5.0,
                   "driving")
    graph.send_pose(1e6)
    ros.spin_for(0.1)
    for k in range(2, 8):  # fresh poses with valid stamps, at 20 Hz
        graph.send_pose(0.05 * k)
        ros.spin_for(0.05)
    ros.spin_for(0.05)
    assert command(graph.commands[-1])[0] > 0.0, "driving on the valid poses again"
    count = len(graph.commands)
    graph.send_pose(0.2, x=0.3)  # a stale pose arriving late: not used as the newest
    ros.spin_for(0.1)
    assert node._latest[1] == int(0.35e9)
    assert len(graph.commands) > count


def test_a_path_stamped_in_the_future_is_forgotten_when_localization_is_lost(ros):
    node = make_node(ros)
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_path(L_PATH, t=1e6)  # planned from a bogus future pose
    ros.spin_until(lambda: node.pursuit.path is not None, 5.0, "the path")
    graph.send_pose(0.05)
    ros.spin_until(lambda: len(graph.commands) == 1, 5.0, "the answer")
    graph.send_pose(0.10, localized=False)
    ros.spin_until(lambda: not node._handover.localized, 5.0, "the loss")
    assert node.pursuit.path is None, "a stale path is not followed after relocalization"


def test_an_obstacle_in_the_way_on_the_scan_halts_the_robot(ros):
    node = make_node(ros)
    graph = Graph(ros)
    scans = scan_publisher(graph)
    bring_up(ros, node, graph, L_PATH)
    ros.spin_until(lambda: node.count_publishers("/scan") >= 1, 5.0, "the scan publisher")
    # Something 12.5 cm straight ahead (2 cm from the footprint) that the map lacks.
    publish_scan(scans, [0.125] + [3.0] * 359)
    ros.spin_until(lambda: node._scan[0] is not None, 5.0, "the scan")
    for k in range(1, 11):
        graph.send_pose(0.05 * k)
        ros.spin_until(lambda: len(graph.commands) == k, 5.0, f"answer {k}")
    assert all(command(message) == (0.0, 0.0) for message in graph.commands)
    assert node.pursuit.state == "blocked"
