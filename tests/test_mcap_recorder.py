"""McapRecorder writes ROS 2 MCAP files that independent readers (rosbags, mcap_ros2) decode."""
from __future__ import annotations

import math
import time
from pathlib import Path

import pytest
from geometry_msgs.msg import TwistStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import LaserScan

from amr_msgs.msg import PoseStamped as GroundTruthPose
from amr_tools.graph_recorder import GraphRecorder
from amr_tools.mcap_recorder import McapRecorder, cdr_header_stamp_ns, full_message_definition

DT_NS = 50_000_000  # 0.05 s
STEPS = 20
SCAN_EVERY = 4      # 5 Hz scans against 20 Hz odometry and commands, like the turtlebot3 profile


def _stamp(msg, ns: int) -> None:
    msg.header.stamp.sec = ns // 1_000_000_000
    msg.header.stamp.nanosec = ns % 1_000_000_000


def _scan(ns: int, k: int) -> LaserScan:
    msg = LaserScan()
    _stamp(msg, ns)
    msg.header.frame_id = "base_scan"
    msg.angle_min = 0.0
    msg.angle_increment = 2 * math.pi / 360
    msg.angle_max = msg.angle_min + 359 * msg.angle_increment
    msg.range_min, msg.range_max = 0.12, 3.5
    msg.ranges = [0.5 + 0.001 * i + k for i in range(360)]
    msg.ranges[7] = 0.0  # the LDS-01 "no return"
    return msg


def _odometry(ns: int, k: int) -> Odometry:
    msg = Odometry()
    _stamp(msg, ns)
    msg.header.frame_id, msg.child_frame_id = "odom", "base_footprint"
    msg.pose.pose.position.x = 0.01 * k
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x = 0.2
    msg.twist.twist.angular.z = -0.1 * k
    return msg


def _command(ns: int, k: int) -> TwistStamped:
    msg = TwistStamped()
    _stamp(msg, ns)
    msg.twist.linear.x = 0.15
    msg.twist.angular.z = 0.05 * k
    return msg


def _truth(ns: int, k: int) -> GroundTruthPose:
    msg = GroundTruthPose()
    _stamp(msg, ns)
    msg.header.frame_id = "map"
    msg.pose.position.x = 1.0 + 0.01 * k
    msg.pose.position.y = -2.0
    msg.pose.orientation.w = 1.0
    msg.localized = k % 2 == 0
    return msg


@pytest.fixture
def recording(tmp_path: Path) -> tuple[Path, dict[str, list[int]]]:
    """A file with /scan (every 4th step), /odometry, /cmd_vel and /ground_truth every step."""
    path = tmp_path / "run.mcap"
    stamps: dict[str, list[int]] = {"/scan": [], "/odometry": [], "/cmd_vel": [],
                                    "/ground_truth": []}
    metadata = {"world": "lab02", "start": "west", "profile": "turtlebot3", "seed": 3, "dt": 0.05}
    with McapRecorder(path, metadata=metadata) as recorder:
        for k in range(STEPS):
            ns = 1_000_000_000 + k * DT_NS  # cross a second boundary: sec and nanosec both matter
            if k % SCAN_EVERY == 0:
                recorder.write("/scan", _scan(ns, k), ns)
                stamps["/scan"].append(ns)
            recorder.write("/odometry", _odometry(ns, k), ns)
            recorder.write("/cmd_vel", _command(ns, k), ns)
            recorder.write("/ground_truth", _truth(ns, k), ns)
            for topic in ("/odometry", "/cmd_vel", "/ground_truth"):
                stamps[topic].append(ns)
        assert recorder.message_counts == {t: len(s) for t, s in stamps.items()}
    return path, stamps


def test_rosbags_reads_counts_stamps_and_values(recording):
    path, stamps = recording
    with AnyReader([path]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {"/scan": "sensor_msgs/msg/LaserScan",
                         "/odometry": "nav_msgs/msg/Odometry",
                         "/cmd_vel": "geometry_msgs/msg/TwistStamped",
                         "/ground_truth": "amr_msgs/msg/PoseStamped"}
        got: dict[str, list] = {t: [] for t in stamps}
        for connection, log_time, raw in reader.messages():
            got[connection.topic].append((log_time, reader.deserialize(raw, connection.msgtype)))
    for topic, expected in stamps.items():
        assert [t for t, _ in got[topic]] == expected, topic
        header_ns = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in got[topic]]
        assert header_ns == expected, topic
    scan = got["/scan"][1][1]  # k = 4
    assert len(scan.ranges) == 360
    assert scan.ranges[0] == pytest.approx(4.5) and scan.ranges[7] == 0.0
    assert scan.angle_increment == pytest.approx(2 * math.pi / 360)
    assert scan.header.frame_id == "base_scan"
    odom = got["/odometry"][5][1]
    assert odom.child_frame_id == "base_footprint"
    assert odom.pose.pose.position.x == pytest.approx(0.05)
    assert odom.twist.twist.angular.z == pytest.approx(-0.5)
    assert got["/cmd_vel"][3][1].twist.angular.z == pytest.approx(0.15)
    truth = got["/ground_truth"][3][1]
    assert truth.pose.position.x == pytest.approx(1.03) and truth.localized is False


def test_mcap_ros2_reader_decodes_with_embedded_definitions_and_metadata(recording):
    path, stamps = recording
    counts: dict[str, int] = {}
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, ros_msg in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/cmd_vel":
                k = (message.log_time - 1_000_000_000) // DT_NS
                assert ros_msg.twist.angular.z == pytest.approx(0.05 * k)
                assert ros_msg.header.stamp.nanosec == message.log_time % 10**9
    assert counts == {t: len(s) for t, s in stamps.items()}

    with open(path, "rb") as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        assert header.profile == "ros2"
        summary = reader.get_summary()
        schemas = {s.name: s for s in summary.schemas.values()}
        assert all(s.encoding == "ros2msg" for s in schemas.values())
        assert all(c.message_encoding == "cdr" for c in summary.channels.values())
        scan_definition = schemas["sensor_msgs/msg/LaserScan"].data.decode()
        assert scan_definition.startswith(
            full_message_definition("sensor_msgs/msg/LaserScan")[:40])
        assert "\n" + "=" * 80 + "\nMSG: std_msgs/Header\n" in scan_definition
        assert "MSG: builtin_interfaces/Time\n" in scan_definition
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert metadata["amr_sim"] == {"world": "lab02", "start": "west", "profile": "turtlebot3",
                                   "seed": "3", "dt": "0.05"}


def test_each_dependency_appears_once_in_the_definition():
    text = full_message_definition("nav_msgs/msg/Odometry")
    for dependency in ("std_msgs/Header", "geometry_msgs/Twist", "geometry_msgs/Vector3",
                       "geometry_msgs/Pose", "builtin_interfaces/Time"):
        assert text.count(f"MSG: {dependency}\n") == 1, dependency


def test_stamp_is_read_from_serialized_bytes():
    from rclpy.serialization import serialize_message
    ns = 1_234_567_891_011
    assert cdr_header_stamp_ns(serialize_message(_scan(ns, 0))) == ns
    assert cdr_header_stamp_ns(serialize_message(_command(ns, 0))) == ns
    assert cdr_header_stamp_ns(serialize_message(LaserScan())) is None  # zero: unset
    assert cdr_header_stamp_ns(serialize_message(LaserScan()), zero_is_unset=False) == 0
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    transform = TransformStamped()
    _stamp(transform, ns)
    tf = serialize_message(TFMessage(transforms=[transform]))
    assert cdr_header_stamp_ns(tf, in_sequence=True) == ns
    assert cdr_header_stamp_ns(serialize_message(TFMessage()), in_sequence=True) is None
    assert cdr_header_stamp_ns(b"\x00\x01\x00") is None


def test_bad_input_gives_clear_errors(tmp_path):
    with McapRecorder(tmp_path / "bad.mcap") as recorder:
        with pytest.raises(ValueError, match="absolute"):
            recorder.write("scan", LaserScan(), 0)
        with pytest.raises(ValueError, match=">= 0"):
            recorder.write("/scan", LaserScan(), -5)
        with pytest.raises(TypeError, match="not a ROS 2 message"):
            recorder.write("/scan", {"ranges": []}, 0)
        recorder.write("/scan", LaserScan(), 0)
        with pytest.raises(TypeError, match="recorded as sensor_msgs/msg/LaserScan"):
            recorder.write("/scan", Odometry(), 1)
    with pytest.raises(RuntimeError, match="closed"):
        recorder.write("/scan", LaserScan(), 2)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        McapRecorder(tmp_path / "missing" / "x.mcap")
    with AnyReader([tmp_path / "bad.mcap"]) as reader:  # the valid message survived
        assert sum(1 for _ in reader.messages()) == 1


def _attached_recording(ros, path, sent_ns, **options) -> dict[str, list[int]]:
    """Publish /scan stamped `sent_ns` and unstamped (zero) /cmd_vel; the log times per topic."""
    talker = ros.node("mcap_talker")
    listener = ros.node("mcap_listener")
    scan_pub = talker.create_publisher(LaserScan, "/scan", 10)
    cmd_pub = talker.create_publisher(TwistStamped, "/cmd_vel", 10)
    recorder = McapRecorder(path)
    graph = GraphRecorder(recorder, listener, discovery_period=0.05, **options)
    ros.spin_until(lambda: {"/scan", "/cmd_vel"} <= set(graph.topics) and graph.matched(),
                   10.0, "recorder subscriptions")
    for ns in sent_ns:
        scan_pub.publish(_scan(ns, 1))
        command = _command(ns, 2)
        command.header.stamp.sec = command.header.stamp.nanosec = 0
        cmd_pub.publish(command)
    ros.spin_until(lambda: recorder.message_counts.get("/scan", 0) == len(sent_ns)
                   and recorder.message_counts.get("/cmd_vel", 0) == len(sent_ns), 10.0,
                   "every message")
    graph.close()
    recorder.close()
    with AnyReader([path]) as reader:
        times: dict[str, list[int]] = {"/scan": [], "/cmd_vel": []}
        for connection, log_time, raw in reader.messages():
            if connection.topic not in times:
                continue  # /rosout, /parameter_events: the graph's own topics
            times[connection.topic].append(log_time)
            if connection.topic == "/scan":
                scan = reader.deserialize(raw, connection.msgtype)
                assert scan.ranges[0] == pytest.approx(1.5) and scan.ranges[7] == 0.0
    return times


def test_graph_recording_logs_every_message_when_it_arrives_on_one_clock(ros, tmp_path):
    """The default, as `ros2 bag record`: one time base whatever the stamps say."""
    sent_ns = [2_000_000_000 + k * DT_NS for k in range(5)]
    before = time.time_ns()
    times = _attached_recording(ros, tmp_path / "receive.mcap", sent_ns)
    after = time.time_ns()
    for topic in ("/scan", "/cmd_vel"):  # the node's clock (wall time here), stamps ignored
        assert len(times[topic]) == 5 and all(before <= t <= after for t in times[topic])


def test_graph_recording_can_log_header_stamps_with_zero_as_a_stamp(ros, tmp_path):
    """A lockstep simulation stamps everything with simulated time, starting at 0."""
    sent_ns = [k * DT_NS for k in range(5)]  # the first stamp is 0: not "unstamped"
    simulated_now = [123 * DT_NS]
    times = _attached_recording(ros, tmp_path / "header.mcap", sent_ns, log_time="header",
                                clock=lambda: simulated_now[0])
    assert times["/scan"] == sent_ns
    assert times["/cmd_vel"] == [0] * 5  # its stamps are zero: t = 0 too, not the wall clock
    with pytest.raises(ValueError, match="log_time"):
        GraphRecorder(McapRecorder(tmp_path / "x.mcap"), ros.node("x"), log_time="stamp")


# What rosbag2 (Jazzy) writes for a publisher seen through the graph: yaml-cpp's dump of the QoS
# vector (rosbag2_storage/qos.cpp, metadata version 9). rmw does not announce a remote
# publisher's history: "unknown", depth 0.
_INFINITE = "    sec: 9223372036\n    nsec: 854775807\n"
_ROSBAG2_BEST_EFFORT_OFFER = (
    "- history: unknown\n  depth: 0\n  reliability: best_effort\n  durability: volatile\n"
    f"  deadline:\n{_INFINITE}  lifespan:\n{_INFINITE}  liveliness: automatic\n"
    f"  liveliness_lease_duration:\n{_INFINITE}  avoid_ros_namespace_conventions: false")


def test_graph_recording_takes_every_topic_with_the_qos_its_publishers_offer(ros, tmp_path):
    """As `ros2 bag record -a`: every topic, found as it appears, its offered QoS in the file.

    A fixed list missed /path and the other outputs; every channel said reliable + volatile, so
    a replay would not latch /map and /tf_static.
    """
    from rosbags.interfaces import QosDurability, QosReliability

    from amr_common.ros.qos import LATCHED, RELIABLE_10, scan_qos
    path = tmp_path / "graph.mcap"
    talker = ros.node("graph_talker")
    scans = talker.create_publisher(LaserScan, "/scan", scan_qos(5))
    commands = talker.create_publisher(TwistStamped, "/cmd_vel", RELIABLE_10)
    latched = talker.create_publisher(Odometry, "/latched", LATCHED)
    latched.publish(_odometry(5 * DT_NS, 7))  # before the recorder exists
    hidden = talker.create_publisher(Odometry, "/_hidden", RELIABLE_10)
    recorder = McapRecorder(path)
    graph = GraphRecorder(recorder, ros.node("graph_recorder"), discovery_period=0.05)
    late = None

    def sent_and_received() -> bool:
        nonlocal late
        if late is None and "/scan" in graph.topics:  # a node that starts later
            late = talker.create_publisher(GroundTruthPose, "/late", RELIABLE_10)
        for publisher, message in ((scans, _scan(DT_NS, 0)), (commands, _command(DT_NS, 1)),
                                   (hidden, _odometry(DT_NS, 2)),
                                   (late, _truth(DT_NS, 3) if late else None)):
            if message is not None:
                publisher.publish(message)
        counts = recorder.message_counts
        return all(counts.get(t, 0) > 0 for t in ("/scan", "/cmd_vel", "/latched", "/late"))

    ros.spin_until(sent_and_received, 15.0, "a message on every topic")
    graph.close()
    recorder.close()
    with AnyReader([path]) as reader:
        connections = {c.topic: c for c in reader.connections}
        latched_messages = [reader.deserialize(raw, c.msgtype) for c, _, raw in
                            reader.messages([connections["/latched"]])]
    assert "/_hidden" not in connections  # as rosbag2: hidden topics are left out
    assert {"/rosout", "/parameter_events"} <= set(connections)
    assert [m.pose.pose.position.x for m in latched_messages] == [pytest.approx(0.07)]
    offered = {t: c.ext.offered_qos_profiles for t, c in connections.items()}
    assert [q.reliability for q in offered["/scan"]] == [QosReliability.BEST_EFFORT]
    assert [(q.reliability, q.durability) for q in offered["/latched"]] == [
        (QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)]
    assert [(q.reliability, q.durability) for q in offered["/cmd_vel"]] == [
        (QosReliability.RELIABLE, QosDurability.VOLATILE)]
    with open(path, "rb") as stream:
        channels = {c.topic: c for c in make_reader(stream).get_summary().channels.values()}
    assert channels["/scan"].metadata["offered_qos_profiles"] == _ROSBAG2_BEST_EFFORT_OFFER
    type_hash = str(talker.get_publishers_info_by_topic("/scan")[0].topic_type_hash)
    assert type_hash.startswith("RIHS01_")
    assert channels["/scan"].metadata["topic_type_hash"] == type_hash


def test_a_best_effort_publisher_joining_a_reliable_topic_is_recorded_too(ros, tmp_path):
    """The subscription was reliable for the first publisher: it would never hear this one."""
    from amr_common.ros.qos import RELIABLE_10, scan_qos
    path = tmp_path / "join.mcap"
    recorder = McapRecorder(path)
    reliable = ros.node("reliable_talker").create_publisher(LaserScan, "/scan", RELIABLE_10)
    graph = GraphRecorder(recorder, ros.node("joining_recorder"), discovery_period=0.05)
    ros.spin_until(lambda: "/scan" in graph.topics and graph.matched(), 10.0, "subscription")
    ros.spin_until(lambda: (reliable.publish(_scan(DT_NS, 0)),
                            recorder.message_counts["/scan"] > 0)[1], 10.0, "the first scan")
    ros.spin_for(0.5)  # the first publisher's scans in flight arrive
    best_effort = ros.node("best_effort_talker").create_publisher(LaserScan, "/scan",
                                                                  scan_qos(5))
    first = recorder.message_counts["/scan"]
    ros.spin_until(lambda: (best_effort.publish(_scan(2 * DT_NS, 5)),
                            recorder.message_counts["/scan"] > first)[1], 15.0,
                   "a scan of the best-effort publisher")
    graph.close()
    recorder.close()
    with AnyReader([path]) as reader:
        ranges = [reader.deserialize(raw, c.msgtype).ranges[0] for c, _, raw in
                  reader.messages([c for c in reader.connections if c.topic == "/scan"])]
    assert len(ranges) > first and ranges[first:] == [pytest.approx(5.5)] * (len(ranges) - first)


def test_offered_qos_text_is_rosbag2s_and_reads_back_with_rosbags():
    from rclpy.duration import Duration
    from rclpy.qos import (
        DurabilityPolicy,
        HistoryPolicy,
        LivelinessPolicy,
        QoSProfile,
        ReliabilityPolicy,
    )
    from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability
    from rosbags.rosbag2.metadata import parse_qos

    from amr_tools.mcap_recorder import offered_qos_yaml
    infinite = Duration(nanoseconds=2**63 - 1)
    remote = QoSProfile(history=HistoryPolicy.UNKNOWN, depth=0,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE, deadline=infinite,
                        lifespan=infinite, liveliness=LivelinessPolicy.AUTOMATIC,
                        liveliness_lease_duration=infinite)
    assert offered_qos_yaml([remote]) == _ROSBAG2_BEST_EFFORT_OFFER
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         deadline=Duration(seconds=1.5))
    text = offered_qos_yaml([remote, latched])
    assert "  deadline:\n    sec: 1\n    nsec: 500000000\n" in text
    parsed = parse_qos(text)
    assert [(q.history, q.depth, q.reliability, q.durability, q.liveliness) for q in parsed] == [
        (QosHistory.UNKNOWN, 0, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
         QosLiveliness.AUTOMATIC),
        (QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
         QosLiveliness.SYSTEM_DEFAULT)]
    assert parsed[0].deadline.sec == 9223372036 and parsed[0].deadline.nsec == 854775807
    assert offered_qos_yaml([]) == "[]" and parse_qos("[]") == []
