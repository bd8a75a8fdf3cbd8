"""The amr_simulator lifecycle node over real DDS: lockstep, real time, goal, bad input.

Every test talks to the node through topics from a separate probe node, as the wall follower
and a localization node would.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan

from amr_common.ros.ros_conversions import (
    laser_scan,
    odometry_message,
    pose_from_message,
    quaternion_to_yaw,
    scan_ranges,
    seconds_to_time,
    time_to_nanoseconds,
    twist_stamped,
    yaw_to_quaternion,
)
from amr_sim.simulator_node import SimulatorNode
from amr_sim.simulator_params import parse_start

DT_NS = 50_000_000
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
BEST_EFFORT = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)


class Probe:
    """The rest of the graph: records every output of the simulator and sends commands."""

    def __init__(self, ros, stamped: bool = True) -> None:
        self.node = ros.node("probe")
        self.received: dict[str, list] = {name: [] for name in
                                          ("odometry", "odom", "scan", "clock", "ground_truth")}
        for topic, msg_type, qos in (("odometry", Odometry, RELIABLE),
                                     ("odom", Odometry, RELIABLE),
                                     ("scan", LaserScan, BEST_EFFORT), ("clock", Clock, RELIABLE),
                                     ("ground_truth", Odometry, RELIABLE)):
            self.node.create_subscription(msg_type, "/" + topic, self.received[topic].append, qos)
        self.stamped = stamped
        self.cmd = self.node.create_publisher(TwistStamped if stamped else Twist, "/cmd_vel", 10)

    def send(self, v: float, w: float, stamp=None) -> None:
        if self.stamped:
            self.cmd.publish(twist_stamped(v, w, stamp))
        else:
            message = Twist()
            message.linear.x, message.angular.z = v, w
            self.cmd.publish(message)

    def count(self) -> dict[str, int]:
        return {topic: len(messages) for topic, messages in self.received.items()}


def start_simulator(ros, probe: Probe, activate: bool = True, **parameters) -> SimulatorNode:
    """Configure (and activate) a simulator once the probe is matched, so nothing is lost."""
    node = ros.add(SimulatorNode(context=ros.context, parameter_overrides=[
        Parameter(name, value=value) for name, value in parameters.items()]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    odom_topic = node.odometry_topic
    ros.spin_until(lambda: all(p.get_subscription_count() > 0
                               for p in node._outputs.publishers.values())
                   and probe.cmd.get_subscription_count() > 0
                   and probe.node.count_publishers(odom_topic) > 0,
                   timeout=10.0, message="probe and simulator to discover each other")
    if activate:
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        if parameters.get("mode", "lockstep") == "lockstep":
            wait_first_measurement(ros, probe, odom_topic.lstrip("/"))
    return node


def wait_first_measurement(ros, probe: Probe, odom_topic: str = "odometry") -> None:
    topics = (odom_topic, "scan", "clock", "ground_truth")
    ros.spin_until(lambda: all(len(probe.received[t]) == 1 for t in topics),
                   message="the first measurement, published on activation")


def step_once(ros, probe: Probe, v: float, w: float, odom_topic: str = "odometry") -> None:
    """Send one command and wait for its whole answer (odometry, scan, clock, ground truth)."""
    before = probe.count()
    probe.send(v, w)
    topics = (odom_topic, "scan", "clock", "ground_truth")
    ros.spin_until(lambda: all(len(probe.received[t]) > before[t] for t in topics),
                   timeout=5.0, message="the answer to a command")


def odometry_is_finite(message: Odometry) -> bool:
    values = [message.pose.pose.position.x, message.pose.pose.position.y,
              message.pose.pose.orientation.z, message.pose.pose.orientation.w,
              message.twist.twist.linear.x, message.twist.twist.angular.z]
    return all(math.isfinite(v) for v in values)


@pytest.fixture
def open_room(tmp_path):
    """A course map JSON: a 20 m square room with one 0.2 m box 0.5 m ahead of the origin."""
    path = tmp_path / "open_room.json"
    path.write_text(json.dumps({"metric": {
        "boundary": [[-10, -10], [10, -10], [10, 10], [-10, 10]],
        "holes": [[[0.5, -0.1], [0.7, -0.1], [0.7, 0.1], [0.5, 0.1]]]}}))
    return str(path)


# --- message helpers ----------------------------------------------------------------------

def test_conversions_round_trip_and_stamp_arithmetic():
    for yaw in (0.0, 1.0, -2.5, math.pi / 2, 3.0):
        assert quaternion_to_yaw(yaw_to_quaternion(yaw)) == pytest.approx(yaw, abs=1e-12)
    # k * dt stamps stay exactly k * 50 ms apart in nanoseconds, even after float accumulation.
    t, previous = 0.0, 0
    for _ in range(1000):
        t += 0.05
        ns = time_to_nanoseconds(seconds_to_time(t))
        assert ns - previous == DT_NS
        previous = ns
    message = odometry_message(seconds_to_time(1.5), "odom", "base_footprint", (1.0, -2.0, 0.5),
                               (0.1, -0.2))
    assert pose_from_message(message.pose.pose) == pytest.approx((1.0, -2.0, 0.5))
    scan = laser_scan([1.0, float("nan"), 0.0], stamp=seconds_to_time(0.0), frame_id="s",
                      angle_min=0.0, angle_increment=0.5, range_min=0.1, range_max=4.0,
                      scan_time=0.3)
    assert scan.angle_max == pytest.approx(1.0) and scan.time_increment == pytest.approx(0.1)
    assert np.isnan(scan_ranges(scan)[1]) and scan_ranges(scan)[2] == 0.0
    with pytest.raises(ValueError):
        seconds_to_time(float("nan"))
    assert parse_start("1, -2.5, 3.1") == (1.0, -2.5, 3.1)
    assert parse_start("outer") == "outer" and parse_start("") is None
    for bad in ("1,2", "1,x,3", "1,2,nan"):
        with pytest.raises(ValueError):
            parse_start(bad)


# --- lockstep -----------------------------------------------------------------------------

def test_lockstep_answers_each_command_once_with_stamps_advancing_by_dt(ros):
    probe = Probe(ros)
    node = start_simulator(ros, probe)
    # The first measurement (stamp 0, no step) arrived on activation, before any command.
    assert node.simulator.steps == 0
    for k in range(1, 21):
        step_once(ros, probe, 0.2, 0.5)
        assert node.simulator.steps == k
    ros.spin_for(0.2)  # nothing more may come without commands
    counts = probe.count()
    assert counts["odometry"] == counts["scan"] == counts["clock"] == 21
    assert counts["ground_truth"] == 21 and counts["odom"] == 0
    for topic in ("odometry", "scan", "ground_truth"):
        stamps = [time_to_nanoseconds(m.header.stamp) for m in probe.received[topic]]
        assert stamps == [k * DT_NS for k in range(21)], topic
    assert [time_to_nanoseconds(m.clock) for m in probe.received["clock"]] == \
        [k * DT_NS for k in range(21)]
    odometry = probe.received["odometry"][-1]
    assert (odometry.header.frame_id, odometry.child_frame_id) == ("odom", "base_footprint")
    # Twist = encoder speeds: the robot turns left while driving at the commanded speeds.
    assert odometry.twist.twist.linear.x == pytest.approx(0.2, abs=0.02)
    assert odometry.twist.twist.angular.z == pytest.approx(0.5, abs=0.05)
    assert pose_from_message(odometry.pose.pose) == pytest.approx(
        node.simulator.odometry_pose, abs=1e-6)
    truth = probe.received["ground_truth"][-1]
    assert truth.header.frame_id == "map"
    assert pose_from_message(truth.pose.pose) == pytest.approx(node.simulator.pose, abs=1e-9)
    assert truth.twist.twist.linear.x == pytest.approx(0.2, abs=0.02)
    start = pose_from_message(probe.received["ground_truth"][0].pose.pose)
    assert math.dist(start[:2], (1.0, -1.0)) < 1e-9  # lab02 'outer', the default start
    assert math.dist(start[:2], node.simulator.pose[:2]) > 0.1  # it did move


@pytest.mark.parametrize("profile, rays, no_return, range_limits, odom_topic", [
    ("ideal", 240, "nan", (0.016, 8.0), "odometry"),
    ("turtlebot3_clean", 360, "zero", (0.12, 3.5), "odometry"),
])
def test_laser_scan_fields_follow_the_profile(ros, open_room, profile, rays, no_return,
                                              range_limits, odom_topic):
    probe = Probe(ros)
    node = start_simulator(ros, probe, world=open_room, start="0,0,0", profile=profile)
    step_once(ros, probe, 0.0, 0.0, odom_topic)
    scan = probe.received["scan"][-1]
    assert len(scan.ranges) == rays
    assert scan.header.frame_id == "base_scan"
    assert scan.angle_min == 0.0
    assert scan.angle_increment == pytest.approx(2 * math.pi / rays, rel=1e-6)
    assert scan.angle_max == pytest.approx(2 * math.pi * (rays - 1) / rays, rel=1e-6)
    assert (scan.range_min, scan.range_max) == pytest.approx(range_limits, rel=1e-6)
    assert scan.scan_time == pytest.approx(0.05) and \
        scan.time_increment == pytest.approx(0.05 / rays, rel=1e-5)
    ranges = scan_ranges(scan)
    # Straight ahead: the box face 0.5 m away. Left, right, back: walls 10 m away = no return.
    assert ranges[0] == pytest.approx(0.5, abs=0.05)
    for index in (rays // 4, rays // 2, 3 * rays // 4):
        assert (math.isnan(ranges[index]) if no_return == "nan" else ranges[index] == 0.0)
    valid = ranges[np.isfinite(ranges) & (ranges != 0.0)]
    assert valid.size > 0 and np.all((valid >= range_limits[0]) & (valid <= range_limits[1]))
    # Lockstep keeps the course protocol in both profiles: /odometry with the encoder twist.
    odometry = probe.received["odometry"][-1]
    assert (odometry.header.frame_id, odometry.child_frame_id) == ("odom", "base_footprint")
    assert probe.count()["odom"] == 0 and node.odometry_topic == "/odometry"


def test_bad_commands_are_zero_or_saturated_and_nothing_non_finite_is_published(ros):
    probe = Probe(ros)
    node = start_simulator(ros, probe)
    start = node.simulator.pose
    for v, w in ((float("nan"), 0.3), (0.1, float("inf")), (float("-inf"), float("nan"))):
        step_once(ros, probe, v, w)
    assert node.simulator.pose == pytest.approx(start, abs=1e-9)
    for _ in range(10):
        step_once(ros, probe, 1e9, 0.0)  # saturated at the wheel-speed limit
    speeds = [m.twist.twist.linear.x for m in probe.received["ground_truth"]]
    assert max(speeds) <= 0.22 + 1e-6 and max(speeds) > 0.15
    assert all(odometry_is_finite(m) for topic in ("odometry", "ground_truth")
               for m in probe.received[topic])


def test_inactive_node_publishes_nothing_and_does_not_step(ros):
    probe = Probe(ros)
    node = start_simulator(ros, probe, activate=False)
    for _ in range(3):
        probe.send(0.1, 0.0)
    ros.spin_for(0.3)
    assert sum(probe.count().values()) == 0 and node.simulator.steps == 0
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    wait_first_measurement(ros, probe)
    step_once(ros, probe, 0.1, 0.0)
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    counts, steps = probe.count(), node.simulator.steps
    for _ in range(3):
        probe.send(0.1, 0.0)
    ros.spin_for(0.3)
    assert probe.count() == counts and node.simulator.steps == steps == 1
    assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
    assert node.simulator is None


@pytest.mark.parametrize("parameters, reason", [
    ({"world": "no_such_world"}, "no_such_world"),
    ({"start": "1,2"}, "x,y,theta"),
    ({"start": "nowhere"}, "nowhere"),
    ({"start": "0,0,0"}, "start"),  # lab02's origin lies in a wall or outside: rejected
    ({"profile": "gazebo"}, "gazebo"),
    ({"profile": "turtlebot3:command_latency_s=-1"}, "command_latency_s must be"),
    ({"profile": "turtlebot3:dropout_share=nan"}, "dropout_share must be"),
    ({"mode": "fast"}, "mode"),
    ({"dt": -0.05}, "dt"),
    ({"goal": [1.0]}, "goal"),
])
def test_bad_parameters_fail_configure_with_the_reason_logged(ros, parameters, reason,
                                                              monkeypatch):
    node = ros.add(SimulatorNode(context=ros.context, parameter_overrides=[
        Parameter(name, value=value) for name, value in parameters.items()]))
    logged = []
    logger = node.get_logger()
    monkeypatch.setattr(type(logger), "error",
                        lambda self, text, **kwargs: logged.append(text) or True)
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert node.simulator is None
    assert logged and reason in logged[-1]


def test_twist_commands_when_cmd_vel_is_not_stamped(ros):
    probe = Probe(ros, stamped=False)
    node = start_simulator(ros, probe, cmd_vel_stamped=False)
    info = node.get_subscriptions_info_by_topic("/cmd_vel")
    assert [i.topic_type for i in info] == ["geometry_msgs/msg/Twist"]
    for _ in range(5):
        step_once(ros, probe, 0.2, 0.0)
    assert node.simulator.steps == 5 and node.simulator.distance > 0.01


def test_on_step_hooks_see_every_step_and_can_finish_the_run(ros):
    probe = Probe(ros)
    node = start_simulator(ros, probe)
    seen = []

    def stop_after_three(simulator) -> None:
        seen.append(simulator.steps)
        if simulator.steps == 3:
            node.finish("duration reached")

    node.on_step.append(stop_after_three)
    for _ in range(2):
        step_once(ros, probe, 0.1, 0.0)
    probe.send(0.1, 0.0)
    ros.spin_until(lambda: node.finished, message="the hook to finish the run")
    probe.send(0.1, 0.0)
    ros.spin_for(0.2)
    assert seen == [1, 2, 3] and node.simulator.steps == 3
    summary = node.summary()
    assert summary["finished"] and summary["reason"] == "duration reached"
    assert not summary["goal_reached"] and summary["steps"] == 3


# --- real time ----------------------------------------------------------------------------

def test_realtime_turtlebot3_rates_and_stale_commands(ros):
    probe = Probe(ros, stamped=False)
    node = start_simulator(ros, probe, mode="realtime", profile="turtlebot3_clean",
                           cmd_vel_stamped=False, command_timeout=0.3)
    probe.send(0.1, 0.0)  # sent once: the robot drives for command_timeout, then stops
    ros.spin_for(1.5)
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    ros.spin_for(0.1)
    steps = node.simulator.steps
    odom = [time_to_nanoseconds(m.header.stamp) for m in probe.received["odom"]]
    scans = [time_to_nanoseconds(m.header.stamp) for m in probe.received["scan"]]
    # Steps follow a wall-clock timer (loaded machine: only a loose lower bound), never faster.
    assert 8 <= steps <= 31
    # Per simulated time, exact: /odom every 50 ms (20 Hz), /scan every 200 ms (5 Hz).
    assert np.all(np.diff(odom) == DT_NS) and abs(len(odom) - steps) <= 1
    assert np.all(np.diff(scans) == 4 * DT_NS) and abs(len(scans) - steps / 4) <= 1
    assert probe.received["scan"][-1].scan_time == pytest.approx(0.2)
    assert probe.count()["odometry"] == 0
    # Stale command: the robot moved, then stood still once the command was older than 0.3 s.
    truth = probe.received["ground_truth"]
    speeds = [m.twist.twist.linear.x for m in truth]
    assert max(speeds) > 0.05
    assert all(abs(s) < 1e-3 for s in speeds[-3:])
    assert node.simulator.distance < 0.1 * (0.3 + 0.2)  # at most ~timeout + a step of driving


# --- goal and localization ----------------------------------------------------------------

def test_goal_reached_while_localized_finishes_the_run_with_a_summary(ros, capfd):
    from amr_msgs.msg import PoseStamped
    probe = Probe(ros)
    pose_publisher = probe.node.create_publisher(PoseStamped, "/pose", 10)
    localized = {"value": False}
    offset = 0.05  # the estimate is 5 cm off in x

    def answer(odometry: Odometry) -> None:
        """A localization node + controller: pose estimate and command, stamped alike."""
        truth = probe.received["ground_truth"][answered].pose.pose
        estimate = PoseStamped()
        estimate.header.stamp = odometry.header.stamp
        estimate.pose = truth
        estimate.pose.position.x += offset
        estimate.localized = localized["value"]
        pose_publisher.publish(estimate)
        probe.send(0.2, 0.0, odometry.header.stamp)

    node = start_simulator(ros, probe, activate=False, enable_localization=True,
                           goal=[1.0, -0.7], goal_tolerance=0.15, goal_rest_time=0.0)
    ros.spin_until(lambda: pose_publisher.get_subscription_count() > 0,
                   message="/pose subscription")
    answered = 0
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    for _ in range(200):
        ros.spin_until(lambda: (len(probe.received["odometry"]) > answered and
                                len(probe.received["ground_truth"]) > answered) or node.finished,
                       message="a measurement or the end of the run")
        if node.finished:
            break
        # Unlocalized, the robot passes within tolerance of the goal without finishing.
        y = node.simulator.pose[1]
        localized["value"] = y > -0.7
        answer(probe.received["odometry"][answered])
        answered += 1
    assert node.finished
    x, y, _ = node.simulator.pose
    assert math.hypot(x - 1.0, y + 0.7) <= 0.15 and y > -0.7
    summary = node.summary()
    assert summary["goal_reached"] and summary["localized"]
    assert summary["steps"] == node.simulator.steps > 3
    assert summary["sim_time_s"] == pytest.approx(0.05 * summary["steps"])
    assert summary["wall_time_s"] > 0
    assert summary["localization_error"][0] == pytest.approx(offset, abs=0.02)
    # Good news is information, not a warning.
    lines = capfd.readouterr().err.splitlines()
    for news in ("Localized: estimated", "Congratulations, you reached the goal!"):
        said = [line for line in lines if news in line]
        assert len(said) == 1 and said[0].startswith("[INFO]"), (news, said)
    # Finished: further commands are not answered.
    steps, count = node.simulator.steps, probe.count()["odometry"]
    probe.send(0.2, 0.0, seconds_to_time(node.simulator.time))
    ros.spin_for(0.2)
    assert node.simulator.steps == steps and probe.count()["odometry"] == count


def test_after_the_goal_the_run_goes_on_until_the_robot_rests(ros):
    from amr_msgs.msg import PoseStamped
    probe = Probe(ros)
    pose_publisher = probe.node.create_publisher(PoseStamped, "/pose", 10)
    node = start_simulator(ros, probe, activate=False, enable_localization=True,
                           goal=[1.0, -0.85], goal_tolerance=0.15, goal_rest_time=0.2)
    ros.spin_until(lambda: pose_publisher.get_subscription_count() > 0,
                   message="/pose subscription")
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    answered = 0
    for _ in range(100):
        ros.spin_until(lambda: len(probe.received["odometry"]) > answered or node.finished,
                       message="a measurement or the end of the run")
        if node.finished:
            break
        odometry = probe.received["odometry"][answered]
        estimate = PoseStamped()
        estimate.header.stamp = odometry.header.stamp
        estimate.pose.orientation.w = 1.0
        estimate.localized = True
        pose_publisher.publish(estimate)
        # Drive until 5 cm past the goal's y (reached at y >= -1.0), then rest.
        moving = node.simulator.pose[1] < -0.80
        probe.send(0.1 if moving else 0.0, 0.0, odometry.header.stamp)
        answered += 1
    assert node.finished
    summary = node.summary()
    assert summary["goal_reached"] and summary["reason"] == "goal reached"
    reached, stopped = summary["goal_reached_time_s"], summary["stopped_time_s"]
    assert reached < stopped and summary["sim_time_s"] == pytest.approx(stopped + 0.2)
    assert node.simulator.pose[1] == pytest.approx(-0.80, abs=0.01), "drove on after reaching"
    assert summary["final_position_error_m"] == pytest.approx(0.05, abs=0.01)


# --- the reality gap ----------------------------------------------------------------------

def test_lds02_scans_carry_their_own_geometry_and_the_summary_the_effects(ros):
    probe = Probe(ros)
    node = start_simulator(ros, probe, profile="turtlebot3_lds02", seed=3)
    for _ in range(12):
        step_once(ros, probe, 0.1, 0.5)
    scans = probe.received["scan"]
    assert len({len(s.ranges) for s in scans}) > 1 and len({s.angle_min for s in scans}) > 1
    for scan in scans:
        n = len(scan.ranges)
        assert (scan.range_min, scan.range_max) == (0.0, 100.0)  # as ld08_driver publishes
        assert scan.scan_time == pytest.approx(0.2)
        assert scan.time_increment == pytest.approx(0.2 / n, rel=1e-5)
        assert scan.angle_max == pytest.approx(scan.angle_min + (n - 1) * scan.angle_increment,
                                               rel=1e-5)
        ranges = scan_ranges(scan)
        assert not (ranges == 0.0).any() and np.all(ranges[np.isfinite(ranges)] >= 0.16)
    assert any(np.isnan(scan_ranges(s)).any() for s in scans)
    assert node.summary()["effects"]["command_latency_s"] == pytest.approx(0.03)
    assert node.summary()["profile"] == "turtlebot3_lds02"


class FakeTimerNode:
    """Just what ScanDelivery needs of a node: one-shot timers, fired by the test."""

    def __init__(self) -> None:
        self.timers = []

    def create_timer(self, delay, callback, clock=None):
        timer = type("Timer", (), {"cancel": lambda self: None})()
        self.timers.append((delay, callback, timer))
        return timer

    def destroy_timer(self, timer) -> None:
        self.timers = [t for t in self.timers if t[2] is not timer]


def test_scan_delivery_loses_some_scans_and_delays_the_others():
    from amr_sim.simulator_outputs import ScanDelivery
    node, published = FakeTimerNode(), []
    publisher = type("Publisher", (), {"publish": lambda self, m: published.append(m)})()
    delivery = ScanDelivery(node, publisher, np.random.default_rng(0), loss=0.2, jitter=0.03)
    for k in range(2000):
        delivery.send(k)
    assert delivery.lost == pytest.approx(400, abs=60) and not published
    delays = [delay for delay, _, _ in node.timers]
    assert len(delays) == 2000 - delivery.lost
    assert 0.0 < min(delays) and max(delays) < 0.03 and np.mean(delays) == pytest.approx(0.015,
                                                                                       rel=0.1)
    for _, deliver, _ in list(node.timers)[:10]:
        deliver()  # a timer fires once: published, then forgotten
    assert len(published) == 10 and len(node.timers) == len(delays) - 10
    delivery.destroy()  # deactivate: the rest never arrives
    assert not node.timers and delivery.sent == 10


@pytest.mark.parametrize("loss, jitter", [(1.0, 0.02), (0.0, 0.05)])
def test_realtime_scans_are_lost_or_late_as_configured(ros, loss, jitter):
    probe = Probe(ros, stamped=False)
    node = start_simulator(ros, probe, mode="realtime", cmd_vel_stamped=False,
                           profile=f"turtlebot3:scan_loss_share={loss}:"
                                   f"scan_jitter_s={jitter}")
    ros.spin_for(1.2)
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    ros.spin_for(0.1)
    delivery = node._outputs._delivery
    assert node.simulator.steps >= 5 and len(probe.received["odom"]) >= 5
    if loss == 1.0:
        assert probe.count()["scan"] == 0 and delivery.lost >= 2
    else:  # late, but every scan arrives, stamped at its revolution's end (5 Hz)
        stamps = [time_to_nanoseconds(m.header.stamp) for m in probe.received["scan"]]
        assert len(stamps) == delivery.sent >= 2 and delivery.lost == 0
        assert np.all(np.diff(stamps) == 4 * DT_NS)
