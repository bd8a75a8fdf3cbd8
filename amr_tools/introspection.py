"""Graph introspection without ros2cli.

Message classes by type name, publisher-matched QoS, messages as plain data (for echo, CSV and
YAML), and the hidden probe node of the tools. Used by the Foxglove bridge and
scripts/topic.py, lifecycle.py and ros_graph.py.
"""
from __future__ import annotations

import array
import importlib
import math
import os
import time
from typing import Any, Iterable

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


class UnknownTypeError(LookupError):
    """A type name that is malformed or whose package is not installed in this environment."""


def message_class(type_name: str) -> type:
    """The message class of "pkg/msg/Type" (or "pkg/Type"), imported at run time."""
    parts = type_name.strip().split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(p.isidentifier() for p in parts):
        raise UnknownTypeError(f"'{type_name}' is not a message type name like "
                               "'sensor_msgs/msg/LaserScan'")
    package, namespace, name = parts
    try:
        module = importlib.import_module(f"{package}.{namespace}")
        cls = getattr(module, name)
    except (ImportError, AttributeError):
        raise UnknownTypeError(f"message type '{type_name}' is not installed here (is the "
                               f"'{package}' package in this environment?)") from None
    if not hasattr(cls, "get_fields_and_field_types"):
        raise UnknownTypeError(f"'{type_name}' is not a message type")
    return cls


def matched_qos(publishers: Iterable, depth: int = 10) -> QoSProfile:
    """A subscription QoS that receives from every publisher in `publishers`.

    `publishers`: rclpy TopicEndpointInfo. Best effort if any offers only that, transient local
    if all keep their last messages for late joiners (latched maps, /tf_static).
    """
    infos = list(publishers)
    best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
    latched = bool(infos) and all(
        i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(
        depth=depth, history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def describe_qos(qos: QoSProfile) -> str:
    """Short text such as 'reliable, transient local, keep last 1' (history when known)."""
    reliability = {ReliabilityPolicy.RELIABLE: "reliable",
                   ReliabilityPolicy.BEST_EFFORT: "best effort"}.get(qos.reliability, "?")
    durability = {DurabilityPolicy.TRANSIENT_LOCAL: "transient local",
                  DurabilityPolicy.VOLATILE: "volatile"}.get(qos.durability, "?")
    if qos.history == HistoryPolicy.KEEP_LAST:
        return f"{reliability}, {durability}, keep last {qos.depth}"
    if qos.history == HistoryPolicy.KEEP_ALL:
        return f"{reliability}, {durability}, keep all"
    return f"{reliability}, {durability}"  # a remote endpoint's history is not announced


def to_data(message: Any) -> Any:
    """A message as nested dicts, lists and plain Python numbers (field order kept).

    rclpy holds fixed-size arrays (a covariance's float64[36]) as numpy arrays: their elements
    become Python floats and ints, printed as `ros2 topic echo` prints them.
    """
    if hasattr(message, "get_fields_and_field_types"):
        return {name: to_data(getattr(message, name))
                for name in message.get_fields_and_field_types()}
    if isinstance(message, np.ndarray):
        return message.tolist()
    if isinstance(message, (list, tuple, array.array)):
        return [to_data(v) for v in message]
    if isinstance(message, bytes):
        return list(message)
    if isinstance(message, np.generic):
        return message.item()
    return message


def flatten(data: Any, prefix: str = "") -> dict[str, Any]:
    """{"header.stamp.sec": 1, "ranges.0": 0.5, ...} of to_data() output (CSV columns)."""
    if isinstance(data, dict):
        out: dict[str, Any] = {}
        for key, value in data.items():
            out.update(flatten(value, f"{prefix}{key}."))
        return out
    if isinstance(data, list):
        out = {}
        for index, value in enumerate(data):
            out.update(flatten(value, f"{prefix}{index}."))
        return out
    return {prefix.rstrip("."): data}


def to_yaml(data: Any, indent: int = 0) -> str:
    """YAML text of to_data() output in the layout of `ros2 topic echo` (floats repr'd)."""
    pad = "  " * indent
    lines = []
    if isinstance(data, dict):
        for key, value in data.items():
            if isinstance(value, dict) and value:
                lines.append(f"{pad}{key}:")
                lines.append(to_yaml(value, indent + 1))
            elif isinstance(value, list) and value and isinstance(value[0], dict):
                lines.append(f"{pad}{key}:")
                for item in value:
                    body = to_yaml(item, indent + 1).lstrip()
                    lines.append(f"{pad}- {body}" if body else f"{pad}- {{}}")
            else:
                lines.append(f"{pad}{key}: {_scalar(value)}")
        return "\n".join(lines)
    return pad + _scalar(data)


def _scalar(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_scalar(v) for v in value) + "]"
    if isinstance(value, str):
        return "''" if value == "" else repr(value) if any(c in value for c in ":#'\"") \
            else value
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf") \
            if math.isinf(value) else repr(value)
    if isinstance(value, dict):
        return "{}"
    return str(value)


class GraphProbe:
    """A command-line tool's own rclpy context, hidden node and executor.

    On the environment's ROS_DOMAIN_ID; the node's name starts with '_', which the graph tools
    leave out.
    """

    def __init__(self, tool: str) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self._rclpy = rclpy
        self.context = rclpy.Context()
        # No arguments for rcl: it would read the tool's own command line (a '__ns:=/x' value
        # as a remapping of the probe node), as run_sim.py and run_robot.py avoid too.
        rclpy.init(args=[], context=self.context)
        self.node = rclpy.create_node(f"_{tool}_{os.getpid()}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def ok(self) -> bool:
        """False once the context is shut down."""
        return self._rclpy.ok(context=self.context)

    def spin(self, seconds: float) -> None:
        """Spin (and let discovery run) for `seconds`."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(end - time.monotonic(), 0.0)))

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self._rclpy.shutdown(context=self.context)


__all__ = ["GraphProbe", "UnknownTypeError", "message_class", "matched_qos", "describe_qos",
           "to_data", "flatten", "to_yaml"]
