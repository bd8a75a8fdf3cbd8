"""Draw a ROS graph like rqt_graph.

Nodes as ellipses, topics as boxes, publisher and subscriber arrows, left to right. No ROS here
(scripts/ros_graph.py collects the graph) and no Graphviz: DOT text is written for those who
have it, and PNG/SVG are drawn with matplotlib after a small layered layout (Sugiyama style:
cycles broken by reversing DFS back edges, longest-path layers, barycenter ordering within
layers).
"""
from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any


@dataclass
class RosGraph:
    """The nodes and topics of a graph and who publishes and subscribes what.

    nodes: node names; topics: topic -> type names; publishes: (node, topic) pairs;
    subscribes: (topic, node) pairs; qos: (source, target) pair -> short QoS text.
    """

    nodes: list[str] = field(default_factory=list)
    topics: dict[str, list[str]] = field(default_factory=dict)
    publishes: list[tuple[str, str]] = field(default_factory=list)
    subscribes: list[tuple[str, str]] = field(default_factory=list)
    qos: dict[tuple[str, str], str] = field(default_factory=dict)

    def vertices(self) -> list[str]:
        """Vertex ids: "n:<node>" and "t:<topic>" (a node and a topic may share a name)."""
        return [f"n:{n}" for n in self.nodes] + [f"t:{t}" for t in self.topics]

    def edges(self) -> list[tuple[str, str, tuple[str, str]]]:
        """(source id, target id, the (source, target) name pair) of every arrow."""
        return [(f"n:{n}", f"t:{t}", (n, t)) for n, t in self.publishes] + \
            [(f"t:{t}", f"n:{n}", (t, n)) for t, n in self.subscribes]


def to_dot(graph: RosGraph, show_qos: bool = False) -> str:
    """Graphviz DOT text of the graph (rankdir LR, as rqt_graph)."""
    def quote(text: str) -> str:
        return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'

    lines = ["digraph ros_graph {", "  rankdir=LR;",
             '  node [fontname="Helvetica", fontsize=11];', '  edge [fontsize=8];']
    for name in graph.nodes:
        lines.append(f"  {quote('n:' + name)} [label={quote(name)}, shape=ellipse, "
                     'style=filled, fillcolor="#dbe9f6"];')
    for topic, types in graph.topics.items():
        label = quote(topic)[:-1] + r"\n" + ", ".join(types) + '"'  # a DOT line break
        lines.append(f"  {quote('t:' + topic)} [label={label}, shape=box, style=filled, "
                     'fillcolor="#fdf1d6"];')
    for source, target, names in graph.edges():
        qos = graph.qos.get(names) if show_qos else None
        attributes = f" [label={quote(qos)}]" if qos else ""
        lines.append(f"  {quote(source)} -> {quote(target)}{attributes};")
    lines.append("}")
    return "\n".join(lines) + "\n"


def layered_layout(vertices: list[str], edges: list[tuple[str, str]],
                   sweeps: int = 8) -> tuple[dict[str, int], dict[str, int], set]:
    """Layer and order within the layer of each vertex, and the reversed edges.

    For a left-to-right drawing (Sugiyama's steps: cycles broken, longest-path layers,
    barycenter ordering). Deterministic: ties are broken by name.
    """
    reversed_edges = _back_edges(vertices, edges)
    dag = [(b, a) if (a, b) in reversed_edges else (a, b) for a, b in edges if a != b]
    layer = _longest_path_layers(vertices, dag)
    return layer, _barycenter_order(vertices, dag, layer, sweeps), reversed_edges


def _back_edges(vertices: list[str], edges: list[tuple[str, str]]) -> set[tuple[str, str]]:
    """The edges to reverse to break the cycles.

    DFS from the vertices that send most and receive least (the data's origin, e.g. a
    simulator or a driver); its back edges.
    """
    successors: dict[str, list[str]] = defaultdict(list)
    indegree = {v: 0 for v in vertices}
    for a, b in edges:
        successors[a].append(b)
        indegree[b] += 1
    state: dict[str, int] = {}
    reversed_edges: set[tuple[str, str]] = set()
    starts = sorted(vertices, key=lambda v: (indegree[v] - len(successors[v]), v))
    for start in starts:
        if start in state:
            continue
        stack = [(start, iter(sorted(successors[start])))]
        state[start] = 1
        while stack:
            vertex, children = stack[-1]
            child = next(children, None)
            if child is None:
                state[vertex] = 2
                stack.pop()
            elif state.get(child) == 1:
                reversed_edges.add((vertex, child))
            elif child not in state:
                state[child] = 1
                stack.append((child, iter(sorted(successors[child]))))
    return reversed_edges


def _longest_path_layers(vertices: list[str], dag: list[tuple[str, str]]) -> dict[str, int]:
    """Each vertex's layer: the longest path to it from a source."""
    incoming: dict[str, list[str]] = defaultdict(list)
    for a, b in dag:
        incoming[b].append(a)
    layer: dict[str, int] = {}

    def depth(vertex: str, guard: int = 0) -> int:
        if vertex not in layer:
            layer[vertex] = 0 if guard > len(vertices) else \
                max((depth(u, guard + 1) + 1 for u in incoming[vertex]), default=0)
        return layer[vertex]

    for v in vertices:
        depth(v)
    return layer


def _barycenter_order(vertices: list[str], dag: list[tuple[str, str]], layer: dict[str, int],
                      sweeps: int) -> dict[str, int]:
    """Each vertex's place in its layer, sweeping left to right and back by barycenters."""
    layers: dict[int, list[str]] = defaultdict(list)
    for v in sorted(vertices):
        layers[layer[v]].append(v)
    neighbours: dict[str, list[str]] = defaultdict(list)
    for a, b in dag:
        neighbours[a].append(b)
        neighbours[b].append(a)
    order = {v: i for members in layers.values() for i, v in enumerate(members)}
    for sweep in range(sweeps):
        keys = sorted(layers) if sweep % 2 == 0 else sorted(layers, reverse=True)
        for k in keys:
            def barycenter(v: str) -> float:
                near = [order[u] for u in neighbours[v] if layer[u] != k]
                return sum(near) / len(near) if near else order[v]
            layers[k].sort(key=lambda v: (barycenter(v), v))
            order.update({v: i for i, v in enumerate(layers[k])})
    return order


_CHAR_WIDTH_IN = 0.068   # inches per character at the label font size (Helvetica/DejaVu 9 pt)
_LAYER_GAP_IN = 0.9
_ROW_PITCH_IN = 0.95
_MARGIN_IN = 0.4
_NODE_COLOR, _TOPIC_COLOR = "#dbe9f6", "#fdf1d6"


@dataclass
class _Placement:
    """Where each vertex goes on the page (inches) and how big it is."""

    size: dict[str, tuple[float, float]]
    position: dict[str, tuple[float, float]]
    column_width: dict[int, float]
    width_in: float
    height_in: float
    bottom_of_rows: float


def _place(vertices: list[str], layer: dict[str, int], order: dict[str, int],
           labels: dict[str, str], types: dict[str, str], back_edges: int,
           title: str | None) -> _Placement:
    """Sizes from the labels, columns by layer, rows by order, lanes below for back edges."""
    size = {}
    for v in vertices:
        chars = max(len(labels[v]), len(types.get(v, "")) * 0.85)
        width = chars * _CHAR_WIDTH_IN + (0.45 if v.startswith("n:") else 0.25)
        size[v] = (width, 0.62 if v in types else 0.5)
    columns = sorted(set(layer.values()))
    column_width = {k: max(size[v][0] for v in vertices if layer[v] == k) for k in columns}
    x_of, x = {}, _MARGIN_IN
    for k in columns:
        x_of[k] = x + column_width[k] / 2
        x += column_width[k] + _LAYER_GAP_IN
    rows = max((sum(1 for v in vertices if layer[v] == k) for k in columns), default=1)
    lanes_in = 0.18 * back_edges  # arrows going back run in lanes below the drawing
    width_in, height_in = x - _LAYER_GAP_IN + _MARGIN_IN, rows * _ROW_PITCH_IN + 2 * _MARGIN_IN
    height_in += lanes_in + (0.4 if title else 0.0)
    centre_y = _MARGIN_IN + lanes_in + rows * _ROW_PITCH_IN / 2
    position = {}
    for v in vertices:
        count = sum(1 for u in vertices if layer[u] == layer[v])
        position[v] = (x_of[layer[v]], centre_y + ((count - 1) / 2 - order[v]) * _ROW_PITCH_IN)
    return _Placement(size, position, column_width, width_in, height_in,
                      centre_y - rows * _ROW_PITCH_IN / 2)


def draw(graph: RosGraph, path: str, show_qos: bool = False, title: str | None = None) -> None:
    """Write a PNG or SVG picture (by the file's suffix) of the graph with matplotlib."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    vertices = graph.vertices()
    edges = [(a, b) for a, b, _ in graph.edges()]
    layer, order, _ = layered_layout(vertices, edges)
    labels = {v: v[2:] for v in vertices}
    types = {f"t:{t}": ", ".join(ts) for t, ts in graph.topics.items()}
    back_edges = [e for e in graph.edges() if layer[e[1]] <= layer[e[0]]]
    placed = _place(vertices, layer, order, labels, types, len(back_edges), title)
    fig = plt.figure(figsize=(max(placed.width_in, 3.0), placed.height_in))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, max(placed.width_in, 3.0))
    ax.set_ylim(0, placed.height_in)
    ax.axis("off")
    if title:
        ax.text(_MARGIN_IN, placed.height_in - 0.3, title, fontsize=11, weight="bold",
                va="center")
    patches = _draw_vertices(ax, vertices, placed, labels, types)
    _draw_edges(ax, graph, layer, placed, patches, back_edges, show_qos)
    fig.savefig(path, dpi=150)
    plt.close(fig)


def _draw_vertices(ax: Any, vertices: list[str], placed: _Placement, labels: dict[str, str],
                   types: dict[str, str]) -> dict[str, Any]:
    """Nodes as ellipses, topics as boxes with their types; the patch of each vertex."""
    from matplotlib.patches import Ellipse, FancyBboxPatch
    patches = {}
    for v in vertices:
        (cx, cy), (w, h) = placed.position[v], placed.size[v]
        if v.startswith("n:"):
            patch = Ellipse((cx, cy), w, h, facecolor=_NODE_COLOR, edgecolor="#2f5d8a", lw=1.2)
            ax.text(cx, cy, labels[v], ha="center", va="center", fontsize=9)
        else:
            patch = FancyBboxPatch((cx - w / 2, cy - h / 2), w, h, facecolor=_TOPIC_COLOR,
                                   edgecolor="#9a6b00", lw=1.0,
                                   boxstyle="round,pad=0.0,rounding_size=0.06")
            ax.text(cx, cy + 0.1, labels[v], ha="center", va="center", fontsize=9)
            ax.text(cx, cy - 0.13, types[v], ha="center", va="center", fontsize=7,
                    color="#555555")
        ax.add_patch(patch)
        patches[v] = patch
    return patches


def _draw_edges(ax: Any, graph: RosGraph, layer: dict[str, int], placed: _Placement,
                patches: dict[str, Any], back_edges: list, show_qos: bool) -> None:
    """Arrows left to right; back edges routed through lanes below; QoS labels if asked."""
    from matplotlib.patches import FancyArrowPatch
    from matplotlib.path import Path
    size, position = placed.size, placed.position
    for source, target, names in graph.edges():
        (x1, y1), (x2, y2) = position[source], position[target]
        if layer[target] > layer[source]:
            rad = 0.0 if layer[target] - layer[source] == 1 else 0.15
            arrow = FancyArrowPatch((x1, y1), (x2, y2), patchA=patches[source],
                                    patchB=patches[target], arrowstyle="-|>",
                                    mutation_scale=11, connectionstyle=f"arc3,rad={rad}",
                                    lw=1.0, color="#333333")
            gap_x = ((x1 + size[source][0] / 2) + (x2 - size[target][0] / 2)) / 2
            label_at = (gap_x, y1 + (y2 - y1) * (gap_x - x1) / (x2 - x1) + 0.08)
        else:  # out right, down a gap to a lane below everything, back, up a gap, in left
            lane_y = placed.bottom_of_rows - 0.1 - 0.18 * back_edges.index(
                (source, target, names))
            out_x = x1 + placed.column_width[layer[source]] / 2 + _LAYER_GAP_IN * 0.35
            in_x = x2 - placed.column_width[layer[target]] / 2 - _LAYER_GAP_IN * 0.35
            route = Path([(x1 + size[source][0] / 2, y1), (out_x, y1), (out_x, lane_y),
                          (in_x, lane_y), (in_x, y2), (x2 - size[target][0] / 2, y2)])
            arrow = FancyArrowPatch(path=route, arrowstyle="-|>", mutation_scale=11, lw=1.0,
                                    color="#7a3e9d")
            label_at = ((x1 + x2) / 2, lane_y + 0.04)
        ax.add_patch(arrow)
        qos = graph.qos.get(names) if show_qos else None
        if qos:
            ax.text(*label_at, qos, fontsize=6, color="#666666", ha="center")
