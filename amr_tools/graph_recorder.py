"""Record every topic of a ROS 2 graph into an MCAP file, as `ros2 bag record -a` does.

GraphRecorder looks for topics when it starts and then every `discovery_period` s (nodes that
start later, such as a planner's /path or a Foxglove client's /initialpose, are recorded from
their first message on), and subscribes to each topic once it has a publisher:
- with a QoS every publisher is compatible with (amr_tools.introspection.matched_qos, as
  rosbag2's adapt_request_to_offers): best effort if any publisher offers only that, transient
  local if all of them keep their last messages for late joiners (a latched /map or /tf_static
  is recorded even if it was published before the recorder started);
- its channel holds the QoS each of those publishers offered and their type hash, as rosbag2
  stores them (McapRecorder.add_topic), so `ros2 bag play` offers them again.
A publisher that joins later with a weaker QoS (best effort or volatile where the subscription
asked for more) gets the subscription replaced by a compatible one (rosbag2 only warns). Hidden
topics (a name part starting with '_'), topics with several types and types whose definition is
not installed are left out, each said once in the node's log.

Messages arrive serialized (raw subscriptions) and are written as they are: no Python
deserialization, so recording barely slows the graph.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Iterable

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.topic_or_service_is_hidden import topic_or_service_is_hidden

from amr_tools.introspection import UnknownTypeError, matched_qos, message_class
from amr_tools.mcap_recorder import (
    McapRecorder,
    MessageDefinitionError,
    cdr_header_stamp_ns,
    common_type_hash,
    offered_qos_yaml,
    stamp_layout,
)

_QOS_DEPTH = 100  # room for bursts while the executor is busy elsewhere


@dataclass
class _Recorded:
    """A topic being recorded: its subscription, that subscription's QoS, publishers seen."""

    type_name: str
    subscription: Any
    qos: QoSProfile
    publishers: int


class GraphRecorder:
    """Records what every publisher of `node`'s graph sends into `recorder`.

    Every message of a file is logged on one time base:
    - log_time "receive" (default, as `ros2 bag record`): when it arrived, on `clock`;
    - log_time "header": its header stamp (a zero stamp included; for /tf the first transform's),
      `clock` for types without a header. For graphs whose every publisher stamps on `clock`'s
      time base, e.g. a lockstep simulation stamping with simulated time: the log time is then
      exact.
    `clock` returns nanoseconds; default the node's clock (simulated time with use_sim_time).
    The node must be spun (its discovery timer and subscriptions run in its executor); close()
    before recorder.close().
    """

    def __init__(self, recorder: McapRecorder, node: Any, *, log_time: str = "receive",
                 clock: Callable[[], int] | None = None, exclude: Iterable[str] = (),
                 discovery_period: float = 0.5) -> None:
        if log_time not in ("receive", "header"):
            raise ValueError(f"log_time must be 'receive' or 'header', got {log_time!r}")
        self.recorder = recorder
        self.node = node
        self._header_time = log_time == "header"
        self._clock = clock or (lambda: node.get_clock().now().nanoseconds)
        self._exclude = set(exclude)
        self._topics: dict[str, _Recorded] = {}
        self._left_out: set[str] = set()
        self.discover()
        self._timer = node.create_timer(discovery_period, self.discover)

    @property
    def topics(self) -> list[str]:
        """The topics being recorded."""
        return sorted(self._topics)

    def discover(self) -> list[str]:
        """Start recording the topics that gained a publisher since the last look; their names.

        Runs every discovery_period; call it yourself at a moment you know new publishers
        exist (e.g. after the nodes are configured, before they publish).
        """
        if self.recorder.closed:
            return []
        started = []
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._topics:
                self._adapt_to_new_publishers(topic)
            elif topic not in self._left_out and topic not in self._exclude \
                    and not topic_or_service_is_hidden(topic) and self._start(topic, types):
                started.append(topic)
        return started

    def matched(self) -> bool:
        """True once every recorded topic's subscription is matched with its publishers."""
        return all(entry.subscription.get_publisher_count() >= entry.publishers
                   for entry in self._topics.values())

    def _start(self, topic: str, types: list[str]) -> bool:
        publishers = self.node.get_publishers_info_by_topic(topic)
        if not publishers:
            return False  # looked at again when a publisher appears: its QoS decides
        if len(types) != 1:
            return self._leave_out(topic, f"it has {len(types)} types: {', '.join(types)}")
        try:
            msg_type = message_class(types[0])
            self.recorder.add_topic(topic, types[0], offered_qos_yaml(
                info.qos_profile for info in publishers), common_type_hash(publishers))
        except (UnknownTypeError, MessageDefinitionError, TypeError) as exc:
            return self._leave_out(topic, str(exc))
        qos = matched_qos(publishers, depth=_QOS_DEPTH)
        self._topics[topic] = _Recorded(types[0], self._subscribe(topic, types[0], msg_type, qos),
                                        qos, len(publishers))
        return True

    def _leave_out(self, topic: str, why: str) -> bool:
        self._left_out.add(topic)
        self.node.get_logger().warning(f"not recording {topic}: {why}")
        return False

    def _adapt_to_new_publishers(self, topic: str) -> None:
        """A new publisher the subscription cannot hear: subscribe again, compatibly."""
        entry = self._topics[topic]
        count = self.node.count_publishers(topic)
        if count == entry.publishers:
            return
        entry.publishers = count
        needed = matched_qos(self.node.get_publishers_info_by_topic(topic), depth=_QOS_DEPTH)
        weaker_reliability = entry.qos.reliability == ReliabilityPolicy.RELIABLE and \
            needed.reliability == ReliabilityPolicy.BEST_EFFORT
        weaker_durability = entry.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL and \
            needed.durability == DurabilityPolicy.VOLATILE
        if not (weaker_reliability or weaker_durability):
            return
        # Volatile: the latched messages already recorded must not come again.
        qos = QoSProfile(depth=_QOS_DEPTH, history=entry.qos.history,
                         reliability=needed.reliability if weaker_reliability
                         else entry.qos.reliability, durability=DurabilityPolicy.VOLATILE)
        msg_type = entry.subscription.msg_type
        self.node.destroy_subscription(entry.subscription)
        entry.subscription = self._subscribe(topic, entry.type_name, msg_type, qos)
        entry.qos = qos
        self.node.get_logger().info(
            f"recording {topic} {'best effort' if weaker_reliability else 'volatile'} from now "
            f"on: a new publisher offers only that")

    def _subscribe(self, topic: str, type_name: str, msg_type: type, qos: QoSProfile) -> Any:
        layout = stamp_layout(msg_type) if self._header_time else None
        recorder, clock = self.recorder, self._clock

        def record(data: bytes) -> None:
            if recorder.closed:
                return
            stamp = None if layout is None else \
                cdr_header_stamp_ns(data, in_sequence=layout, zero_is_unset=False)
            recorder.write_serialized(topic, type_name, data, clock() if stamp is None else stamp)

        return self.node.create_subscription(msg_type, topic, record, qos, raw=True)

    def close(self) -> None:
        """Stop looking for topics and destroy the subscriptions (the file stays open)."""
        if self._timer is not None:
            self.node.destroy_timer(self._timer)
            self._timer = None
        for entry in self._topics.values():
            self.node.destroy_subscription(entry.subscription)
        self._topics.clear()


__all__ = ["GraphRecorder"]
