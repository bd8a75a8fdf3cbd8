#!/usr/bin/env python3
"""Topic tools without ros2cli: list, info, echo and hz on the current ROS_DOMAIN_ID.

  .venv/bin/python scripts/topic.py list -t                 # topics and their types
  .venv/bin/python scripts/topic.py info /scan -v           # publishers, subscribers, QoS, hash
  .venv/bin/python scripts/topic.py echo /odom --once       # one message as YAML
  .venv/bin/python scripts/topic.py echo /cmd_vel --csv > cmd.csv   # one CSV row per message
  .venv/bin/python scripts/topic.py hz /scan                # rate every second (Ctrl-C stops)
Types are resolved at run time from the graph; the subscription's QoS is matched to the
publishers (best effort for a LiDAR, transient local for maps). Set ROS_DOMAIN_ID (or
--domain-id) and, for a robot on the LAN, leave discovery at its default. Exit code 1 when the
topic does not appear within --timeout; 2 for a mistake in the command line, including a --type
that is not the topic's; 141 when echo or hz ends because its output closed (`| head`), quietly
as `yes | head` does.
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from script_endings import OUTPUT_CLOSED, run_script, stdout_closed  # noqa: E402

from amr_tools.introspection import (  # noqa: E402
    GraphProbe,
    UnknownTypeError,
    describe_qos,
    flatten,
    matched_qos,
    message_class,
    to_data,
    to_yaml,
)
from cli_checks import (  # noqa: E402
    add_domain_id_option,
    number_argument,
    ros_name_argument,
    use_domain_id,
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n", 1)[1])
    add_domain_id_option(parser)
    commands = parser.add_subparsers(dest="command", required=True)
    listing = commands.add_parser("list", help="topics of the graph")
    listing.add_argument("-t", "--show-types", action="store_true")
    info = commands.add_parser("info", help="type, publishers and subscribers of a topic")
    info.add_argument("-v", "--verbose", action="store_true", help="every endpoint with QoS")
    echo = commands.add_parser("echo", help="print messages as YAML (or CSV)")
    how_many = echo.add_mutually_exclusive_group()
    how_many.add_argument("--once", action="store_true", help="print one message and exit")
    how_many.add_argument("--count", type=number_argument(int, 1), default=None,
                          help="exit after N messages (default: until Ctrl-C)")
    echo.add_argument("--csv", action="store_true", help="a header row, then a row per message")
    echo.add_argument("--no-arr", action="store_true", help="print array lengths, not values")
    hz = commands.add_parser("hz", help="message rate")
    hz.add_argument("--window", type=number_argument(int, 1), default=100,
                    help="messages in the statistics")
    hz.add_argument("--period", type=number_argument(float, 0.0, above=True), default=1.0,
                    help="seconds between reports")
    hz.add_argument("--once", action="store_true", help="print one report and exit")
    for sub in (info, echo, hz):
        sub.add_argument("topic", type=ros_name_argument("topic"))
        sub.add_argument("--timeout", type=number_argument(float, 0.0), default=5.0,
                         help="seconds to wait for the topic to appear (default 5)")
    for sub in (echo, hz):
        sub.add_argument("--type", default=None, type=_message_type,
                         help="message type, if no publisher exists yet (must be the topic's)")
    listing.add_argument("--timeout", type=number_argument(float, 0.0), default=3.0,
                         help="seconds of discovery before listing (default 3)")
    return parser.parse_args(argv)


def _message_type(text: str) -> str:
    """--type as "pkg/msg/Type", if this environment has it (a one-line error if not)."""
    try:
        message_class(text)
    except UnknownTypeError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    parts = text.strip().split("/")
    return "/".join([parts[0], "msg", parts[1]]) if len(parts) == 2 else text.strip()


class ToolError(Exception):
    """A one-line message for stderr and the exit code."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


class Graph(GraphProbe):
    """The tool's probe node with the topic queries it needs."""

    def __init__(self) -> None:
        super().__init__("topic_tool")

    def topic_types(self) -> dict[str, list[str]]:
        return dict(self.node.get_topic_names_and_types())

    def wait_for(self, topic: str, timeout: float) -> list[str] | None:
        """The topic's types once it has a publisher (or, failing that, any endpoint)."""
        end = time.monotonic() + timeout
        while True:
            types = self.topic_types().get(topic)
            if types and self.node.count_publishers(topic) > 0:
                return types
            if time.monotonic() >= end:
                return types
            self.spin(0.05)


def resolve_type(graph: Graph, args) -> type:
    """The topic's message class; ToolError if it is missing or --type is not its type."""
    types = graph.wait_for(args.topic, args.timeout)
    if args.type is not None:
        if types and args.type not in types:  # a subscription of another type hears nothing
            raise ToolError(f"topic {args.topic} carries {', '.join(types)}, not --type "
                            f"{args.type}", 2)
        return message_class(args.type)
    if not types:
        raise ToolError(f"topic {args.topic} not found within {args.timeout:g} s (try --type "
                        "or a longer --timeout)")
    if len(types) > 1:
        print(f"topic {args.topic} has several types {types}: using {types[0]}",
              file=sys.stderr)
    try:
        return message_class(types[0])
    except UnknownTypeError as exc:
        raise ToolError(str(exc)) from None


def run_list(graph: Graph, args) -> int:
    graph.spin(args.timeout)
    for topic, types in sorted(graph.topic_types().items()):
        print(f"{topic} [{', '.join(types)}]" if args.show_types else topic)
    return 0


def run_info(graph: Graph, args) -> int:
    types = graph.wait_for(args.topic, args.timeout)
    if not types:
        raise ToolError(f"topic {args.topic} not found within {args.timeout:g} s")
    node = graph.node
    if args.verbose:  # node names come with a later discovery message than the endpoints
        end = time.monotonic() + args.timeout
        while time.monotonic() < end and any(
                i.node_name == "_NODE_NAME_UNKNOWN_" for i in
                node.get_publishers_info_by_topic(args.topic) +
                node.get_subscriptions_info_by_topic(args.topic)):
            graph.spin(0.05)
    publishers = node.get_publishers_info_by_topic(args.topic)
    subscribers = [i for i in node.get_subscriptions_info_by_topic(args.topic)
                   if i.node_name != node.get_name()]
    print(f"Type: {', '.join(types)}")
    print(f"Publisher count: {len(publishers)}")
    print(f"Subscription count: {len(subscribers)}")
    if args.verbose:
        for kind, infos in (("PUBLISHER", publishers), ("SUBSCRIPTION", subscribers)):
            for i in infos:
                namespace = i.node_namespace.rstrip("/")
                print(f"\n  {kind} {namespace}/{i.node_name}\n    type hash: "
                      f"{i.topic_type_hash}\n    QoS: {describe_qos(i.qos_profile)}")
    return 0


def _abbreviate_arrays(data):
    if isinstance(data, dict):
        return {k: _abbreviate_arrays(v) for k, v in data.items()}
    if isinstance(data, list) and data and not isinstance(data[0], dict):
        return f"<sequence of {len(data)}>"
    if isinstance(data, list):
        return [_abbreviate_arrays(v) for v in data]
    return data


def run_echo(graph: Graph, args) -> int:
    msg_type = resolve_type(graph, args)
    limit = 1 if args.once else args.count
    printed = 0
    writer = csv.writer(sys.stdout) if args.csv else None
    columns: list[str] | None = None

    def show(message) -> None:
        nonlocal printed, columns
        data = to_data(message)
        if args.no_arr:
            data = _abbreviate_arrays(data)
        if writer is None:
            print(to_yaml(data))
            print("---", flush=True)
        else:
            row = flatten(data)
            if columns is None:
                columns = list(row)
                writer.writerow(columns)
            writer.writerow(["" if row.get(c) is None else row[c] for c in columns])
            sys.stdout.flush()
        printed += 1

    qos = matched_qos(graph.node.get_publishers_info_by_topic(args.topic))
    graph.node.create_subscription(msg_type, args.topic, show, qos)
    while graph.ok() and not (limit is not None and printed >= limit) and not stdout_closed():
        graph.executor.spin_once(timeout_sec=0.1)
    return OUTPUT_CLOSED if stdout_closed() else 0


def rate_statistics(arrivals: list[float]) -> tuple[float, float, float, float] | None:
    """(rate Hz, min, max, std dev of the periods in s) of arrival times, or None if < 2."""
    if len(arrivals) < 2:
        return None
    periods = [b - a for a, b in zip(arrivals, arrivals[1:])]
    mean = sum(periods) / len(periods)
    std = math.sqrt(sum((p - mean) ** 2 for p in periods) / len(periods))
    return (1.0 / mean if mean > 0 else math.inf), min(periods), max(periods), std


def run_hz(graph: Graph, args) -> int:
    msg_type = resolve_type(graph, args)
    arrivals: list[float] = []

    def arrived(_data) -> None:
        arrivals.append(time.monotonic())
        del arrivals[:-args.window - 1]

    qos = matched_qos(graph.node.get_publishers_info_by_topic(args.topic))
    graph.node.create_subscription(msg_type, args.topic, arrived, qos, raw=True)
    next_report = time.monotonic() + args.period
    while graph.ok() and not stdout_closed():
        graph.executor.spin_once(timeout_sec=0.05)
        if time.monotonic() < next_report:
            continue
        next_report += args.period
        stats = rate_statistics(arrivals)
        if stats is None:
            print("no new messages", flush=True)
            continue
        rate, low, high, std = stats
        print(f"average rate: {rate:.3f}\n\tmin: {low:.3f}s max: {high:.3f}s std dev: "
              f"{std:.5f}s window: {len(arrivals)}", flush=True)
        if args.once:
            return 0
    return OUTPUT_CLOSED if stdout_closed() else 0


def main(argv=None) -> int:
    args = parse_args(argv)
    use_domain_id(args)
    graph = Graph()
    try:
        return {"list": run_list, "info": run_info, "echo": run_echo,
                "hz": run_hz}[args.command](graph, args)
    except ToolError as exc:
        print(f"topic.py: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        return 0
    finally:
        graph.close()


if __name__ == "__main__":
    sys.exit(run_script(main))
