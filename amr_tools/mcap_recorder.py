"""Record ROS 2 messages into an MCAP file that Foxglove, `ros2 bag` and `rosbags` can open.

The file follows what rosbag2's (Jazzy) MCAP storage plugin writes: profile "ros2", one schema per
message type with encoding "ros2msg" holding the complete message definition (the type's .msg
text, then every dependency once, each preceded by a line of 80 '=' and "MSG: pkg/Type"),
channels with message encoding "cdr" and, in their metadata, `offered_qos_profiles` (the QoS each
publisher offered, the YAML text of rosbag2_storage's serialize_rclcpp_qos_vector: `ros2 bag
play` offers it again, so latched topics stay latched) and `topic_type_hash`, and messages
serialized by rclpy. Definitions are read from the .msg files installed under
<prefix>/share/<pkg>/msg/.

amr_tools.graph_recorder records every topic of a graph into it, as `ros2 bag record -a` does.
rclpy is imported lazily (only when a message is serialized or a QoS named), so this module can
be imported where ROS is absent.
"""
from __future__ import annotations

import os
import re
import struct
import sys
import threading
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from mcap.writer import CompressionType, Writer

# Same rules as rosbag2_cpp's LocalMessageDefinitionSource, so the text matches `ros2 bag record`.
_MSG_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVE_TYPES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring"})
_DELIMITER = "=" * 80 + "\n"
_MAX_DEPTH = 50

# The QoS rosbag2 (Jazzy) writes for a default reliable publisher, for messages written without a
# graph (write()): replays with a profile every subscriber (reliable or best effort) accepts.
_INFINITE = "    sec: 9223372036\n    nsec: 854775807\n"
DEFAULT_OFFERED_QOS_YAML = (
    "- history: keep_last\n  depth: 10\n  reliability: reliable\n  durability: volatile\n"
    f"  deadline:\n{_INFINITE}  lifespan:\n{_INFINITE}  liveliness: automatic\n"
    f"  liveliness_lease_duration:\n{_INFINITE}  avoid_ros_namespace_conventions: false")


def _policy_name(policy_enum: type, value: Any) -> str:
    # rclpy's enum names are rmw's strings in upper case (rmw_qos_*_policy_to_str).
    try:
        return policy_enum(value).name.lower()
    except ValueError:
        return "unknown"


def _duration_yaml(duration: Any) -> str:
    # RMW_DURATION_INFINITE (2^63 - 1 ns) comes out as rosbag2's {9223372036, 854775807}.
    nanoseconds = int(duration.nanoseconds)
    return (f"    sec: {nanoseconds // 1_000_000_000}\n"
            f"    nsec: {nanoseconds % 1_000_000_000}\n")


def offered_qos_yaml(profiles: Iterable[Any]) -> str:
    """The `offered_qos_profiles` text rosbag2 (Jazzy) writes for publishers offering `profiles`.

    `profiles`: rclpy QoSProfile, e.g. TopicEndpointInfo.qos_profile of each publisher. The text
    of yaml-cpp's dump of rosbag2_storage's QoS vector, metadata version 9: policies by name (a
    remote publisher's history is "unknown", depth 0), durations as sec/nsec; "[]" for none.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, ReliabilityPolicy
    entries = []
    for qos in profiles:
        entries.append(
            f"- history: {_policy_name(HistoryPolicy, qos.history)}\n"
            f"  depth: {int(qos.depth)}\n"
            f"  reliability: {_policy_name(ReliabilityPolicy, qos.reliability)}\n"
            f"  durability: {_policy_name(DurabilityPolicy, qos.durability)}\n"
            f"  deadline:\n{_duration_yaml(qos.deadline)}"
            f"  lifespan:\n{_duration_yaml(qos.lifespan)}"
            f"  liveliness: {_policy_name(LivelinessPolicy, qos.liveliness)}\n"
            f"  liveliness_lease_duration:\n{_duration_yaml(qos.liveliness_lease_duration)}"
            f"  avoid_ros_namespace_conventions: "
            f"{'true' if qos.avoid_ros_namespace_conventions else 'false'}")
    return "\n".join(entries) if entries else "[]"


def common_type_hash(publishers: Iterable[Any]) -> str:
    """The publishers' type hash ("RIHS01_..."), "" if none is known or they disagree (rosbag2)."""
    hashes = {str(info.topic_type_hash) for info in publishers
              if getattr(info.topic_type_hash, "version", 0) > 0}  # 0, -1: not known
    return hashes.pop() if len(hashes) == 1 else ""


def _chunk_compression() -> CompressionType:
    # mcap's zstd needs the `zstandard` package (not installed); lz4 is, and Foxglove, rosbags and
    # ros2 bag read it. Without lz4, write uncompressed chunks rather than fail.
    try:
        import lz4.frame  # noqa: F401
    except ImportError:
        return CompressionType.NONE
    return CompressionType.LZ4


class MessageDefinitionError(LookupError):
    """A .msg file needed for a schema could not be found or parsed."""


def _share_roots() -> list[Path]:
    roots = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    roots.append(Path(sys.prefix))
    return roots


def _find_msg_file(package: str, namespace: str, type_name: str) -> Path:
    for root in _share_roots():
        candidate = root / "share" / package / namespace / f"{type_name}.msg"
        if candidate.is_file():
            return candidate
    searched = ", ".join(str(r / "share") for r in _share_roots())
    raise MessageDefinitionError(
        f"no {package}/{namespace}/{type_name}.msg under {searched}: is the package installed?")


def _split_type(full_type: str) -> tuple[str, str, str]:
    parts = full_type.split("/")
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    raise MessageDefinitionError(f"message type name {full_type!r} is not 'pkg/Type' or "
                                 f"'pkg/msg/Type'")


def _dependencies(text: str, package: str) -> list[str]:
    found: set[str] = set()
    for match in _MSG_FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in _PRIMITIVE_TYPES:
            continue
        found.add(field_type if "/" in field_type else f"{package}/{field_type}")
    return sorted(found)  # rosbag2 keeps them in a std::set: sorted


def full_message_definition(full_type: str) -> str:
    """Return the concatenated "ros2msg" definition of e.g. "sensor_msgs/msg/LaserScan"."""
    seen: set[str] = set()

    def append(type_name: str, depth: int) -> str:
        if depth <= 0:
            raise MessageDefinitionError(f"definition of {full_type} nests deeper than "
                                         f"{_MAX_DEPTH}")
        package, namespace, name = _split_type(type_name)
        text = _find_msg_file(package, namespace, name).read_text(encoding="utf-8")
        result = text
        for dependency in _dependencies(text, package):
            if dependency not in seen:
                seen.add(dependency)
                result += ("\n" + _DELIMITER + f"MSG: {dependency}\n"
                           + append(dependency, depth - 1))
        return result

    return append(full_type, _MAX_DEPTH)


def ros_type_name(msg_or_type: Any) -> str:
    """"pkg/msg/Type" of an rclpy message instance or class."""
    cls = msg_or_type if isinstance(msg_or_type, type) else type(msg_or_type)
    parts = cls.__module__.split(".")
    if len(parts) < 2 or parts[1] != "msg" or not hasattr(cls, "get_fields_and_field_types"):
        raise TypeError(f"{cls!r} is not a ROS 2 message class")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def cdr_header_stamp_ns(data: bytes, in_sequence: bool = False,
                        zero_is_unset: bool = True) -> int | None:
    """header.stamp (ns) of a serialized message whose first field is a std_msgs/Header.

    CDR starts with a 4-byte encapsulation header (0x0001 little endian, 0x0000 big endian), then
    the stamp's int32 sec and uint32 nanosec. With `in_sequence`, the message starts with a
    sequence of stamped messages (tf2_msgs/TFMessage): a uint32 length, then the first element's
    stamp. None for an empty sequence, data too short to hold a stamp, a negative stamp, and a
    zero stamp unless `zero_is_unset` is false (in a simulation, t = 0 is a real instant).
    """
    offset = 8 if in_sequence else 4
    if len(data) < offset + 8 or data[0] != 0 or data[1] not in (0, 1):
        return None
    order = "<" if data[1] == 1 else ">"
    if in_sequence and struct.unpack_from(order + "I", data, 4)[0] == 0:
        return None
    sec, nanosec = struct.unpack_from(order + "iI", data, offset)
    ns = sec * 1_000_000_000 + nanosec
    return ns if ns > 0 or (ns == 0 and not zero_is_unset) else None


def stamp_layout(msg_type: type) -> bool | None:
    """Where a message type's first header is; None if it has none.

    False: its own (its first field); True: the first element's of its first field, a sequence
    of stamped messages (tf2_msgs/TFMessage, visualization_msgs/MarkerArray).
    """
    first = next(iter(msg_type.get_fields_and_field_types().items()), None)
    if first is None:
        return None
    if first[1] == "std_msgs/Header":
        return False
    element = re.fullmatch(r"sequence<(\w+)/(\w+)>", first[1])
    if element is None:
        return None
    import importlib
    element_type = getattr(importlib.import_module(f"{element[1]}.msg"), element[2], None)
    fields = element_type.get_fields_and_field_types() if element_type else {}
    return True if next(iter(fields.values()), None) == "std_msgs/Header" else None


class McapRecorder:
    """Write rclpy messages to a ROS 2 MCAP file.

    `write(topic, msg, log_time_ns)` records one message; amr_tools.graph_recorder records what
    a node's graph carries. Use as a context manager or call `close()`: the file index is written
    on close, and a file left unclosed is unreadable by most tools. Thread-safe.
    """

    def __init__(self, path: str | os.PathLike, metadata: Mapping[str, Any] | None = None,
                 chunk_size: int = 1024 * 1024) -> None:
        self.path = Path(path)
        if self.path.parent and not self.path.parent.exists():
            raise FileNotFoundError(f"cannot record to {self.path}: folder {self.path.parent} "
                                    f"does not exist")
        self._stream = open(self.path, "wb")
        self._writer = Writer(self._stream, chunk_size=chunk_size,
                              compression=_chunk_compression())
        self._writer.start(profile="ros2", library="amr_tools.mcap_recorder")
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}  # topic -> (channel id, type name)
        self._sequence: dict[int, int] = {}
        self._message_counts: dict[str, int] = {}
        self._log_time_range: tuple[int, int] | None = None  # first, last (ns)
        self._serialize: Callable[[Any], bytes] | None = None
        self._closed = False
        if metadata:
            self.write_metadata("amr_sim", metadata)

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written so far, per topic."""
        return dict(self._message_counts)

    @property
    def duration_s(self) -> float:
        """Seconds from the first message's log time to the last's (0 with fewer than two)."""
        span = self._log_time_range
        return 0.0 if span is None else (span[1] - span[0]) * 1e-9

    @property
    def closed(self) -> bool:
        """True once close() has run: messages are no longer taken."""
        return self._closed

    def write_metadata(self, name: str, values: Mapping[str, Any]) -> None:
        """Add an MCAP metadata record (values are stored as strings; None as "")."""
        data = {str(k): "" if v is None else str(v) for k, v in values.items()}
        with self._lock:
            self._check_open()
            self._writer.add_metadata(name, data)

    def add_topic(self, topic: str, type_name: str, offered_qos: str = DEFAULT_OFFERED_QOS_YAML,
                  type_hash: str = "") -> None:
        """Register `topic` before its first message, with what its publishers offer.

        `offered_qos`: offered_qos_yaml() of its publishers; `type_hash`: theirs ("RIHS01_...").
        MessageDefinitionError if the type's .msg files are missing; TypeError if the topic is
        already recorded with another type. A topic registered already keeps its metadata.
        """
        self._check_topic(topic)
        with self._lock:
            self._check_open()
            self._channel_for(topic, type_name, offered_qos, type_hash)

    def write(self, topic: str, msg: Any, log_time_ns: int) -> None:
        """Record `msg` (an rclpy message instance) on `topic` at `log_time_ns` (ns, >= 0)."""
        if self._serialize is None:
            from rclpy.serialization import serialize_message
            self._serialize = serialize_message
        type_name = ros_type_name(msg)
        self.write_serialized(topic, type_name, self._serialize(msg), log_time_ns)

    def write_serialized(self, topic: str, type_name: str, data: bytes, log_time_ns: int) -> None:
        """Record an already CDR-serialized message of type `type_name` ("pkg/msg/Type").

        A topic not registered with add_topic() gets the default publisher's QoS.
        """
        self._check_topic(topic)
        log_time_ns = int(log_time_ns)
        if log_time_ns < 0:
            raise ValueError(f"log time must be >= 0 ns, got {log_time_ns}")
        with self._lock:
            self._check_open()
            channel_id = self._channel_for(topic, type_name)
            sequence = self._sequence[channel_id]
            self._sequence[channel_id] = sequence + 1
            self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data,
                                     publish_time=log_time_ns, sequence=sequence)
            self._message_counts[topic] += 1
            span = self._log_time_range
            self._log_time_range = (log_time_ns, log_time_ns) if span is None else \
                (min(span[0], log_time_ns), max(span[1], log_time_ns))

    @staticmethod
    def _check_topic(topic: Any) -> None:
        if not isinstance(topic, str) or not topic.startswith("/"):
            raise ValueError(f"topic must be an absolute name like '/scan', got {topic!r}")

    def _channel_for(self, topic: str, type_name: str,
                     offered_qos: str = DEFAULT_OFFERED_QOS_YAML, type_hash: str = "") -> int:
        known = self._channels.get(topic)
        if known is not None:
            if known[1] != type_name:
                raise TypeError(f"topic {topic} is recorded as {known[1]}, got a {type_name}")
            return known[0]
        schema_id = self._schemas.get(type_name)
        if schema_id is None:
            definition = full_message_definition(type_name)
            schema_id = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=definition.encode("utf-8"))
            self._schemas[type_name] = schema_id
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=schema_id,
            metadata={"offered_qos_profiles": offered_qos, "topic_type_hash": type_hash})
        self._channels[topic] = (channel_id, type_name)
        self._sequence[channel_id] = 0
        self._message_counts[topic] = 0
        return channel_id

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"MCAP recorder for {self.path} is closed")

    def close(self) -> None:
        """Stop recording and write the file's index. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._writer.finish()
            finally:
                self._stream.close()

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()
