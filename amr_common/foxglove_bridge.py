"""The `amr_foxglove_bridge` lifecycle node: the ROS 2 graph live in Foxglove, no apt ROS.

A Foxglove WebSocket server (foxglove-sdk, the protocol of ROS' foxglove_bridge) that forwards
every topic of the graph as ROS 2 messages: channels with message encoding "cdr" and "ros2msg"
schemas (the full .msg definitions, as in MCAP recordings), so Foxglove decodes them like
foxglove_bridge's. Topics are found by name every `discovery_period` s (nodes that start later,
such as a particle filter or a planner, appear by themselves); a ROS subscription exists only
while a Foxglove client subscribes to the topic (nothing is received otherwise), with a QoS
matched to the publishers (best effort for /scan, transient local for /map and /tf_static).
Client publishing ("2D Pose Estimate" -> /initialpose, "2D Goal Pose" -> /goal_pose, the Publish
panel): CDR messages from the client are published as they are.

    .venv/bin/amr_foxglove_bridge --ros-args -p autostart:=true     # ws://127.0.0.1:8765

The SDK calls the listener from its own thread: requests are queued and carried out by a timer
in the executor's thread (rclpy entities are created and destroyed there only).
"""
from __future__ import annotations

import queue
import sys
from typing import Any

from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn

from amr_common.introspection import UnknownTypeError, matched_qos, message_class
from amr_common.lifecycle_node import GuardedLifecycleNode
from amr_common.mcap_recorder import (
    MessageDefinitionError,
    cdr_header_stamp_ns,
    full_message_definition,
)
from amr_common.node_runner import run_lifecycle_node
from amr_common.parameters import declare_parameters, finite
from amr_common.qos import RELIABLE_10

PARAMETERS: dict[str, tuple[Any, str]] = {
    "host": ("127.0.0.1", "Address the WebSocket server listens on (127.0.0.1: this machine "
                          "only; 0.0.0.0: every interface, e.g. the robot's LAN)"),
    "port": (8765, "WebSocket port (foxglove_bridge's 8765)"),
    "discovery_period": (1.0, "Seconds between looks for new topics"),
    "exclude_topics": (["/parameter_events"], "Topics never forwarded"),
    "client_publish": (True, "Let Foxglove publish (2D Pose Estimate, 2D Goal Pose, ...)"),
}
_WORK_PERIOD_S = 0.05  # how often the executor thread picks up the SDK's requests


class FoxgloveBridgeNode(GuardedLifecycleNode):
    """Forwards the graph's topics to Foxglove clients and publishes what clients send.

    Configure starts the WebSocket server; activate creates the work timer (discovery, client
    requests) and the ROS subscriptions clients ask for; deactivate destroys the timer, every
    ROS subscription and client publisher (the server and its clients stay); cleanup and
    shutdown also stop the server (release()). Nothing is sent on the way down.
    """

    def __init__(self, node_name: str = "foxglove_bridge", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # Numbers take ints for doubles (-p discovery_period:=2): amr_common.parameters.
        declare_parameters(self, PARAMETERS)
        self.server = None
        self._requests: queue.SimpleQueue = queue.SimpleQueue()
        self._reset()

    def _reset(self) -> None:
        self._channels: dict[str, tuple[Any, str]] = {}   # topic -> (foxglove Channel, type)
        self._unusable: set[str] = set()                  # topics whose type cannot be sent
        self._forwarding: dict[str, Any] = {}          # topic -> rclpy raw subscription
        self._subscribers: dict[str, int] = {}            # topic -> subscribed clients
        self._client_publishers: dict[tuple[int, int], Any] = {}
        self._timer = None
        self._ticks = 0

    # --- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start the WebSocket server (FAILURE if the port is taken or the SDK is missing)."""
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        port = p["port"]
        if isinstance(port, bool) or not (isinstance(port, int) and 0 <= port <= 65535):
            self.get_logger().error(f"configure failed: port must be 0-65535 (got {p['port']})")
            return TransitionCallbackReturn.FAILURE
        period = p["discovery_period"]
        if not (finite(period) and 0.05 <= period <= 60.0):
            self.get_logger().error(f"configure failed: discovery_period must be 0.05-60 s "
                                    f"(got {period!r})")
            return TransitionCallbackReturn.FAILURE
        try:
            import foxglove
            from foxglove.websocket import Capability
            capabilities = [Capability.ClientPublish] if p["client_publish"] else []
            self.server = foxglove.start_server(
                name=f"amr ({self.get_fully_qualified_name()})", host=p["host"],
                port=p["port"], capabilities=capabilities, supported_encodings=["cdr"],
                server_listener=_Listener(self._requests))
        except Exception as exc:  # port in use, bad host, SDK missing
            self.get_logger().error(f"configure failed: cannot start the Foxglove server on "
                                    f"{p['host']}:{p['port']}: {exc}")
            return TransitionCallbackReturn.FAILURE
        self._foxglove = foxglove
        self._exclude = set(p["exclude_topics"])
        self._discovery_ticks = max(1, round(period / _WORK_PERIOD_S))
        self.port = self.server.port
        self.get_logger().info(f"Foxglove WebSocket server on ws://{p['host']}:{self.port} "
                               f"(open it in Foxglove: Open connection -> Foxglove WebSocket)")
        return TransitionCallbackReturn.SUCCESS

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
        for publisher in self._client_publishers.values():
            self.destroy_publisher(publisher)
        self._client_publishers.clear()

    def release(self) -> None:
        """Stop the server (clients are disconnected) and forget every channel; sends nothing.

        The timer, every ROS subscription and client publisher go first.
        """
        self._release_ros_entities()
        for channel, _ in self._channels.values():
            channel.close()
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
        if encoding != "cdr":
            self.get_logger().warning(f"client channel {topic} uses encoding '{encoding}': only "
                                      "cdr is published")
            return
        publisher = self.create_publisher(message_class(schema_name), topic, RELIABLE_10)
        self._client_publishers[(client_id, channel_id)] = publisher
        self.get_logger().info(f"a Foxglove client publishes {schema_name} on {topic}")

    def _handle_unadvertise(self, client_id: int, channel_id: int) -> None:
        publisher = self._client_publishers.pop((client_id, channel_id), None)
        if publisher is not None:
            self.destroy_publisher(publisher)

    def _handle_data(self, client_id: int, channel_id: int, data: bytes) -> None:
        publisher = self._client_publishers.get((client_id, channel_id))
        if publisher is not None:
            publisher.publish(bytes(data))


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
        self._requests.put(("data", client.id, client_channel_id, data))


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(FoxgloveBridgeNode, args)


if __name__ == "__main__":
    sys.exit(main())
