"""The Foxglove bridge as Foxglove sees it, and as a hostile web page or client would.

A WebSocket client (the `websockets` package) speaks the Foxglove protocol to it on 127.0.0.1
under both names of the protocol, decodes /scan with the advertised ros2msg schema (mcap_ros2's
decoder, not rclpy) and publishes /initialpose back into the graph. Handshakes from other
Origins, client channels outside the allow-list and schema names outside the known types are
refused.
"""
from __future__ import annotations

import importlib
import json
import math
import signal
import socket
import ssl
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Twist
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import OccupancyGrid
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import LaserScan
from websockets.exceptions import InvalidHandshake, InvalidMessage, InvalidStatus
from websockets.sync.client import connect

from amr_common.ros.map_messages import occupancy_grid
from amr_common.ros.qos import LATCHED, scan_qos
from amr_common.ros.ros_conversions import laser_scan, seconds_to_time
from amr_tools.foxglove_bridge import FoxgloveBridgeNode
from tests.processes import terminate, wait_for

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))

SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove_bridge 3.x and the SDK
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"  # Lichtblick, @foxglove/ws-protocol, bridge 0.x
MESSAGE_DATA, CLIENT_MESSAGE_DATA = 0x01, 0x01


class FoxgloveClient:
    """The Foxglove app's side of the protocol, just enough for the tests."""

    def __init__(self, ros, port: int, subprotocol: str = SUBPROTOCOL,
                 origin: str | None = None) -> None:
        self.ros = ros
        self.socket = connect(f"ws://127.0.0.1:{port}", subprotocols=[subprotocol],
                              origin=origin, open_timeout=5.0, proxy=None, legacy=True)
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

    def wait_for_server_info(self) -> None:
        self.wait(lambda: self.server_info is not None, what="serverInfo")

    def subscribe(self, topic: str, subscription_id: int) -> dict:
        self.wait(lambda: topic in self.channels, what=f"{topic} to be advertised")
        channel = self.channels[topic]
        self.socket.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": subscription_id, "channelId": channel["id"]}]}))
        return channel

    def advertise(self, channel_id: int, topic: str, schema_name: str) -> None:
        self.socket.send(json.dumps({"op": "advertise", "channels": [{
            "id": channel_id, "topic": topic, "encoding": "cdr", "schemaName": schema_name}]}))

    def publish(self, channel_id: int, message) -> None:
        self.socket.send(struct.pack("<BI", CLIENT_MESSAGE_DATA, channel_id) +
                         serialize_message(message))

    def decoder(self, channel: dict):
        assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
        schema = Schema(id=1, name=channel["schemaName"], encoding="ros2msg",
                        data=channel["schema"].encode())
        return DecoderFactory().decoder_for("cdr", schema)

    def close(self) -> None:
        self.socket.close()


def start_bridge(ros, **parameters) -> FoxgloveBridgeNode:
    values = {"port": 0, "discovery_period": 0.1, **parameters}  # port 0: any free port
    node = ros.add(FoxgloveBridgeNode(context=ros.context, parameter_overrides=[
        Parameter(name, value=value) for name, value in values.items()]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    return node


@pytest.fixture
def bridge(ros):
    node = start_bridge(ros)
    yield node
    node.trigger_shutdown()


@pytest.mark.parametrize("subprotocol", [SUBPROTOCOL, LEGACY_SUBPROTOCOL])
def test_client_decodes_the_published_laser_scan_and_a_latched_map(ros, bridge, subprotocol):
    talker = ros.node("scan_talker")
    scans = talker.create_publisher(LaserScan, "/scan", scan_qos(5))
    grids = talker.create_publisher(OccupancyGrid, "/map", LATCHED)
    sent = laser_scan([0.5, 1.25, math.nan, 0.0, 3.0], stamp=seconds_to_time(12.5),
                      frame_id="base_scan", angle_min=0.0, angle_increment=0.25,
                      range_min=0.12, range_max=3.5, scan_time=0.2)
    grids.publish(occupancy_grid([[0, 100], [-1, 0]], 0.05, (-1.0, 2.0), "map"))
    client = FoxgloveClient(ros, bridge.port, subprotocol)
    try:
        assert client.socket.subprotocol == subprotocol  # the name the client offered
        client.wait_for_server_info()
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


@pytest.mark.slow
def test_fifty_idle_clients_and_silent_sockets_leave_the_bridge_serving(ros, bridge):
    """Clients that never read and sockets that never send a request cost the others nothing."""
    idle = [connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=[SUBPROTOCOL], proxy=None,
                    open_timeout=10.0, legacy=True) for _ in range(50)]
    silent = [socket.create_connection(("127.0.0.1", bridge.port)) for _ in range(20)]
    talker = ros.node("busy_scan_talker")
    scans = talker.create_publisher(LaserScan, "/scan", scan_qos(5))
    talker.create_timer(0.05, lambda: scans.publish(laser_scan(
        [1.0] * 360, stamp=seconds_to_time(1.0), frame_id="base_scan", angle_min=0.0,
        angle_increment=0.0174, range_min=0.12, range_max=3.5, scan_time=0.05)))
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.subscribe("/scan", 5)
        client.wait(lambda: len(client.messages.get(5, [])) >= 20, what="20 scans")
    finally:
        client.close()
        for connection in idle:
            connection.close()
        for raw in silent:
            raw.close()


def test_a_client_that_quits_without_closing_is_no_error(ros, bridge, caplog, capfd):
    """A viewer's connection reset (a closed laptop lid, a killed app) is said at debug level.

    It ends without the WebSocket close handshake: normal for a viewer, yet the SDK logged
    'Connection reset without closing handshake' as an ERROR, once per such client.
    """
    import logging
    client = FoxgloveClient(ros, bridge.port)
    client.wait_for_server_info()
    raw = client.socket.socket
    raw.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # reset
    raw.close()

    def said() -> list:
        return [r for r in caplog.records if "without closing handshake" in r.getMessage()]

    ros.spin_until(lambda: said(), timeout=10.0, message="the SDK's word on the reset")
    assert [r.levelno for r in said()] == [logging.DEBUG]
    assert "without closing handshake" not in capfd.readouterr().err
    second = FoxgloveClient(ros, bridge.port)  # still serving
    second.wait_for_server_info()
    second.close()


def initial_pose(x: float, y: float) -> PoseWithCovarianceStamped:
    pose = PoseWithCovarianceStamped()
    pose.header.frame_id = "map"
    pose.pose.pose.position.x, pose.pose.pose.position.y = x, y
    pose.pose.pose.orientation.w = 1.0
    return pose


def publish_until_received(client, channel: int, message, received: list,
                           also: tuple = ()) -> None:
    """Send `message` (and each of `also`: (channel, message)) until `received` has one."""
    def arrived() -> bool:
        for other_channel, other in also:
            client.publish(other_channel, other)
        client.publish(channel, message)
        return bool(received)

    client.wait(arrived, what=f"the client's message on channel {channel} in the graph")


def test_client_publishes_an_initial_pose_into_the_graph(ros, bridge):
    listener = ros.node("initialpose_listener")
    received = []
    listener.create_subscription(PoseWithCovarianceStamped, "/initialpose", received.append, 10)
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.wait_for_server_info()
        client.advertise(3, "/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped")
        pose = initial_pose(1.5, -0.25)
        publish_until_received(client, 3, pose, received)
    finally:
        client.close()
    assert received[0] == pose


@pytest.mark.parametrize("origin", [
    "http://evil.example.com", "https://evil.example.com:8765", "null",
    "https://app.foxglove.dev.evil.example.com", "http://localhost.evil.example.com",
    "http://127.0.0.1.evil.example.com", "https://evil.example.com/https://app.foxglove.dev"])
def test_a_web_page_of_another_origin_cannot_open_the_bridge(ros, bridge, origin):
    """A page in the user's browser sends its Origin; only known ones get a WebSocket."""
    with pytest.raises(InvalidStatus) as refused:
        FoxgloveClient(ros, bridge.port, origin=origin)
    assert refused.value.response.status_code == 403


@pytest.mark.parametrize("origin", [
    None, "https://app.foxglove.dev", "http://localhost:8080", "http://127.0.0.1",
    "https://LOCALHOST:3000", "http://[::1]:5173", "file://"])
def test_native_clients_the_foxglove_app_and_local_pages_open_the_bridge(ros, bridge, origin):
    client = FoxgloveClient(ros, bridge.port, origin=origin)
    try:
        client.wait_for_server_info()
    finally:
        client.close()


def test_an_origin_added_by_the_user_opens_the_bridge(ros):
    node = start_bridge(ros, allowed_origins=["https://lichtblick.example.org"])
    try:
        client = FoxgloveClient(ros, node.port, origin="https://lichtblick.example.org")
        client.wait_for_server_info()
        client.close()
        with pytest.raises(InvalidStatus):
            FoxgloveClient(ros, node.port, origin="https://other.example.org")
    finally:
        node.trigger_shutdown()


def test_a_client_offering_neither_protocol_name_is_refused(ros, bridge):
    with pytest.raises(InvalidStatus) as refused:
        FoxgloveClient(ros, bridge.port, subprotocol="graphql-ws")
    assert refused.value.response.status_code == 400


def test_the_sdk_server_behind_the_gate_cannot_be_opened_by_a_browser(ros, bridge):
    """The SDK's own port speaks only TLS with a certificate no browser trusts."""
    internal = bridge.sdk_port
    assert internal != bridge.port
    with pytest.raises((InvalidMessage, InvalidHandshake, ConnectionError, OSError)):
        connect(f"ws://127.0.0.1:{internal}", subprotocols=[SUBPROTOCOL], open_timeout=3.0,
                proxy=None)
    with pytest.raises(ssl.SSLCertVerificationError):  # the default trust store, as a browser
        connect(f"wss://127.0.0.1:{internal}", subprotocols=[SUBPROTOCOL], open_timeout=3.0,
                proxy=None, ssl=ssl.create_default_context())


def test_a_client_cannot_publish_outside_the_allow_list(ros, bridge):
    """/cmd_vel (it would drive the robot) and any other topic are refused; /initialpose goes."""
    listener = ros.node("allow_list_listener")
    poses, commands, others = [], [], []
    listener.create_subscription(PoseWithCovarianceStamped, "/initialpose", poses.append, 10)
    listener.create_subscription(Twist, "/cmd_vel", commands.append, 10)
    listener.create_subscription(PoseStamped, "/some_topic", others.append, 10)
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.wait_for_server_info()
        client.advertise(1, "/cmd_vel", "geometry_msgs/msg/Twist")
        client.advertise(2, "/some_topic", "geometry_msgs/msg/PoseStamped")
        client.advertise(3, "/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped")
        drive = Twist()
        drive.linear.x = 0.2
        publish_until_received(client, 3, initial_pose(0.5, 0.5), poses,
                                           also=[(1, drive), (2, PoseStamped())])
        for _ in range(10):  # the refused channels had every chance
            client.publish(1, drive)
            client.publish(2, PoseStamped())
            ros.spin_for(0.05)
        ros.spin_for(0.3)
    finally:
        client.close()
    assert poses and commands == [] and others == []
    assert "/cmd_vel" not in dict(listener.get_topic_names_and_types()) or \
        listener.count_publishers("/cmd_vel") == 0


def test_the_teleop_option_lets_a_client_publish_cmd_vel(ros):
    node = start_bridge(ros, client_teleop=True)
    listener = ros.node("teleop_listener")
    commands = []
    listener.create_subscription(Twist, "/cmd_vel", commands.append, 10)
    client = FoxgloveClient(ros, node.port)
    try:
        client.wait_for_server_info()
        client.advertise(1, "/cmd_vel", "geometry_msgs/Twist")  # Foxglove's short form
        drive = Twist()
        drive.angular.z = 0.5
        publish_until_received(client, 1, drive, commands)
    finally:
        client.close()
        node.trigger_shutdown()
    assert commands[0] == drive


def test_a_schema_name_never_imports_a_module(ros, bridge, tmp_path, monkeypatch):
    """Schema names are looked up among the known message types, never imported."""
    probe = tmp_path / "amr_hostile_probe"
    (probe / "msg").mkdir(parents=True)
    (probe / "__init__.py").write_text("IMPORTED = True\n")
    (probe / "msg" / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    listener = ros.node("schema_listener")
    poses = []
    listener.create_subscription(PoseWithCovarianceStamped, "/initialpose", poses.append, 10)
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.wait_for_server_info()
        client.advertise(1, "/initialpose", "amr_hostile_probe/msg/PoseWithCovarianceStamped")
        client.advertise(2, "/goal_pose", "amr_hostile_probe/PoseStamped")
        client.advertise(3, "/initialpose", "geometry_msgs/msg/PoseStamped")  # wrong type
        client.advertise(4, "/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped")
        publish_until_received(client, 4, initial_pose(1.0, 2.0), poses,
                                           also=[(1, initial_pose(9.0, 9.0))])
        ros.spin_for(0.3)
    finally:
        client.close()
    assert "amr_hostile_probe" not in sys.modules
    assert all(p.pose.pose.position.x == 1.0 for p in poses)


def test_a_flood_of_client_messages_is_bounded_while_the_bridge_is_inactive(ros, bridge):
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.wait_for_server_info()
        client.advertise(4, "/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped")
        ros.spin_until(lambda: bridge._client_publishers, message="the client channel")
        assert bridge.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
        for _ in range(5000):
            client.publish(4, initial_pose(1.0, 2.0))
        sizes = [-1, bridge._requests.qsize()]
        while sizes[-1] != sizes[-2]:  # until the SDK has handed over all it will
            ros.spin_for(0.3)
            sizes.append(bridge._requests.qsize())
        assert 500 <= sizes[-1] <= 1000
        assert bridge.trigger_activate() == TransitionCallbackReturn.SUCCESS
    finally:
        client.close()


def test_malformed_client_data_is_dropped(ros, bridge):
    listener = ros.node("malformed_listener")
    poses = []
    listener.create_subscription(PoseWithCovarianceStamped, "/initialpose", poses.append, 10)
    client = FoxgloveClient(ros, bridge.port)
    try:
        client.wait_for_server_info()
        client.advertise(4, "/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped")
        for garbage in (b"", b"\x00\x01\x00\x00", b"\xff" * 7):
            client.socket.send(struct.pack("<BI", CLIENT_MESSAGE_DATA, 4) + garbage)
        publish_until_received(client, 4, initial_pose(1.0, 2.0), poses)
    finally:
        client.close()
    assert poses[0] == initial_pose(1.0, 2.0)


def test_a_taken_port_fails_configure_with_a_message(ros, bridge):
    taken = [Parameter("port", value=bridge.port)]
    second = ros.add(FoxgloveBridgeNode("second_bridge", context=ros.context,
                                        parameter_overrides=taken))
    assert second.trigger_configure() == TransitionCallbackReturn.FAILURE


JS_CLIENT = Path(__file__).resolve().parent / "foxglove_js"


@pytest.fixture(scope="session")
def foxglove_js():
    """tests/foxglove_js with its pinned packages (npm ci from the npm registry, once)."""
    lock = JS_CLIENT / "package-lock.json"
    stamp = JS_CLIENT / "node_modules" / ".amr-installed"
    if not stamp.is_file() or stamp.read_text() != lock.read_text():
        subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--loglevel=error"],
                       cwd=JS_CLIENT, check=True, timeout=300)
        stamp.write_text(lock.read_text())
    return JS_CLIENT / "client.mjs"


@pytest.mark.slow
def test_foxgloves_own_javascript_client_decodes_and_publishes(ros, bridge, foxglove_js):
    """@foxglove/ws-protocol's FoxgloveClient (foxglove.websocket.v1 only, as Lichtblick)."""
    talker = ros.node("js_talker")
    scans = talker.create_publisher(LaserScan, "/scan", scan_qos(5))
    grids = talker.create_publisher(OccupancyGrid, "/map", LATCHED)
    grids.publish(occupancy_grid([[0, 100], [-1, 0]], 0.05, (-1.0, 2.0), "map"))
    talker.create_timer(0.05, lambda: scans.publish(laser_scan(
        [0.5, math.nan, 2.0], stamp=seconds_to_time(7.25), frame_id="base_scan",
        angle_min=-0.5, angle_increment=0.5, range_min=0.1, range_max=3.5, scan_time=0.05)))
    poses = []
    talker.create_subscription(PoseWithCovarianceStamped, "/initialpose", poses.append, 10)
    client = subprocess.Popen(["node", str(foxglove_js), f"ws://127.0.0.1:{bridge.port}"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ros.spin_until(lambda: poses or client.poll() is not None, 30.0,
                       "the JavaScript client's /initialpose")
    finally:
        terminate(client, 2.0)
    out, err = client.communicate()
    assert poses, f"exit {client.returncode}: {err}"
    decoded = {line["topic"]: line["message"] for line in map(json.loads, out.splitlines()[:2])}
    assert decoded["/scan"] == {"frame_id": "base_scan",
                                "stamp": {"sec": 7, "nanosec": 250_000_000},
                                "angle_min": -0.5, "angle_increment": 0.5,
                                "ranges": [0.5, None, 2.0]}
    assert decoded["/map"] == {"width": 2, "height": 2, "data": [0, 100, -1, 0]}
    assert poses[0].header.frame_id == "map"
    assert (poses[0].pose.pose.position.x, poses[0].pose.pose.position.y) == (0.75, -0.5)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.slow
@pytest.mark.parametrize("ending", [signal.SIGINT, signal.SIGKILL])
def test_the_gate_process_ends_with_the_bridge(ending):
    """Ctrl-C or a crash of the bridge's process: its gate process ends and frees the port."""
    port = free_port()
    bridge = subprocess.Popen([str(Path(sys.executable).parent / "amr_foxglove_bridge"),
                               "--ros-args", "-p", "autostart:=true", "-p", f"port:={port}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        def opens() -> bool:
            try:
                with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], proxy=None,
                             open_timeout=2.0):
                    return True
            except (OSError, InvalidHandshake):
                return False

        wait_for(opens, 60.0, "the bridge's WebSocket")
        bridge.send_signal(ending)
        bridge.wait(timeout=30.0)

        def refused() -> bool:
            with socket.socket() as probe:
                return probe.connect_ex(("127.0.0.1", port)) != 0

        wait_for(refused, 10.0, "the gate to stop listening")
    finally:
        terminate(bridge, 2.0)


@pytest.mark.parametrize("script", ["run_sim", "run_robot"])
@pytest.mark.parametrize("options", [
    ["--foxglove-teleop"], ["--foxglove-origin", "https://a.example.org"],
    ["--foxglove", "--foxglove-origin", "null"], ["--foxglove", "--foxglove-origin", "*"],
    ["--foxglove", "--foxglove-origin", "https://a.example.org/page"]])
def test_foxglove_option_mistakes_are_one_line_errors(script, options, capsys):
    module = importlib.import_module(script)
    with pytest.raises(SystemExit) as stopped:
        module.parse_args(options)
    assert stopped.value.code == 2
    assert "--foxglove" in capsys.readouterr().err.splitlines()[-1]


def test_foxglove_options_reach_the_bridge_node(ros):
    import run_sim

    from launch_common import make_viewer_nodes
    args = run_sim.parse_args(["--foxglove", "--foxglove-teleop", "--foxglove-origin",
                               "HTTPS://Lichtblick.Example.org/", "--foxglove-port", "0"])
    node = ros.add(make_viewer_nodes(ros.context, args)[0])
    assert node.get_parameter("client_teleop").value is True
    assert node.get_parameter("allowed_origins").value == ["https://lichtblick.example.org"]
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    try:
        client = FoxgloveClient(ros, node.port, origin="https://lichtblick.example.org")
        client.close()
    finally:
        node.trigger_shutdown()


@pytest.mark.slow
def test_run_sim_starts_the_bridge_before_the_simulation(tmp_path):
    import run_sim
    report = tmp_path / "run.json"
    assert run_sim.main(["--duration", "2", "--foxglove", "--foxglove-port", "0",
                         "--report", str(report)]) == 0
    assert json.loads(report.read_text())["nodes"] == [
        "foxglove_bridge", "wall_follower", "amr_simulator"]


# What Foxglove's 3D panel draws, by ROS 2 type name (its ThreeDeeRender/ros.ts): TF, markers,
# occupancy grids, point clouds, laser scans, poses (stamped, with covariance, arrays), paths,
# camera info, images and polygons. Not nav_msgs/Odometry, nor a package's own types such as
# amr_msgs/PoseStamped.
FOXGLOVE_3D_TYPES = {f"{package}/msg/{name}" for package, names in {
    "tf2_msgs": ["TFMessage"], "visualization_msgs": ["Marker", "MarkerArray"],
    "nav_msgs": ["OccupancyGrid", "Path"],
    "sensor_msgs": ["PointCloud2", "LaserScan", "CameraInfo", "Image", "CompressedImage"],
    "geometry_msgs": ["TransformStamped", "PoseStamped", "PoseWithCovarianceStamped",
                      "PoseArray", "PolygonStamped"]}.items() for name in names}


def _goal_run_topic_types() -> dict[str, list[str]]:
    """{topic: types} of run_sim.py --goal's graph (every node configured: all topics exist)."""
    import run_sim
    from sim_session import SimSession
    args = run_sim.parse_args(["--world", "lab02", "--goal", "inner_far"])
    world, map_world, starts, _ = run_sim._prepare(args)
    session = SimSession(args, world, starts[0], map_world=map_world)
    try:
        for node in [*session.viewer_nodes, *session.control_nodes, session.simulator_node]:
            assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS, node.get_name()
        outputs = {"/amcl_pose", "/particles", "/path", "/scan", "/map", "/tf"}
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            topics = dict(session.manager.get_topic_names_and_types())
            if outputs <= set(topics):
                return topics
            session.executor.spin_once(timeout_sec=0.05)
        pytest.fail(f"the --goal graph lacks {sorted(outputs - set(topics))}")
    finally:
        session.close()


def test_every_topic_of_the_shipped_layout_is_one_foxglove_draws():
    """The 3D panel showed /pose (amr_msgs/PoseStamped), which Foxglove cannot draw."""
    from amr_tools.introspection import message_class
    layout = json.loads((Path(__file__).resolve().parent.parent / "docs" /
                         "foxglove-layout.json").read_text())
    panel = layout["configById"]["3D!amr"]
    assert panel["followTf"] == "map"
    assert panel["publish"]["poseEstimateTopic"] == "/initialpose"
    assert panel["publish"]["poseTopic"] == "/goal_pose"
    graph = _goal_run_topic_types()
    drawn = {topic: graph.get(topic) for topic in panel["topics"]}
    assert {t: types for t, types in drawn.items()
            if types is None or len(types) != 1 or types[0] not in FOXGLOVE_3D_TYPES} == {}
    # The filter's estimate (as AMCL's), the path, the map, the scan and the particles; what
    # the world has beyond the map (walls it lacks, movers).
    assert {"/amcl_pose", "/path", "/map", "/map_markers", "/scan", "/particles",
            "/world_markers"} <= set(drawn)
    for panel_id, config in layout["configById"].items():  # the other panels' topics
        if "topicPath" in config:
            assert config["topicPath"] in graph, panel_id
        for path in (p["value"] for p in config.get("paths", [])):  # a plot: to a number
            topic, *fields = path.split(".")
            assert topic in graph, (panel_id, path)
            message = message_class(graph[topic][0])()
            for field in fields:
                message = getattr(message, field)
            assert isinstance(message, float), (panel_id, path)
