"""The command-line tools that stand in for ros2cli and rqt_graph: topic.py (list, info, echo,
hz), lifecycle.py (get, set) and ros_graph.py, each against a graph with known contents."""
from __future__ import annotations

import csv
import io
import math
import subprocess
import sys
from pathlib import Path

import pytest
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from sensor_msgs.msg import LaserScan

from amr_common.map_messages import occupancy_grid
from amr_common.map_publisher import MapPublisherNode
from amr_common.qos import LATCHED, RELIABLE_10, scan_qos
from amr_common.ros_conversions import laser_scan, odometry_message, seconds_to_time

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import ros_graph  # noqa: E402
from topic import rate_statistics  # noqa: E402


def run_tool(ros, *args: str, timeout: float = 20.0) -> tuple[int, str]:
    """Run a script in its own process while this test's nodes keep spinning."""
    process = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, cwd=SCRIPTS.parent)
    try:
        ros.spin_until(lambda: process.poll() is not None, timeout=timeout,
                       message=f"{' '.join(args)} to finish")
    finally:
        if process.poll() is None:
            process.kill()
    out, err = process.communicate()
    assert process.returncode == 0, err
    return process.returncode, out


@pytest.fixture
def talker(ros):
    """/probe_odom at 20 Hz (reliable), /probe_scan (best effort), /probe_map (latched)."""
    node = ros.node("probe_talker")
    odometry = node.create_publisher(Odometry, "/probe_odom", RELIABLE_10)
    scans = node.create_publisher(LaserScan, "/probe_scan", scan_qos(5))
    maps = node.create_publisher(OccupancyGrid, "/probe_map", LATCHED)
    maps.publish(occupancy_grid([[0, 100, -1]], 0.1, (1.0, 2.0), "map"))
    count = [0]

    def tick() -> None:
        count[0] += 1
        odometry.publish(odometry_message(seconds_to_time(count[0] * 0.05), "odom",
                                          "base_footprint", (1.5, -2.25, 0.5), (0.2, -0.1)))
        scans.publish(laser_scan([0.5, math.nan, 2.0], stamp=seconds_to_time(count[0] * 0.05),
                                 frame_id="base_scan", angle_min=0.0, angle_increment=0.1,
                                 range_min=0.1, range_max=3.5, scan_time=0.05))

    node.create_timer(0.05, tick)
    return node


@pytest.mark.slow
def test_topic_echo_hz_list_and_info_on_known_publishers(ros, talker):
    _, out = run_tool(ros, "scripts/topic.py", "echo", "/probe_odom", "--once")
    assert "frame_id: odom" in out and "child_frame_id: base_footprint" in out
    assert "x: 1.5" in out and "y: -2.25" in out and out.rstrip().endswith("---")
    # Best effort publisher: the tool must subscribe best effort to hear it.
    _, out = run_tool(ros, "scripts/topic.py", "echo", "/probe_scan", "--csv", "--count", "3")
    rows = list(csv.DictReader(io.StringIO(out)))
    assert len(rows) == 3
    assert rows[0]["header.frame_id"] == "base_scan" and float(rows[0]["ranges.0"]) == 0.5
    assert rows[0]["ranges.1"] == "nan" and float(rows[0]["ranges.2"]) == 2.0
    stamps = [int(r["header.stamp.nanosec"]) + 10**9 * int(r["header.stamp.sec"]) for r in rows]
    assert stamps == sorted(stamps) and len(set(stamps)) == 3
    # Latched: published once before the tool started, still received.
    _, out = run_tool(ros, "scripts/topic.py", "echo", "/probe_map", "--once")
    assert "data: [0, 100, -1]" in out and "resolution: 0.1" in out
    _, out = run_tool(ros, "scripts/topic.py", "hz", "/probe_odom", "--once", "--period", "2")
    rate = float(out.split("average rate:")[1].split()[0])
    assert 15.0 < rate < 22.0  # a 20 Hz timer on a loaded 2-core machine
    _, out = run_tool(ros, "scripts/topic.py", "list", "-t")
    assert "/probe_scan [sensor_msgs/msg/LaserScan]" in out.splitlines()
    _, out = run_tool(ros, "scripts/topic.py", "info", "/probe_scan", "-v")
    assert "Publisher count: 1" in out and "PUBLISHER /probe_talker" in out
    assert "best effort, volatile" in out


def test_rate_statistics():
    assert rate_statistics([0.0]) is None
    rate, low, high, std = rate_statistics([0.0, 0.1, 0.2, 0.4])
    assert rate == pytest.approx(3 / 0.4) and (low, high) == pytest.approx((0.1, 0.2))
    assert std == pytest.approx(math.sqrt(((0.1 - 0.4 / 3) ** 2 * 2 + (0.2 - 0.4 / 3) ** 2) / 3))


@pytest.mark.slow
def test_topic_tool_reports_a_missing_topic(ros):
    process = subprocess.run([sys.executable, "scripts/topic.py", "echo", "/nobody",
                              "--timeout", "0.5"], capture_output=True, text=True,
                             cwd=SCRIPTS.parent, timeout=30)
    assert process.returncode == 1 and "/nobody not found" in process.stderr


@pytest.mark.slow
def test_lifecycle_tool_gets_and_sets_states(ros):
    node = ros.add(MapPublisherNode(context=ros.context, parameter_overrides=[
        Parameter("world", value="corridor_loop")]))
    _, out = run_tool(ros, "scripts/lifecycle.py", "get", "map_publisher")
    assert out.strip() == "unconfigured [1]"
    _, out = run_tool(ros, "scripts/lifecycle.py", "set", "map_publisher", "configure")
    assert "successful" in out
    assert node._state_machine.current_state[1] == "inactive"
    process = subprocess.run([sys.executable, "scripts/lifecycle.py", "set", "map_publisher",
                              "configure", "--timeout", "1"], capture_output=True, text=True,
                             cwd=SCRIPTS.parent, timeout=30)
    assert process.returncode == 1  # nobody spins the node now: no answer, a clear exit code


@pytest.mark.slow
def test_ros_graph_finds_the_simulation_and_draws_it(ros, tmp_path):
    from amr_control.wall_follower_node import WallFollowerNode
    from amr_sim.simulator_node import SimulatorNode
    simulator = ros.add(SimulatorNode(context=ros.context))
    follower = ros.add(WallFollowerNode(context=ros.context))
    for node in (follower, simulator):
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    graph = ros_graph.collect_graph(wait=4.0)  # in-process contexts can take 3 s to meet
    assert {"/amr_simulator", "/wall_follower"} <= set(graph.nodes)
    assert not any(n.startswith("/_ros_graph") for n in graph.nodes)
    for edge in [("/amr_simulator", "/scan"), ("/amr_simulator", "/odometry"),
                 ("/wall_follower", "/cmd_vel"), ("/amr_simulator", "/tf"),
                 ("/amr_simulator", "/tf_static"), ("/amr_simulator", "/map")]:
        assert edge in graph.publishes, edge
    for edge in [("/scan", "/wall_follower"), ("/odometry", "/wall_follower"),
                 ("/cmd_vel", "/amr_simulator"), ("/tf_static", "/wall_follower")]:
        assert edge in graph.subscribes, edge
    assert graph.topics["/scan"] == ["sensor_msgs/msg/LaserScan"]
    assert graph.qos[("/amr_simulator", "/scan")].startswith("best effort")
    assert "transient local" in graph.qos[("/amr_simulator", "/map")]
    assert "/rosout" not in graph.topics
    written = ros_graph.write_outputs(graph, [str(tmp_path / "g.png"), str(tmp_path / "g.svg")],
                                      show_qos=True, title="test")
    assert {p.name for p in written} == {"g.dot", "g.png", "g.svg"}
    assert (tmp_path / "g.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "<svg" in (tmp_path / "g.svg").read_text()[:400]
    dot = (tmp_path / "g.dot").read_text()
    assert '"n:/amr_simulator" -> "t:/scan"' in dot and '"t:/scan" -> "n:/wall_follower"' in dot
