"""The wall_follower node: lockstep answers, robot-mode timer, and every path that must stop."""
import math

import pytest
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan

from amr_control.wall_follower_node import WallFollowerNode

BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)


def make_node(ros, node_name="wall_follower", **params):
    overrides = [Parameter(name, value=value) for name, value in params.items()]
    return ros.add(WallFollowerNode(node_name, context=ros.context,
                                    parameter_overrides=overrides))


def scan_msg(stamp_ns, rays=360, value=1.0):
    msg = LaserScan()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = "base_scan"
    msg.angle_min = 0.0
    msg.angle_increment = 2 * math.pi / rays
    msg.angle_max = msg.angle_increment * (rays - 1)
    msg.range_min, msg.range_max = 0.12, 3.5
    msg.ranges = [value] * rays
    return msg


def odom_msg(stamp_ns, v=0.0, w=0.0):
    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, w
    return msg


class Robot:
    """The test's side of the graph: publishes /odometry and /scan, records /cmd_vel."""

    def __init__(self, ros, stamped=True):
        self.node = ros.node("fake_robot")
        self.odometry = self.node.create_publisher(Odometry, "/odometry", 10)
        self.scan = self.node.create_publisher(LaserScan, "/scan", BEST_EFFORT)
        self.commands = []
        self.node.create_subscription(TwistStamped if stamped else Twist, "/cmd_vel",
                                      self.commands.append, 10)

    def send(self, stamp_ns, **kwargs):
        self.odometry.publish(odom_msg(stamp_ns, **kwargs))
        self.scan.publish(scan_msg(stamp_ns))


def twist_of(msg):
    return msg.twist if isinstance(msg, TwistStamped) else msg


def bring_up(ros, node, robot):
    assert node.trigger_configure().name == "SUCCESS"
    assert node.trigger_activate().name == "SUCCESS"
    # Wait for discovery both ways before measuring anything.
    ros.spin_until(lambda: node.count_publishers("/scan") >= 1 and
                   robot.node.count_subscribers("/cmd_vel") >= 1 and
                   node.count_subscribers("/scan") >= 1, 10.0, "discovery")
    ros.spin_for(0.2)


def test_simulation_mode_answers_each_synchronized_set_once_with_its_stamp(ros):
    node = make_node(ros, controller="tests.controllers:ConstantController")
    robot = Robot(ros)
    bring_up(ros, node, robot)
    for k in range(1, 6):
        robot.send(k * 50_000_000, v=0.1, w=0.2)
        ros.spin_until(lambda: len(robot.commands) == k, 5.0, f"command {k}")
    stamps = [c.header.stamp.sec * 10**9 + c.header.stamp.nanosec for c in robot.commands]
    assert stamps == [k * 50_000_000 for k in range(1, 6)]
    assert all(twist_of(c).linear.x == pytest.approx(0.1) and
               twist_of(c).angular.z == pytest.approx(0.5) for c in robot.commands)
    assert node.controller.calls[-1] == (360, pytest.approx(0.1), pytest.approx(0.2))
    assert node.controller.geometry[2:] == (pytest.approx(0.12), pytest.approx(3.5))


def test_non_finite_and_absurd_controller_outputs_never_reach_the_robot(ros):
    node = make_node(ros, controller="tests.controllers:NanController")
    robot = Robot(ros)
    bring_up(ros, node, robot)
    robot.send(50_000_000)
    ros.spin_until(lambda: len(robot.commands) == 1, 5.0, "a command")
    assert (twist_of(robot.commands[0]).linear.x, twist_of(robot.commands[0]).angular.z) == (0, 0)

    huge = make_node(ros, "wall_follower_huge", controller="tests.controllers:HugeController",
                     cmd_vel_topic="/cmd_vel_huge")
    received = []
    robot.node.create_subscription(TwistStamped, "/cmd_vel_huge", received.append, 10)
    bring_up(ros, huge, robot)
    robot.send(100_000_000)
    ros.spin_until(lambda: len(received) == 1, 5.0, "a clamped command")
    assert twist_of(received[0]).linear.x == pytest.approx(0.22)
    assert twist_of(received[0]).angular.z == pytest.approx(-2.84)


def test_deactivation_publishes_zero(ros):
    node = make_node(ros, controller="tests.controllers:ConstantController")
    robot = Robot(ros)
    bring_up(ros, node, robot)
    robot.send(50_000_000)
    ros.spin_until(lambda: len(robot.commands) == 1, 5.0, "a command")
    node.trigger_deactivate()
    ros.spin_until(lambda: len(robot.commands) == 2, 5.0, "the zero command")
    assert twist_of(robot.commands[-1]).linear.x == 0.0
    assert twist_of(robot.commands[-1]).angular.z == 0.0
    # Simulation mode needs no clock: the zero carries the last measurement's (simulated) stamp.
    last = robot.commands[-1].header.stamp
    assert (last.sec, last.nanosec) == (0, 50_000_000)
    robot.send(100_000_000)  # inactive: no more commands
    ros.spin_for(0.5)
    assert len(robot.commands) == 2


def test_robot_mode_commands_on_a_timer_and_stops_when_scan_stops(ros):
    node = make_node(ros, controller="tests.controllers:ConstantController", simulation=False,
                     cmd_vel_stamped=False, angular_sign=-1, data_timeout=0.5, dt=0.05)
    robot = Robot(ros, stamped=False)
    bring_up(ros, node, robot)
    stamp = [0]

    def feed(seconds, with_scan=True):
        end = node.get_clock().now().nanoseconds + int(seconds * 1e9)
        while node.get_clock().now().nanoseconds < end:
            stamp[0] += 50_000_000
            robot.odometry.publish(odom_msg(stamp[0]))
            if with_scan:
                robot.scan.publish(scan_msg(stamp[0]))
            ros.spin_for(0.05)

    feed(1.0)
    moving = [c for c in robot.commands if c.linear.x != 0.0]
    assert len(moving) >= 10, "the timer computes about every dt while data flows"
    assert moving[-1].angular.z == pytest.approx(-0.5), "angular_sign flips the turn"
    count_before_stop = len(robot.commands)
    feed(1.2, with_scan=False)  # /odometry alone cannot form a synchronized set
    after = robot.commands[count_before_stop:]
    first_zero = next(i for i, c in enumerate(after) if c.linear.x == 0.0 and c.angular.z == 0.0)
    assert first_zero * 0.05 <= 0.5 + 0.3, "zero within data_timeout (+ timer slack)"
    assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in after[first_zero:]), \
        "keeps commanding zero while data is stale"


def pose_msg(stamp_ns, localized):
    from amr_msgs.msg import PoseStamped
    pose = PoseStamped()
    pose.header.stamp.sec, pose.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    pose.header.frame_id = "map"
    pose.localized = localized
    return pose


def test_lockstep_handover_publishes_nothing_while_localized_and_resumes_when_lost(ros):
    """In lockstep the follower is silent while localized and answers when lost.

    In lockstep the pure pursuit answers localized poses: the follower must be silent then
    (two answers per step would advance the simulator twice) and answer again when lost.
    """
    from amr_msgs.msg import PoseStamped
    node = make_node(ros, controller="tests.controllers:ConstantController",
                     enable_localization=True)
    robot = Robot(ros)
    pose_pub = robot.node.create_publisher(PoseStamped, "/pose", 10)
    bring_up(ros, node, robot)
    localized = [False, True, True, False, True, False]
    answered = []
    for k, flag in enumerate(localized, start=1):
        stamp = k * 50_000_000
        before = len(robot.commands)
        pose_pub.publish(pose_msg(stamp, flag))
        robot.send(stamp, v=0.1)
        if flag:
            ros.spin_for(0.3)
        else:
            ros.spin_until(lambda: len(robot.commands) == before + 1, 5.0, f"command {k}")
        answered.append(len(robot.commands) - before)
    assert answered == [0 if flag else 1 for flag in localized]
    stamps = [c.header.stamp.nanosec for c in robot.commands]
    assert stamps == [50_000_000, 200_000_000, 300_000_000], "each answer carries its set's stamp"
    assert all(twist_of(c).linear.x == pytest.approx(0.1) for c in robot.commands)
    assert len(node.controller.calls) == len(localized), "the controller saw every set"


def test_stop_when_localized_false_keeps_exploring(ros):
    from amr_msgs.msg import PoseStamped
    node = make_node(ros, controller="tests.controllers:ConstantController",
                     enable_localization=True, stop_when_localized=False)
    robot = Robot(ros)
    pose_pub = robot.node.create_publisher(PoseStamped, "/pose", 10)
    bring_up(ros, node, robot)
    for k in range(1, 4):
        pose_pub.publish(pose_msg(k * 50_000_000, True))
        robot.send(k * 50_000_000, v=0.1)
        ros.spin_until(lambda: len(robot.commands) == k, 5.0, f"command {k}")
    assert all(twist_of(c).linear.x == pytest.approx(0.1) for c in robot.commands)


def test_robot_mode_handover_sends_one_zero_then_nothing_then_resumes(ros):
    from amr_msgs.msg import PoseStamped
    node = make_node(ros, controller="tests.controllers:ConstantController",
                     enable_localization=True, simulation=False, dt=0.05)
    robot = Robot(ros)
    pose_pub = robot.node.create_publisher(PoseStamped, "/pose", 10)
    bring_up(ros, node, robot)
    stamp = [0]

    def feed(seconds, localized):
        end = node.get_clock().now().nanoseconds + int(seconds * 1e9)
        while node.get_clock().now().nanoseconds < end:
            stamp[0] += 50_000_000
            pose_pub.publish(pose_msg(stamp[0], localized))
            robot.send(stamp[0])
            ros.spin_for(0.05)

    feed(0.6, False)
    assert any(twist_of(c).linear.x > 0 for c in robot.commands), "wall following"
    count = len(robot.commands)
    feed(0.8, True)
    handed_over = robot.commands[count:]
    moving_after = [c for c in handed_over if twist_of(c).linear.x != 0.0]
    zeros = [c for c in handed_over if twist_of(c).linear.x == 0.0 and twist_of(c).angular.z == 0]
    # Up to a few moving commands computed on sets from before the localized ones arrived,
    # then exactly one zero, then silence.
    assert len(zeros) == 1 and handed_over[-1] is zeros[0], [twist_of(c) for c in handed_over]
    assert len(moving_after) <= 3
    count = len(robot.commands)
    feed(0.6, False)
    assert any(twist_of(c).linear.x > 0 for c in robot.commands[count:]), "resumed when lost"


def test_bad_parameters_fail_configure_with_a_reason(ros):
    node = make_node(ros, controller="tests.controllers:ConstantController", dt=-1.0)
    assert node.trigger_configure().name == "FAILURE"
    broken = make_node(ros, "broken", controller="no_such_module:Nothing")
    assert broken.trigger_configure().name == "FAILURE"


def test_ctrl_c_on_the_executable_sends_a_final_zero(ros):
    """The TurtleBot3 keeps its last command: Ctrl-C must leave a zero behind."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parent.parent
    robot = Robot(ros, stamped=True)
    env = dict(os.environ, PYTHONPATH=str(repo))
    process = subprocess.Popen(
        [str(Path(sys.executable).parent / "amr_wall_follower"), "--ros-args",
         "-p", "autostart:=true", "-p", "simulation:=false",
         "-p", "controller:=tests.controllers:ConstantController"],
        cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        stamp = [0]

        def moving_commands():
            stamp[0] += 50_000_000
            robot.send(stamp[0])
            return any(twist_of(c).linear.x > 0 for c in robot.commands)

        ros.spin_until(moving_commands, 20.0, "the node to command motion")
        process.send_signal(signal.SIGINT)
        ros.spin_until(lambda: process.poll() is not None and
                       twist_of(robot.commands[-1]).linear.x == 0.0, 10.0,
                       "the node to exit after a zero command")
    finally:
        if process.poll() is None:
            process.kill()
        output = process.communicate(timeout=10)[0]
    assert process.returncode == 0, output
    last = twist_of(robot.commands[-1])
    assert (last.linear.x, last.angular.z) == (0.0, 0.0), output


def send_set(ros, robot, stamp_ns, count_before, scan=None, **odometry):
    """Publish one odometry + scan pair and wait for the lockstep answer."""
    robot.odometry.publish(odom_msg(stamp_ns, **odometry))
    robot.scan.publish(scan or scan_msg(stamp_ns))
    ros.spin_until(lambda: len(robot.commands) > count_before, 5.0, "the lockstep answer")


def test_physically_impossible_odometry_is_ignored_and_the_next_good_set_used(ros, capfd):
    node = make_node(ros, controller="tests.controllers:ConstantController")
    robot = Robot(ros)
    bring_up(ros, node, robot)
    stamp = 0
    for bad in ({"v": 1e20}, {"w": 1e16}, {"v": -5.0, "w": 0.1}, {"v": 1e20, "w": -1e20}):
        stamp += 50_000_000
        send_set(ros, robot, stamp, len(robot.commands), **bad)
        assert (twist_of(robot.commands[-1]).linear.x,
                twist_of(robot.commands[-1]).angular.z) == (0.0, 0.0), bad
    assert node.controller.calls == []   # the controller never saw them
    stamp += 50_000_000
    send_set(ros, robot, stamp, len(robot.commands), v=0.2, w=-2.0)
    assert node.controller.calls == [(360, pytest.approx(0.2), pytest.approx(-2.0))]
    assert twist_of(robot.commands[-1]).linear.x == pytest.approx(0.1)
    logged = capfd.readouterr().err
    assert logged.count("is physically impossible") == 1, logged   # throttled


def test_broken_scans_warn_throttled_through_the_ros_logger(ros, capfd, caplog):
    node = make_node(ros)   # the project's WallFollower
    robot = Robot(ros)
    bring_up(ros, node, robot)
    stamp = 0
    with caplog.at_level("WARNING"):
        for k in range(30):
            stamp += 50_000_000
            scan = scan_msg(stamp)
            if k < 15:
                scan.range_min = math.nan          # unusable range limits
            else:
                scan.ranges = [1.0]                # one ray
            send_set(ros, robot, stamp, len(robot.commands), scan=scan)
    logged = capfd.readouterr().err
    python_messages = [r.getMessage() for r in caplog.records]
    # Each problem reported, through the node's logger, once (throttled), not once per scan.
    assert logged.count("range limits [nan, 3.5] m are unusable") == 1, logged
    assert logged.count("[wall_follower]: WallFollower: ignoring unusable scan geometry") == 1, \
        logged
    assert logged.count("[wall_follower]: WallFollower: scan has 1 readings") == 1, logged
    assert sum("scan geometry" in m for m in python_messages) == 1, python_messages
    assert sum("1 readings" in m for m in python_messages) == 1, python_messages
    assert all(math.isfinite(twist_of(c).linear.x) for c in robot.commands)
