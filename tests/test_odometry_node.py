"""The amr_odometry lifecycle node over DDS: /odom (pose only) in, /odometry (pose + twist) out."""
from __future__ import annotations

import math

import pytest
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from amr_turtlebot3.odometry_node import OdometryNode
from tests.emulator_process import running_emulator

RELIABLE_10 = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST)
START_NS = 1_700_000_000 * 1_000_000_000 + 123_000_000


def odom_message(t: float, v: float, w: float, yaw0: float) -> Odometry:
    """The robot's /odom after t s of constant (v, w) from the origin: pose only, twist zero."""
    yaw = yaw0 + w * t
    msg = Odometry()
    stamp_ns = START_NS + round(t * 1e9)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = "odom"
    msg.child_frame_id = "base_footprint"
    msg.pose.pose.position.x = v / w * (math.sin(yaw) - math.sin(yaw0))
    msg.pose.pose.position.y = -v / w * (math.cos(yaw) - math.cos(yaw0))
    msg.pose.pose.orientation.z = math.sin(yaw / 2.0)
    msg.pose.pose.orientation.w = math.cos(yaw / 2.0)
    msg.pose.covariance[0] = 0.01
    msg.twist.covariance[35] = 0.02
    return msg


class Harness:
    """The node under test plus a test node publishing /odom and recording /odometry."""

    def __init__(self, ros, **overrides) -> None:
        self.node = ros.add(OdometryNode(context=ros.context, parameter_overrides=[
            Parameter(name, value=value) for name, value in overrides.items()]))
        self.peer = ros.node("odometry_test_peer")
        self.received: list[Odometry] = []
        self.peer.create_subscription(Odometry, "/odometry", self.received.append, RELIABLE_10)
        self.odom = self.peer.create_publisher(Odometry, "/odom", RELIABLE_10)
        self.ros = ros

    def wait_for_matching(self) -> None:
        self.ros.spin_until(lambda: self.odom.get_subscription_count() > 0
                            and self.node._publisher.get_subscription_count() > 0,
                            timeout=10.0, message="/odom and /odometry to match")

    def send(self, msg: Odometry, expect_output: bool) -> None:
        """Publish one /odom message; when output is expected, spin until it arrives."""
        before = len(self.received)
        self.odom.publish(msg)
        if expect_output:
            self.ros.spin_until(lambda: len(self.received) > before, timeout=5.0,
                                message="an /odometry message")
        else:
            self.ros.spin_for(0.1)


def test_republishes_odom_with_velocities_and_preserved_pose(ros):
    h = Harness(ros)
    assert h.node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert h.node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    h.wait_for_matching()
    # Reversing while turning clockwise through the +-pi heading: sign and wrap both matter.
    v, w, yaw0 = -0.1, -1.5, -3.0
    sent = [odom_message(0.05 * k, v, w, yaw0) for k in range(12)]
    h.send(sent[0], expect_output=False)  # first message: nothing to differentiate
    assert h.received == []
    for msg in sent[1:]:
        h.send(msg, expect_output=True)
    assert len(h.received) == len(sent) - 1
    for got, original in zip(h.received, sent[1:]):
        assert got.twist.twist.linear.x == pytest.approx(v, abs=1e-6)
        assert got.twist.twist.angular.z == pytest.approx(w, abs=1e-6)
        assert got.header == original.header
        assert got.child_frame_id == "base_footprint"
        assert got.pose == original.pose
        assert got.twist.covariance[35] == pytest.approx(0.02)
        assert got.twist.twist.linear.y == 0.0 and got.twist.twist.angular.x == 0.0


def test_invalid_pose_and_time_jump_publish_nothing(ros):
    h = Harness(ros, max_gap=0.5)
    h.node.trigger_configure()
    h.node.trigger_activate()
    h.wait_for_matching()
    h.send(odom_message(0.0, 0.2, 0.5, 0.0), expect_output=False)
    h.send(odom_message(0.05, 0.2, 0.5, 0.0), expect_output=True)
    zero_quaternion = odom_message(0.10, 0.2, 0.5, 0.0)
    zero_quaternion.pose.pose.orientation.z = zero_quaternion.pose.pose.orientation.w = 0.0
    h.send(zero_quaternion, expect_output=False)
    h.send(odom_message(0.0, 0.2, 0.5, 0.0), expect_output=False)  # time went backwards: reset
    h.send(odom_message(0.05, 0.2, 0.5, 0.0), expect_output=True)
    assert len(h.received) == 2
    for got in h.received:
        assert got.twist.twist.linear.x == pytest.approx(0.2, abs=1e-6)
        assert got.twist.twist.angular.z == pytest.approx(0.5, abs=1e-6)


def test_inactive_node_publishes_nothing(ros):
    h = Harness(ros)
    assert h.node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    h.wait_for_matching()
    for k in range(5):
        h.send(odom_message(0.05 * k, 0.2, 0.5, 0.0), expect_output=False)
    assert h.received == []
    # Activation restarts the estimator: the first message after it is a first message again.
    h.node.trigger_activate()
    h.send(odom_message(0.25, 0.2, 0.5, 0.0), expect_output=False)
    h.send(odom_message(0.30, 0.2, 0.5, 0.0), expect_output=True)
    assert len(h.received) == 1
    h.node.trigger_deactivate()
    for k in range(7, 10):
        h.send(odom_message(0.05 * k, 0.2, 0.5, 0.0), expect_output=False)
    assert len(h.received) == 1


def test_cleanup_releases_topics(ros):
    h = Harness(ros)
    h.node.trigger_configure()
    ros.spin_until(lambda: h.peer.count_subscribers("/odom") == 1, message="node's /odom sub")
    assert h.node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
    ros.spin_until(lambda: h.peer.count_subscribers("/odom") == 0
                   and h.peer.count_publishers("/odometry") == 0,
                   message="node's topics to disappear")


@pytest.mark.parametrize("overrides", [{"max_gap": -1.0}, {"max_gap": "soon"},
                                       {"smoothing_time_constant": math.nan},
                                       {"output_topic": ""}, {"output_topic": "/odom"}])
def test_bad_parameters_fail_configure(ros, overrides):
    node = ros.add(OdometryNode(context=ros.context, parameter_overrides=[
        Parameter(name, value=value) for name, value in overrides.items()]))
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE


def test_integer_parameters_accepted(ros):
    node = ros.add(OdometryNode(context=ros.context, parameter_overrides=[
        Parameter("max_gap", value=1), Parameter("smoothing_time_constant", value=0)]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.estimator.max_gap == 1.0


def test_velocities_of_the_cyclone_dds_emulated_robot(ros, tmp_path):
    """Fast DDS node on a Cyclone DDS robot: the estimate matches the velocities it applies."""
    h = Harness(ros)
    h.node.trigger_configure()
    h.node.trigger_activate()
    cmd_vel = h.peer.create_publisher(TwistStamped, "/cmd_vel", RELIABLE_10)
    command = TwistStamped()
    command.twist.linear.x, command.twist.angular.z = -0.15, 2.5  # reversing, spinning past pi
    with running_emulator(tmp_path, "--corridor-width", "0"):
        ros.spin_until(lambda: cmd_vel.get_subscription_count() > 0 and len(h.received) > 0,
                       timeout=20.0, message="the emulator and /odometry")
        start = len(h.received)

        def driven_long_enough() -> bool:
            cmd_vel.publish(command)
            ros.spin_for(0.05)
            steady = [m for m in h.received[start:] if m.twist.twist.angular.z > 1.0]
            # 4.5 s at 2.5 rad/s: the heading crosses +-pi twice. Once was not enough on a
            # loaded machine: at 20 Hz a sample lands only every ~0.13 rad, about the width of
            # the windows checked below, so one crossing could leave both sides unsampled.
            return len(steady) >= 90

        ros.spin_until(driven_long_enough, timeout=20.0, message="4.5 s of estimates")
    # The emulator fills its own twist with the applied velocities; the node overwrote it with
    # the estimate from poses. Skip the message spanning the command change (not one arc).
    steady = [m for m in h.received[start:] if m.twist.twist.angular.z > 1.0][1:]
    yaws = [2 * math.atan2(m.pose.pose.orientation.z, m.pose.pose.orientation.w) for m in steady]
    assert max(yaws) > 3.0 and min(yaws) < -3.0  # crossed +-pi
    for msg in steady:
        assert msg.twist.twist.linear.x == pytest.approx(-0.15, abs=1e-6)
        assert msg.twist.twist.angular.z == pytest.approx(2.5, abs=1e-6)


def test_huge_quaternions_and_implausible_stamps_never_publish_absurd_velocities(ros, capfd):
    """Only the Burger's possible velocities come out.

    A 1e300-norm quaternion keeps its yaw, stamps 1 ns apart are skipped and a pose jump is
    not a speed.
    """
    h = Harness(ros)
    h.node.trigger_configure()
    h.node.trigger_activate()
    h.wait_for_matching()
    v, w, yaw0 = 0.2, 0.5, 1.0
    first = odom_message(0.0, v, w, yaw0)
    h.send(first, expect_output=False)
    scaled = odom_message(0.05, v, w, yaw0)
    q = scaled.pose.pose.orientation
    q.z, q.w = q.z * 1e300, q.w * 1e300
    h.send(scaled, expect_output=True)
    nanosecond_later = odom_message(0.05, v, w, yaw0)
    nanosecond_later.header.stamp.nanosec += 1
    nanosecond_later.pose.pose.position.x += 0.01
    h.send(nanosecond_later, expect_output=False)
    h.send(odom_message(0.10, v, w, yaw0), expect_output=True)
    jumped = odom_message(0.15, v, w, yaw0)
    jumped.pose.pose.position.x += 2.0   # 40 m/s
    h.send(jumped, expect_output=False)
    h.send(odom_message(0.20, v, w, yaw0), expect_output=False)  # restarted from the jump
    h.send(odom_message(0.25, v, w, yaw0), expect_output=True)
    assert len(h.received) == 3
    for got in h.received:
        assert got.twist.twist.linear.x == pytest.approx(v, abs=1e-6)
        assert got.twist.twist.angular.z == pytest.approx(w, abs=1e-6)
    logged = capfd.readouterr().err
    assert "interval shorter than 1 ms" in logged and "physically impossible motion" in logged
