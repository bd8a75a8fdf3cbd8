"""The Cyclone DDS robot emulator (tests/robot_emulator.py) interoperates with rclpy on Fast DDS.

Each test starts the emulator as a separate process in the `ros` fixture's private domain and
talks to it from rclpy both ways: /odom and /scan with the robot's layouts, /cmd_vel commands as
TwistStamped (Jazzy bringup) or Twist (--cmd-vel twist).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

from tests.emulator_process import commands_in, read_log, running_emulator
from tests.robot_emulator import (
    FOOTPRINT_RADIUS,
    SCANNER_OFFSET_X,
    Robot,
    apply_like_turtlebot3,
    corridor_walls,
)

RELIABLE_10 = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST)
CORRIDOR_WIDTH = 0.8
WALL_AHEAD = 1.0


def expected_scan(x: float) -> np.ndarray:
    """Ranges of the corridor with a wall ahead, scanner at (x + offset, 0) facing +x."""
    angles = np.radians(np.arange(360.0))
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        front = np.where(c > 1e-12, (WALL_AHEAD - x - SCANNER_OFFSET_X) / c, np.inf)
        side = np.where(np.abs(s) > 1e-12, CORRIDOR_WIDTH / 2 / np.abs(s), np.inf)
    ranges = np.minimum(front, side)
    return np.where((ranges >= 0.12) & (ranges <= 3.5), ranges, 0.0)


def test_odom_scan_and_stamped_commands_with_rclpy(ros, tmp_path):
    node = ros.node("emulator_peer")
    odoms: list[Odometry] = []
    scans: list[LaserScan] = []
    node.create_subscription(Odometry, "/odom", odoms.append, RELIABLE_10)
    node.create_subscription(LaserScan, "/scan", scans.append, qos_profile_sensor_data)
    cmd_vel = node.create_publisher(TwistStamped, "/cmd_vel", RELIABLE_10)
    with running_emulator(tmp_path, "--corridor-width", str(CORRIDOR_WIDTH),
                          "--wall-ahead-at", str(WALL_AHEAD)) as (process, log):
        ros.spin_until(lambda: len(odoms) >= 3 and len(scans) >= 2, timeout=20.0,
                       message="/odom and /scan from the Cyclone DDS emulator")
        odom, scan = odoms[-1], scans[-1]
        assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_footprint")
        assert odom.pose.pose.position.x == 0.0 and odom.pose.pose.orientation.w == 1.0
        assert scan.header.frame_id == "base_scan"
        assert len(scan.ranges) == 360 and len(scan.intensities) == 360
        assert scan.angle_min == 0.0
        assert scan.angle_increment == pytest.approx(math.radians(1.0), rel=1e-6)
        assert scan.angle_max == pytest.approx(math.radians(359.0), rel=1e-6)
        assert (scan.range_min, scan.range_max) == pytest.approx((0.12, 3.5))
        ranges = np.array(scan.ranges)
        expected = expected_scan(0.0)
        assert np.count_nonzero(ranges == 0.0) >= 10  # open corridor behind: no return
        assert np.all((ranges == 0.0) == (expected == 0.0))
        assert np.max(np.abs(ranges - expected)) < 1e-5  # float32 ranges

        # Commands from rclpy reach the emulator; the robot drives towards the wall.
        ros.spin_until(lambda: cmd_vel.get_subscription_count() > 0, timeout=10.0,
                       message="the emulator's /cmd_vel reader")
        command = TwistStamped()
        command.header.frame_id = "base_link"
        command.header.stamp.sec, command.header.stamp.nanosec = 42, 7
        command.twist.linear.x = 0.1
        start_count = len(odoms)

        def moved() -> bool:
            cmd_vel.publish(command)
            ros.spin_for(0.05)
            return len(odoms) > start_count and odoms[-1].pose.pose.position.x > 0.05

        ros.spin_until(moved, timeout=10.0, message="the emulated robot to move")
        received = commands_in(log)[0]
        assert received["linear"] == [0.1, 0.0, 0.0] and received["angular"] == [0.0, 0.0, 0.0]
        assert received["stamp"] == [42, 7] and received["applied"] == [0.1, 0.0]
        assert odoms[-1].twist.twist.linear.x == pytest.approx(0.1)
        assert odoms[-1].pose.pose.position.y == pytest.approx(0.0, abs=1e-9)
        # The scan follows the motion: the wall ahead is closer by the distance driven.
        scan_count = len(scans)
        ros.spin_until(lambda: len(scans) > scan_count, timeout=5.0, message="a new /scan")
        latest_scan = scans[-1]
        scan_time = latest_scan.header.stamp.sec + latest_scan.header.stamp.nanosec * 1e-9
        nearest_odom = min(odoms, key=lambda o: abs(
            o.header.stamp.sec + o.header.stamp.nanosec * 1e-9 - scan_time))
        x_at_scan = nearest_odom.pose.pose.position.x
        # Odom and scan are stamped up to 25 ms apart: 2.5 mm at 0.1 m/s.
        assert latest_scan.ranges[0] == pytest.approx(WALL_AHEAD - SCANNER_OFFSET_X - x_at_scan,
                                                      abs=0.005)
        command.twist.linear.x = 0.0
        cmd_vel.publish(command)
        ros.spin_for(0.2)
        assert process.poll() is None, "the emulator exited early"


def test_twist_commands_with_flag_and_writer_going_away(ros, tmp_path):
    node = ros.node("emulator_twist_peer")
    odoms: list[Odometry] = []
    node.create_subscription(Odometry, "/odom", odoms.append, RELIABLE_10)
    cmd_vel = node.create_publisher(Twist, "/cmd_vel", RELIABLE_10)
    with running_emulator(tmp_path, "--cmd-vel", "twist") as (process, log):
        ros.spin_until(lambda: cmd_vel.get_subscription_count() > 0 and odoms, timeout=20.0,
                       message="the emulator to match /cmd_vel and /odom")
        command = Twist()
        command.angular.z = 0.5

        def turned() -> bool:
            cmd_vel.publish(command)
            ros.spin_for(0.05)
            return bool(commands_in(log)) and odoms[-1].pose.pose.orientation.z > 0.01

        ros.spin_until(turned, timeout=10.0, message="the emulated robot to turn left (CCW)")
        received = commands_in(log)[0]
        assert received["angular"] == [0.0, 0.0, 0.5] and received["stamp"] is None
        assert odoms[-1].twist.twist.angular.z == pytest.approx(0.5)

        # A writer going away gives the emulator's reader an InvalidSample: it must keep going.
        node.destroy_publisher(cmd_vel)
        ros.spin_for(0.3)
        cmd_vel = node.create_publisher(Twist, "/cmd_vel", RELIABLE_10)
        command.angular.z = 0.0
        ros.spin_until(lambda: cmd_vel.get_subscription_count() > 0, timeout=10.0,
                       message="the emulator's reader to match the new publisher")

        def stopped() -> bool:
            cmd_vel.publish(command)
            ros.spin_for(0.05)
            return commands_in(log)[-1]["angular"][2] == 0.0

        ros.spin_until(stopped, timeout=10.0, message="the stop command")
        assert process.poll() is None, "the emulator exited early"
    end = read_log(log)[-1]
    assert end["event"] == "end" and end["cmds"] >= 2 and end["collisions"] == 0
    assert end["invalid_samples"] >= 1


def test_scan_stops_while_odom_continues(ros, tmp_path):
    node = ros.node("emulator_scan_stop_peer")
    odoms: list[Odometry] = []
    scans: list[LaserScan] = []
    node.create_subscription(Odometry, "/odom", odoms.append, RELIABLE_10)
    node.create_subscription(LaserScan, "/scan", scans.append, qos_profile_sensor_data)
    with running_emulator(tmp_path, "--stop-scan-after", "2.0") as (process, log):
        ros.spin_until(lambda: any(r["event"] == "scan_stopped" for r in read_log(log)),
                       timeout=15.0, message="the emulator to stop scanning")
        assert scans, "no /scan arrived before the emulator stopped scanning"
        ros.spin_for(0.2)  # a scan in flight may still arrive
        scan_count, odom_count = len(scans), len(odoms)
        ros.spin_for(0.8)  # 4 scan periods
        assert len(scans) == scan_count
        assert len(odoms) > odom_count


def test_emulated_robot_stops_at_walls_and_applies_commands_like_turtlebot3():
    robot = Robot(corridor_walls(0.8, 0.6))
    robot.v, robot.w = apply_like_turtlebot3(0.5, 0.0)  # clamped to 0.22 m/s
    assert (robot.v, robot.w) == (0.22, 0.0)
    new_contacts = sum(robot.step(0.05) for _ in range(100))  # 1.1 m of commanded travel
    assert new_contacts == 1 and robot.collisions == 1
    assert 0.6 - FOOTPRINT_RADIUS - 0.22 * 0.05 <= robot.x < 0.6 - FOOTPRINT_RADIUS
    assert apply_like_turtlebot3(0.129, -3.5) == (0.12, -2.84)  # 0.01 steps, truncated
    assert apply_like_turtlebot3(-0.057, 0.0) == (-0.05, 0.0)
