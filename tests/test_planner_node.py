"""The planner node with a fake /pose publisher.

It plans on the first localized pose, on /goal_pose and after relocalization; a latched /path
for late subscribers; bad goals.
"""
from __future__ import annotations

import pytest
from geometry_msgs.msg import PoseStamped as GoalPose
from nav_msgs.msg import Path
from rclpy.parameter import Parameter

from amr_common.ros.qos import LATCHED
from amr_common.ros.ros_conversions import path_points, seconds_to_time, time_to_seconds
from amr_planning.planner_node import PlannerNode


def make_node(ros, node_name="planner", **params):
    overrides = [Parameter(name, value=value) for name, value in params.items()]
    return ros.add(PlannerNode(node_name, context=ros.context, parameter_overrides=overrides))


class Graph:
    """The test's side: a particle filter (/pose), RViz (/goal_pose) and a /path listener."""

    def __init__(self, ros):
        from amr_msgs.msg import PoseStamped
        self.ros = ros
        self.PoseStamped = PoseStamped
        self.node = ros.node("fake_filter")
        self.pose = self.node.create_publisher(PoseStamped, "/pose", 10)
        self.goal = self.node.create_publisher(GoalPose, "/goal_pose", 10)
        self.paths = []
        self.node.create_subscription(Path, "/path", self.paths.append, LATCHED)

    def send_pose(self, t, x, y, localized=True):
        message = self.PoseStamped()
        message.header.stamp = seconds_to_time(t)
        message.header.frame_id = "map"
        message.pose.position.x, message.pose.position.y = x, y
        message.localized = localized
        self.pose.publish(message)

    def send_goal(self, x, y, frame_id="map"):
        message = GoalPose()
        message.header.frame_id = frame_id
        message.pose.position.x, message.pose.position.y = x, y
        self.goal.publish(message)


def bring_up(ros, node, graph):
    ros.bring_up(node, lambda: graph.node.count_subscribers("/pose") >= 1 and
                 graph.node.count_subscribers("/goal_pose") >= 1 and
                 node.count_subscribers("/path") >= 1)


def test_plans_once_on_the_first_localized_pose_and_latches_the_path(ros):
    node = make_node(ros, world="lab02")  # the world's goal: inner_far (0.6, -0.2)
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_pose(0.05, 1.0, -1.0, localized=False)
    ros.spin_for(0.3)
    assert graph.paths == []
    for k in range(2, 5):
        graph.send_pose(0.05 * k, 1.0, -1.0)
    ros.spin_until(lambda: len(graph.paths) == 1, 5.0, "the path")
    ros.spin_for(0.3)
    assert len(graph.paths) == 1, "plans once, not on every pose"
    path = graph.paths[0]
    points = path_points(path)
    assert path.header.frame_id == "map"
    assert time_to_seconds(path.header.stamp) == pytest.approx(0.10), "stamped like its pose"
    assert points[0] == pytest.approx((1.0, -1.0)) and points[-1] == pytest.approx((0.6, -0.2))
    assert node.last_plan.length_m == pytest.approx(7.4, abs=0.1)
    # A subscriber that comes late still gets the path (transient local).
    late = []
    ros.node("late_listener").create_subscription(Path, "/path", late.append, LATCHED)
    ros.spin_until(lambda: len(late) == 1, 5.0, "the latched path")
    assert len(late[0].poses) == len(path.poses)


def test_goal_pose_replans_and_bad_goals_give_an_empty_path(ros):
    node = make_node(ros, world="lab02", goal_name="north_west")
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_goal(1.0, 1.0)  # before localization: planned on the next localized pose
    ros.spin_for(0.2)
    assert graph.paths == []
    graph.send_pose(0.05, 1.0, -1.0)
    ros.spin_until(lambda: len(graph.paths) == 1, 5.0, "the path to the /goal_pose")
    assert path_points(graph.paths[0])[-1] == pytest.approx((1.0, 1.0))
    graph.send_goal(0.0, -0.8)  # on a wall
    ros.spin_until(lambda: len(graph.paths) == 2, 5.0, "the empty path")
    assert graph.paths[1].poses == [] and node.last_plan is None
    graph.send_goal(9.0, 9.0)  # outside the map
    ros.spin_until(lambda: len(graph.paths) == 3, 5.0, "another empty path")
    assert graph.paths[2].poses == []
    graph.send_goal(-1.0, 1.0, frame_id="odom")  # ignored with an error
    graph.send_goal(float("nan"), 1.0)
    ros.spin_for(0.3)
    assert len(graph.paths) == 3
    graph.send_goal(-1.0, 1.0)
    ros.spin_until(lambda: len(graph.paths) == 4, 5.0, "a path again")
    assert path_points(graph.paths[3])[-1] == pytest.approx((-1.0, 1.0))


def test_replans_from_the_relocalized_pose(ros):
    node = make_node(ros, world="maze_deadends")
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_pose(0.05, 0.2, 0.2)
    ros.spin_until(lambda: len(graph.paths) == 1, 5.0, "the first path")
    graph.send_pose(0.10, 0.2, 0.2, localized=False)  # lost (e.g. kidnapped)
    graph.send_pose(0.15, 1.4, 1.0)  # relocalized elsewhere
    ros.spin_until(lambda: len(graph.paths) == 2, 5.0, "the replanned path")
    assert path_points(graph.paths[1])[0] == pytest.approx((1.4, 1.0))
    assert path_points(graph.paths[1])[-1] == pytest.approx((3.0, 2.2))


def test_a_pose_stamped_far_in_the_future_does_not_stick(ros):
    """The planner keeps no stamp order that one bad stamp could block .

    After a pose stamped 11 days ahead, a /goal_pose plans from the newest pose that arrived,
    and the path carries that pose's stamp (the pursuit forgets a path stamped far beyond a
    lost pose).
    """
    node = make_node(ros, world="lab02")
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_pose(1e6, 1.0, -1.0)
    ros.spin_until(lambda: len(graph.paths) == 1, 5.0, "the first path")
    graph.send_pose(0.2, 1.0, -0.6)
    ros.spin_for(0.2)
    graph.send_goal(0.6, -0.2)
    ros.spin_until(lambda: len(graph.paths) == 2, 5.0, "the path to the new goal")
    assert path_points(graph.paths[1])[0] == pytest.approx((1.0, -0.6))
    assert time_to_seconds(graph.paths[1].header.stamp) == pytest.approx(0.2)


def test_no_goal_anywhere_gives_an_empty_path_and_a_start_in_a_wall_too(ros, tmp_path):
    world = tmp_path / "empty_room.yaml"
    world.write_text("boundary: [[0, 0], [2, 0], [2, 1], [0, 1]]\n")
    node = make_node(ros, world=str(world))
    graph = Graph(ros)
    bring_up(ros, node, graph)
    graph.send_pose(0.05, 0.5, 0.5)
    ros.spin_until(lambda: len(graph.paths) == 1, 5.0, "the empty path")
    assert graph.paths[0].poses == []


@pytest.mark.parametrize("params", [{"world": "lab99"}, {"goal": [1.0]},
                                    {"goal_name": "kitchen"}, {"algorithm": "dfs"},
                                    {"resolution_m": -0.02}])
def test_bad_parameters_fail_configure(ros, params):
    assert make_node(ros, **params).trigger_configure().name == "FAILURE"


def test_goal_parameter_and_integer_values(ros):
    node = make_node(ros, world="wide_maze", goal=[3, 2], resolution_m=1, clearance_weight=2)
    assert node.trigger_configure().name == "SUCCESS"
    assert node.goal == (3.0, 2.0) and node.planner.grid.resolution == 1.0
