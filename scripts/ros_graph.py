#!/usr/bin/env python3
"""Draw the live ROS graph of the current ROS_DOMAIN_ID, like rqt_graph, without rqt or Graphviz.

  .venv/bin/python scripts/ros_graph.py --out docs/graph.png          # + docs/graph.dot
  .venv/bin/python scripts/ros_graph.py --out graph.svg --qos --domain-id 30
Nodes are ellipses, topics boxes (with their message type), arrows go from publishers to topics
and from topics to subscribers; --qos labels each arrow with its QoS. Found with rclpy's graph
API after --wait seconds of discovery. Hidden: this tool's own node, /rosout, /parameter_events
and lifecycle transition_event topics (--all shows them). The DOT file is always written next
to a PNG/SVG (render it with Graphviz `dot -Tpng` where available).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from graph_drawing import RosGraph, draw, to_dot  # noqa: E402

from cli_checks import (  # noqa: E402
    add_domain_id_option,
    check_output_file,
    number_argument,
    use_domain_id,
)

DEBUG_TOPICS = ("/rosout", "/parameter_events")


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n", 1)[1])
    parser.add_argument("--out", required=True, action="append",
                        help="FILE.png, FILE.svg or FILE.dot (repeatable)")
    parser.add_argument("--qos", action="store_true", help="label arrows with their QoS")
    parser.add_argument("--all", action="store_true", help="also debug topics and hidden nodes")
    parser.add_argument("--wait", type=number_argument(float, 0.0, maximum=3600), default=3.0,
                        help="seconds of discovery (default 3)")
    parser.add_argument("--title", default=None, help="title above the picture")
    add_domain_id_option(parser)
    args = parser.parse_args(argv)
    for out in args.out:
        if Path(out).suffix.lower() not in (".png", ".svg", ".dot"):
            parser.error(f"--out {out}: the file must end in .png, .svg or .dot")
        try:  # before the discovery: the picture and the DOT file beside it
            for path in {Path(out), Path(out).with_suffix(".dot")}:
                check_output_file(path, "--out")
        except ValueError as exc:
            parser.error(str(exc))
    return args


def shown(topic: str, include_all: bool) -> bool:
    return include_all or not (topic in DEBUG_TOPICS or topic.endswith("/transition_event"))


def collect_graph(wait: float = 3.0, include_all: bool = False) -> RosGraph:
    """The graph as rclpy sees it after `wait` seconds of discovery (own context and node)."""
    from amr_tools.introspection import GraphProbe, describe_qos
    probe = GraphProbe("ros_graph")
    node = probe.node
    try:
        time.sleep(wait)  # discovery runs in the RMW's own threads
        graph = RosGraph()
        own = node.get_name()

        def hidden(name: str) -> bool:
            return name == own or (name.startswith("_") and not include_all)

        # Nodes once each (a node that just left may linger in the graph for a while), edges
        # from each topic's endpoints, which also carry the QoS.
        names = sorted({(n, ns) for n, ns in node.get_node_names_and_namespaces()
                        if not hidden(n)})
        graph.nodes = [ns.rstrip("/") + "/" + n for n, ns in names]
        for topic, types in node.get_topic_names_and_types():
            if not shown(topic, include_all):
                continue
            for kind, infos in (("pub", node.get_publishers_info_by_topic(topic)),
                                ("sub", node.get_subscriptions_info_by_topic(topic))):
                for info in infos:
                    if hidden(info.node_name):
                        continue
                    full = info.node_namespace.rstrip("/") + "/" + info.node_name
                    edge = (full, topic) if kind == "pub" else (topic, full)
                    edges = graph.publishes if kind == "pub" else graph.subscribes
                    if edge not in edges:
                        edges.append(edge)
                        graph.qos[edge] = describe_qos(info.qos_profile)
                    graph.topics.setdefault(topic, list(types))
                    if full not in graph.nodes:
                        graph.nodes.append(full)
        graph.topics = dict(sorted(graph.topics.items()))
        return graph
    finally:
        probe.close()


def write_outputs(graph: RosGraph, outputs: list[str], show_qos: bool,
                  title: str | None) -> list[Path]:
    """Write every requested file plus the DOT beside each picture; return the paths."""
    written = []
    for out in outputs:
        path = Path(out)
        path.parent.mkdir(parents=True, exist_ok=True)
        dot = path.with_suffix(".dot")
        dot.write_text(to_dot(graph, show_qos))
        if dot not in written:
            written.append(dot)
        if path.suffix.lower() != ".dot":
            draw(graph, str(path), show_qos=show_qos, title=title)
            written.append(path)
    return written


def main(argv=None) -> int:
    args = parse_args(argv)
    use_domain_id(args)
    graph = collect_graph(args.wait, args.all)
    if not graph.nodes:
        print(f"ros_graph: no node found on ROS_DOMAIN_ID="
              f"{os.environ.get('ROS_DOMAIN_ID', '0')} within {args.wait} s", file=sys.stderr)
        return 1
    try:
        written = write_outputs(graph, args.out, args.qos, args.title)
    except OSError as exc:  # e.g. the disk filled up during the discovery
        print(f"ros_graph: cannot write {exc.filename or ''}: {exc.strerror or exc}",
              file=sys.stderr)
        return 1
    for path in written:
        print(f"ros_graph: wrote {path}")
    print(f"ros_graph: {len(graph.nodes)} nodes, {len(graph.topics)} topics, "
          f"{len(graph.publishes)} publisher and {len(graph.subscribes)} subscriber edges")
    return 0


if __name__ == "__main__":
    from script_endings import run_script  # a closed output loses nothing
    sys.exit(run_script(main))
