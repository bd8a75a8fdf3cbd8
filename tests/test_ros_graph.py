"""scripts/ros_graph.py finds the nodes and edges of a simulation and draws them."""
from __future__ import annotations

import subprocess
import sys

import pytest
from rclpy.lifecycle import TransitionCallbackReturn

from tests.processes import REPO

sys.path.insert(0, str(REPO / "scripts"))
import ros_graph  # noqa: E402


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


@pytest.mark.parametrize("mistake", ["--wait -1", "--out FILE/g.png"])
def test_mistakes_that_ended_in_tracebacks_are_one_line_errors(tmp_path, mistake):
    (tmp_path / "FILE").write_text("a regular file")
    argv = ["--out", str(tmp_path / "g.png"), "--wait", "0"]
    option, value = mistake.split()
    argv += [option, str(tmp_path / value) if option == "--out" else value]
    process = subprocess.run([sys.executable, "scripts/ros_graph.py", *argv], cwd=REPO,
                             capture_output=True, text=True, timeout=60)
    assert process.returncode == 2 and "Traceback" not in process.stderr
    assert process.stderr.splitlines()[-1].startswith("ros_graph.py: error: ")
    assert not (tmp_path / "g.png").exists()  # nothing ran


@pytest.mark.parametrize("argv", [
    ["--wait", "nan"], ["--wait", "inf"], ["--wait", "1e9"], ["--out", "{d}/folder.png"],
    ["--out", "{d}/picture.png"], ["--out", "{d}/g.txt"]])
def test_wait_and_out_are_checked_before_the_discovery(tmp_path, argv, capsys):
    (tmp_path / "folder.png").mkdir()
    (tmp_path / "picture.dot").mkdir()  # where picture.png's DOT file would go
    argv = [a.format(d=tmp_path) for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "g.png")]
    with pytest.raises(SystemExit) as stopped:
        ros_graph.parse_args(argv)
    assert stopped.value.code == 2
    assert ": error: " in capsys.readouterr().err.splitlines()[-1]
