"""The Foxglove bridge as Foxglove sees it.

A WebSocket client (the `websockets` package) speaks the Foxglove protocol to it on 127.0.0.1,
decodes /scan with the advertised ros2msg schema (mcap_ros2's decoder, not rclpy) and publishes
/initialpose back into the graph.
"""
from __future__ import annotations

import json
import math
import struct

import pytest
from geometry_msgs.msg import PoseWithCovarianceStamped
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import OccupancyGrid
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import LaserScan
from websockets.sync.client import connect

from amr_common.foxglove_bridge import FoxgloveBridgeNode
from amr_common.map_messages import occupancy_grid
from amr_common.qos import LATCHED, scan_qos
from amr_common.ros_conversions import laser_scan, seconds_to_time

SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove_bridge 3.x and the SDK; as foxglove.websocket.v1
MESSAGE_DATA, CLIENT_MESSAGE_DATA = 0x01, 0x01


class FoxgloveClient:
    """The Foxglove app's side of the protocol, just enough for the tests."""

    def __init__(self, ros, port: int) -> None:
        self.ros = ros
        self.socket = connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL],
                              open_timeout=5.0, legacy=True)
        self.channels: dict[str, dict] = {}
        self.messages: dict[int, list[tuple[int, bytes]]] = {}
        self.server_info: dict | None = None

    def poll(self) -> None:
        """Spin ROS a little and take whatever the server sent."""
        self.ros.executor.spin_once(timeout_sec=0.01)
        while True:
            try:
                frame = self.socket.recv(timeout=0.005)
            except TimeoutError:
                return
            if isinstance(frame, bytes):
                assert frame[0] == MESSAGE_DATA
                subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                self.messages.setdefault(subscription, []).append((log_time, frame[13:]))
                continue
            message = json.loads(frame)
            if message["op"] == "serverInfo":
                self.server_info = message
            elif message["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in message["channels"]})
            elif message["op"] == "unadvertise":
                gone = set(message["channelIds"])
                self.channels = {t: c for t, c in self.channels.items() if c["id"] not in gone}

    def wait(self, condition, timeout: float = 10.0, what: str = "the server") -> None:
        self.ros.spin_until(lambda: (self.poll(), condition())[1], timeout=timeout,
                            message=what)

    def subscribe(self, topic: str, subscription_id: int) -> dict:
        self.wait(lambda: topic in self.channels, what=f"{topic} to be advertised")
        channel = self.channels[topic]
        self.socket.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": subscription_id, "channelId": channel["id"]}]}))
        return channel

    def decoder(self, channel: dict):
        assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
        schema = Schema(id=1, name=channel["schemaName"], encoding="ros2msg",
                        data=channel["schema"].encode())
        return DecoderFactory().decoder_for("cdr", schema)

    def close(self) -> None:
        self.socket.close()


@pytest.fixture
def bridge(ros):
    node = ros.add(FoxgloveBridgeNode(context=ros.context, parameter_overrides=[
        Parameter("port", value=0), Parameter("discovery_period", value=0.1)]))  # any free port
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    yield node
    node.trigger_shutdown()


def test_client_decodes_the_published_laser_scan_and_a_latched_map(ros, bridge):
    talker = ros.node("scan_talker")
    scans = talker.create_publisher(LaserScan, "/scan", scan_qos(5))
    grids = talker.create_publisher(OccupancyGrid, "/map", LATCHED)
    sent = laser_scan([0.5, 1.25, math.nan, 0.0, 3.0], stamp=seconds_to_time(12.5),
                      frame_id="base_scan", angle_min=0.0, angle_increment=0.25,
                      range_min=0.12, range_max=3.5, scan_time=0.2)
    grids.publish(occupancy_grid([[0, 100], [-1, 0]], 0.05, (-1.0, 2.0), "map"))
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.wait(lambda: client.server_info is not None, what="serverInfo")
        assert "clientPublish" in client.server_info["capabilities"]
        scan_channel = client.subscribe("/scan", 7)
        map_channel = client.subscribe("/map", 8)
        assert scan_channel["schemaName"] == "sensor_msgs/msg/LaserScan"

        def scan_arrived() -> bool:
            scans.publish(sent)  # best effort: repeat until the bridge's subscription is up
            return bool(client.messages.get(7))

        client.wait(scan_arrived, what="a /scan through the bridge")
        client.wait(lambda: client.messages.get(8), what="the latched /map")
    finally:
        client.close()
    log_time, payload = client.messages[7][0]
    assert log_time == 12_500_000_000  # the header stamp
    # (not compared byte for byte: CDR padding bytes are not initialised by the serializer)
    got = client.decoder(scan_channel)(payload)
    assert got.header.frame_id == "base_scan"
    assert (got.header.stamp.sec, got.header.stamp.nanosec) == (12, 500_000_000)
    assert (got.angle_min, got.angle_increment, got.range_min, got.range_max) == \
        pytest.approx((0.0, 0.25, 0.12, 3.5))
    assert list(got.ranges[:2]) == [0.5, 1.25] and math.isnan(got.ranges[2])
    assert list(got.ranges[3:]) == [0.0, 3.0]
    grid = client.decoder(map_channel)(client.messages[8][0][1])
    assert (grid.info.width, grid.info.height) == (2, 2)
    assert list(grid.data) == [0, 100, -1, 0]


def test_client_publishes_an_initial_pose_into_the_graph(ros, bridge):
    listener = ros.node("initialpose_listener")
    received = []
    listener.create_subscription(PoseWithCovarianceStamped, "/initialpose", received.append, 10)
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.wait(lambda: client.server_info is not None, what="serverInfo")
        client.socket.send(json.dumps({"op": "advertise", "channels": [{
            "id": 3, "topic": "/initialpose", "encoding": "cdr",
            "schemaName": "geometry_msgs/msg/PoseWithCovarianceStamped"}]}))
        pose = PoseWithCovarianceStamped()
        pose.header.frame_id = "map"
        pose.pose.pose.position.x, pose.pose.pose.position.y = 1.5, -0.25
        pose.pose.pose.orientation.w = 1.0
        frame = struct.pack("<BI", CLIENT_MESSAGE_DATA, 3) + serialize_message(pose)

        def arrived() -> bool:
            client.socket.send(frame)
            return bool(received)

        client.wait(arrived, what="the client's /initialpose in the graph")
    finally:
        client.close()
    assert received[0] == pose


def test_a_taken_port_fails_configure_with_a_message(ros, bridge):
    taken = [Parameter("port", value=bridge.port)]
    second = ros.add(FoxgloveBridgeNode("second_bridge", context=ros.context,
                                        parameter_overrides=taken))
    assert second.trigger_configure() == TransitionCallbackReturn.FAILURE


@pytest.mark.slow
def test_run_sim_starts_the_bridge_before_the_simulation(tmp_path):
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
    import run_sim
    report = tmp_path / "run.json"
    assert run_sim.main(["--duration", "2", "--foxglove", "--foxglove-port", "0",
                         "--report", str(report)]) == 0
    assert json.loads(report.read_text())["nodes"] == [
        "foxglove_bridge", "wall_follower", "amr_simulator"]


def test_shipped_layout_shows_the_map_frame_and_the_simulators_topics():
    from pathlib import Path
    layout = json.loads((Path(__file__).resolve().parent.parent / "docs" /
                         "foxglove-layout.json").read_text())
    panel = layout["configById"]["3D!amr"]
    assert panel["followTf"] == "map"
    assert {"/map", "/map_markers", "/scan"} <= set(panel["topics"])
    assert panel["publish"]["poseEstimateTopic"] == "/initialpose"
    assert panel["publish"]["poseTopic"] == "/goal_pose"
