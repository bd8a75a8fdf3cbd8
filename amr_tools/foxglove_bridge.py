"""The `amr_foxglove_bridge` lifecycle node: the ROS 2 graph live in Foxglove, no apt ROS.

A Foxglove WebSocket server (foxglove-sdk, the protocol of ROS' foxglove_bridge) that forwards
every topic of the graph as ROS 2 messages: channels with message encoding "cdr" and "ros2msg"
schemas (the full .msg definitions, as in MCAP recordings), so Foxglove decodes them like
foxglove_bridge's. Topics are found by name every `discovery_period` s (nodes that start later,
such as a particle filter or a planner, appear by themselves); a ROS subscription exists only
while a Foxglove client subscribes to the topic (nothing is received otherwise), with a QoS
matched to the publishers (best effort for /scan, transient local for /map and /tf_static).
Clients may publish only on an allow-list, each topic with its types from a fixed table (a
schema name is looked up there, never imported): "2D Pose Estimate" -> /initialpose, "2D Goal
Pose" -> /goal_pose, and /cmd_vel (the Teleop panel) only with `client_teleop`; a client's CDR
message is published if it deserializes as that type. Each handshake passes the gate first
(amr_tools/foxglove_gate.py: known Origins only, both names of the protocol), which relays to
the SDK's server on a loopback TLS port.

    .venv/bin/amr_foxglove_bridge --ros-args -p autostart:=true     # ws://127.0.0.1:8765

The SDK and the gate call back from their own threads: requests are queued and carried out by a
timer in the executor's thread (rclpy entities are created and destroyed there only).
"""
from __future__ import annotations

import logging
import queue
import sys
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message

from amr_common.plugins.parameter_table import Param, between, ruled
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_parameters, read_parameters
from amr_common.ros.qos import RELIABLE_10
from amr_tools.foxglove_gate import FoxgloveGate, normalize_origin, self_signed_certificate
from amr_tools.introspection import UnknownTypeError, matched_qos, message_class
from amr_tools.mcap_recorder import (
    MessageDefinitionError,
    cdr_header_stamp_ns,
    full_message_definition,
)

PARAMETERS: dict[str, Param] = ruled({
    "host": ("127.0.0.1", "Address the WebSocket server listens on (127.0.0.1: this machine "
                          "only; 0.0.0.0: every interface, e.g. the robot's LAN)"),
    "port": (8765, "WebSocket port (foxglove_bridge's 8765)"),
    "discovery_period": (1.0, "Seconds between looks for new topics"),
    "exclude_topics": (["/parameter_events"], "Topics never forwarded"),
    "client_publish": (True, "Let Foxglove publish /initialpose and /goal_pose (2D Pose "
                             "Estimate, 2D Goal Pose)"),
    "client_teleop": (False, "Also let Foxglove publish /cmd_vel (the Teleop panel): a client "
                             "then drives the robot"),
}, port=between(0, 65535), discovery_period=between(0.05, 60.0))
# A string array without a default (rclpy cannot type an empty list): declared on its own.
ALLOWED_ORIGINS = ("allowed_origins", "WebSocket Origins allowed besides no Origin, "
                   "https://app.foxglove.dev, file:// and http(s)://localhost, 127.0.0.1, "
                   "[::1] (any port), e.g. ['https://lichtblick.example.org']")
_WORK_PERIOD_S = 0.05  # how often the executor thread picks up the SDK's requests
_MAX_PENDING_REQUESTS = 1000  # client messages beyond are dropped (clients' own data only)

# What clients may publish: topic -> the types accepted there. Schema names are looked up in
# this table (client_message_type), never imported.
CLIENT_TOPICS = {
    "/initialpose": ("geometry_msgs/msg/PoseWithCovarianceStamped",),
    "/goal_pose": ("geometry_msgs/msg/PoseStamped",),
}
TELEOP_TOPICS = {"/cmd_vel": ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")}


def client_message_type(schema_name: str) -> tuple[str, type] | None:
    """(full type name, class) of a client's schema name among the known ones, else None.

    "geometry_msgs/msg/Twist" and Foxglove's short "geometry_msgs/Twist" are the same type.
    """
    from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Twist, TwistStamped
    known = {f"geometry_msgs/msg/{c.__name__}": c
             for c in (PoseStamped, PoseWithCovarianceStamped, Twist, TwistStamped)}
    parts = schema_name.split("/")
    full = "/".join([parts[0], "msg", parts[1]]) if len(parts) == 2 else schema_name
    return (full, known[full]) if full in known else None


class FoxgloveBridgeNode(GuardedLifecycleNode):
    """Forwards the graph's topics to Foxglove clients and publishes what clients send.

    Configure starts the SDK's server (loopback, TLS) and the gate process in front of it on
    host:port; activate creates the work timer (discovery, client requests) and the ROS
    subscriptions clients ask for; deactivate destroys the timer, every ROS subscription and
    client publisher (the servers and their clients stay); cleanup and shutdown also stop the
    gate and the server (release()). Nothing is sent on the way down.
    """

    def __init__(self, node_name: str = "foxglove_bridge", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # Numbers take ints for doubles (-p discovery_period:=2): amr_common.ros.parameters.
        declare_parameters(self, PARAMETERS)
        self.declare_parameter(ALLOWED_ORIGINS[0], Parameter.Type.STRING_ARRAY,
                               ParameterDescriptor(description=ALLOWED_ORIGINS[1]))
        self.server = None
        self.gate = None
        self.port = self.sdk_port = None
        self._requests: queue.SimpleQueue = queue.SimpleQueue()
        self._reset()
        # The SDK's own log (Python logging, "foxglove.*") under this node's name.
        self.forward_python_logging("foxglove", _AbruptDisconnectIsNormal())

    def _reset(self) -> None:
        self._channels: dict[str, tuple[Any, str]] = {}   # topic -> (foxglove Channel, type)
        self._unusable: set[str] = set()                  # topics whose type cannot be sent
        self._forwarding: dict[str, Any] = {}          # topic -> rclpy raw subscription
        self._subscribers: dict[str, int] = {}            # topic -> subscribed clients
        self._client_publishers: dict[tuple[int, int], tuple[Any, type]] = {}
        self._timer = None
        self._ticks = 0

    # --- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start the servers (FAILURE: port taken, origin malformed, SDK missing)."""
        p, problems = read_parameters(self, PARAMETERS)
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        period = p["discovery_period"]
        try:
            extra_origins = frozenset(normalize_origin(o) for o in self.get_parameter_or(
                ALLOWED_ORIGINS[0], Parameter(ALLOWED_ORIGINS[0], value=[])).value)
        except ValueError as exc:
            self.get_logger().error(f"configure failed: allowed_origins: {exc}")
            return TransitionCallbackReturn.FAILURE
        self._client_topics = {**CLIENT_TOPICS, **(TELEOP_TOPICS if p["client_teleop"] else {})}
        try:
            self._start_servers(p, extra_origins)
        except Exception as exc:  # port in use, bad host, SDK missing
            self.get_logger().error(f"configure failed: cannot start the Foxglove server on "
                                    f"{p['host']}:{p['port']}: {exc}")
            self.release()
            return TransitionCallbackReturn.FAILURE
        self._exclude = set(p["exclude_topics"])
        self._discovery_ticks = max(1, round(period / _WORK_PERIOD_S))
        self.get_logger().info(
            f"Foxglove WebSocket server on ws://{p['host']}:{self.port} (open it in Foxglove: "
            f"Open connection -> Foxglove WebSocket); clients may publish "
            f"{', '.join(self._client_topics) if p['client_publish'] else 'nothing'}")
        return TransitionCallbackReturn.SUCCESS

    def _start_servers(self, p: dict[str, Any], extra_origins: frozenset[str]) -> None:
        """The SDK's server on a loopback TLS port, then the gate on host:port in front of it."""
        import foxglove
        from foxglove.websocket import Capability
        self._foxglove = foxglove
        certificate, key = self_signed_certificate()
        capabilities = [Capability.ClientPublish] if p["client_publish"] else []
        self.server = foxglove.start_server(
            name=f"amr ({self.get_fully_qualified_name()})", host="127.0.0.1", port=0,
            capabilities=capabilities, supported_encodings=["cdr"],
            server_listener=_Listener(self._requests), tls_cert=certificate, tls_key=key)
        self.sdk_port = self.server.port
        self.gate = FoxgloveGate(p["host"], p["port"], self.sdk_port, certificate, extra_origins,
                                 on_refused=self._log_refused_handshake)
        self.gate.start()
        self.port = self.gate.port

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Look for topics now and then every discovery_period; serve client requests."""
        self._discover()
        for topic, clients in self._subscribers.items():  # clients kept across deactivation
            if clients and topic in self._channels and topic not in self._forwarding:
                self._subscribe(topic)
        self._timer = self.create_timer(_WORK_PERIOD_S, self._on_timer)
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop forwarding: the timer and every ROS subscription and client publisher go."""
        self._release_ros_entities()
        return super().on_deactivate(state)

    def _release_ros_entities(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        for subscription in self._forwarding.values():
            self.destroy_subscription(subscription)
        self._forwarding.clear()
        for publisher, _ in self._client_publishers.values():
            self.destroy_publisher(publisher)
        self._client_publishers.clear()

    def release(self) -> None:
        """Stop the gate and the server (clients leave), forget every channel; sends nothing.

        The timer, every ROS subscription and client publisher go first.
        """
        self._release_ros_entities()
        for channel, _ in self._channels.values():
            channel.close()
        if self.gate is not None:
            self.gate.stop()
            self.gate = None
        if self.server is not None:
            self.server.stop()
            self.server = None
        self._reset()

    # --- the executor thread's work ---------------------------------------------------------
    def _on_timer(self) -> None:
        self._ticks += 1
        if self._ticks % self._discovery_ticks == 0:
            self._discover()
        while True:
            try:
                request = self._requests.get_nowait()
            except queue.Empty:
                return
            try:
                getattr(self, f"_handle_{request[0]}")(*request[1:])
            except Exception as exc:  # one bad request must not stop the bridge
                self.get_logger().error(f"Foxglove request {request[0]} failed: {exc!r}",
                                        throttle_duration_sec=5.0)

    def _discover(self) -> None:
        """A channel per topic with one known type; gone topics lose theirs."""
        seen = set()
        for topic, types in self.get_topic_names_and_types():
            if topic in self._exclude or topic in self._unusable:
                continue
            seen.add(topic)
            if topic in self._channels:
                continue
            if len(types) != 1:
                self._skip(topic, f"it has {len(types)} types {types}")
                continue
            try:
                message_class(types[0])  # its typesupport must be here to subscribe
                schema = full_message_definition(types[0]).encode("utf-8")
            except (UnknownTypeError, MessageDefinitionError) as exc:
                self._skip(topic, str(exc))
                continue
            channel = self._foxglove.Channel(
                topic, message_encoding="cdr",
                schema=self._foxglove.Schema(name=types[0], encoding="ros2msg", data=schema))
            self._channels[topic] = (channel, types[0])
            if self._subscribers.get(topic):
                self._subscribe(topic)
        for topic in [t for t in self._channels if t not in seen]:
            if self._subscribers.get(topic):
                continue  # a subscribed topic whose publishers come and go stays
            self._channels.pop(topic)[0].close()

    def _skip(self, topic: str, why: str) -> None:
        self._unusable.add(topic)
        self.get_logger().warning(f"not forwarding {topic}: {why}")

    def _handle_subscribe(self, topic: str) -> None:
        self._subscribers[topic] = self._subscribers.get(topic, 0) + 1
        if topic in self._channels and topic not in self._forwarding:
            self._subscribe(topic)

    def _handle_unsubscribe(self, topic: str) -> None:
        remaining = max(0, self._subscribers.get(topic, 0) - 1)
        self._subscribers[topic] = remaining
        if remaining == 0 and topic in self._forwarding:
            self.destroy_subscription(self._forwarding.pop(topic))

    def _subscribe(self, topic: str) -> None:
        channel, type_name = self._channels[topic]
        msg_type = message_class(type_name)
        qos = matched_qos(self.get_publishers_info_by_topic(topic))
        fields = iter(msg_type.get_fields_and_field_types().items())
        stamped = next(fields, None) == ("header", "std_msgs/Header")
        clock = self.get_clock()

        def forward(data: bytes) -> None:
            stamp = cdr_header_stamp_ns(data) if stamped else None
            channel.log(data, log_time=stamp if stamp is not None else clock.now().nanoseconds)

        self._forwarding[topic] = self.create_subscription(msg_type, topic, forward, qos,
                                                              raw=True)

    def _handle_advertise(self, client_id: int, channel_id: int, topic: str, schema_name: str,
                          encoding: str) -> None:
        """A publisher for a client channel on an allowed topic with a known type."""
        self._handle_unadvertise(client_id, channel_id)  # a channel id advertised again
        refused = f"refused a client channel on {topic[:80]!r}"
        accepted = self._client_topics.get(topic)
        if accepted is None:
            teleop = "" if "/cmd_vel" in self._client_topics else \
                " (/cmd_vel only with --foxglove-teleop / client_teleop)"
            self._refuse_channel(f"{refused}: clients may publish on "
                                 f"{', '.join(self._client_topics)}{teleop}")
            return
        known = client_message_type(schema_name)
        if known is None or known[0] not in accepted:
            self._refuse_channel(f"{refused}: schema {schema_name[:80]!r} is not "
                                 f"{' or '.join(accepted)}")
            return
        if encoding != "cdr":
            self._refuse_channel(f"{refused}: encoding {encoding[:20]!r} (only cdr is published)")
            return
        in_graph = dict(self.get_topic_names_and_types()).get(topic, [])
        if in_graph and known[0] not in in_graph:
            self._refuse_channel(f"{refused}: {known[0]}, but the graph carries "
                                 f"{', '.join(in_graph)} there")
            return
        publisher = self.create_publisher(known[1], topic, RELIABLE_10)
        self._client_publishers[(client_id, channel_id)] = (publisher, known[1])
        self.get_logger().info(f"a Foxglove client publishes {known[0]} on {topic}")

    def _refuse_channel(self, text: str) -> None:
        """Tell the log and the clients (Foxglove lists it among its problems)."""
        self.get_logger().warning(text, throttle_duration_sec=2.0)
        if self.server is not None:
            self.server.publish_status(text, self._foxglove.StatusLevel.Warning)

    def _log_refused_handshake(self, text: str) -> None:
        """From the gate's report thread: logged at once (a flood is throttled, not queued)."""
        self.get_logger().warning(text, throttle_duration_sec=2.0)

    def _handle_unadvertise(self, client_id: int, channel_id: int) -> None:
        entry = self._client_publishers.pop((client_id, channel_id), None)
        if entry is not None:
            self.destroy_publisher(entry[0])

    def _handle_data(self, client_id: int, channel_id: int, data: bytes) -> None:
        entry = self._client_publishers.get((client_id, channel_id))
        if entry is None:
            return  # a refused or unknown channel
        publisher, message_type = entry
        try:
            message = deserialize_message(bytes(data), message_type)
        except Exception:  # rclpy raises its own error types for a malformed CDR buffer
            self.get_logger().warning(f"dropped a malformed {message_type.__name__} from a "
                                      f"Foxglove client on {publisher.topic_name}",
                                      throttle_duration_sec=2.0)
            return
        publisher.publish(message)


class _AbruptDisconnectIsNormal(logging.Filter):
    """A client ending without the WebSocket close handshake is said at debug level.

    The SDK logs an ERROR for each; for a viewer it is normal (a closed laptop lid, a killed
    app, a dropped Wi-Fi).
    """

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno > logging.DEBUG and \
                "without closing handshake" in record.getMessage():
            record.levelno, record.levelname = logging.DEBUG, "DEBUG"
        return True


class _Listener:
    """foxglove.websocket.ServerListener: runs in the SDK's thread, so it only queues work."""

    def __init__(self, requests: queue.SimpleQueue) -> None:
        self._requests = requests

    def on_subscribe(self, client, channel) -> None:
        self._requests.put(("subscribe", channel.topic))

    def on_unsubscribe(self, client, channel) -> None:
        self._requests.put(("unsubscribe", channel.topic))

    def on_client_advertise(self, client, channel) -> None:
        self._requests.put(("advertise", client.id, channel.id, channel.topic,
                            channel.schema_name, channel.encoding))

    def on_client_unadvertise(self, client, client_channel_id: int) -> None:
        self._requests.put(("unadvertise", client.id, client_channel_id))

    def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
        if self._requests.qsize() < _MAX_PENDING_REQUESTS:  # a flood, or while inactive
            self._requests.put(("data", client.id, client_channel_id, data))


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(FoxgloveBridgeNode, args)


if __name__ == "__main__":
    sys.exit(main())
