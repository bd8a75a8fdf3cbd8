"""scripts/topic.py against known publishers: echo (YAML, CSV), hz, list, info."""
from __future__ import annotations

import csv
import io
import math
import subprocess
import sys
import time

import pytest
from nav_msgs.msg import OccupancyGrid, Odometry
from sensor_msgs.msg import LaserScan

from amr_common.ros.map_messages import occupancy_grid
from amr_common.ros.qos import LATCHED, RELIABLE_10, scan_qos
from amr_common.ros.ros_conversions import laser_scan, odometry_message, seconds_to_time
from tests.processes import REPO, run_script_while_spinning, terminate

sys.path.insert(0, str(REPO / "scripts"))
from topic import parse_args, rate_statistics  # noqa: E402


@pytest.fixture
def talker(ros):
    """/probe_odom at 20 Hz (reliable), /probe_scan (best effort), /probe_map (latched)."""
    node = ros.node("probe_talker")
    odometry = node.create_publisher(Odometry, "/probe_odom", RELIABLE_10)
    scans = node.create_publisher(LaserScan, "/probe_scan", scan_qos(5))
    maps = node.create_publisher(OccupancyGrid, "/probe_map", LATCHED)
    maps.publish(occupancy_grid([[0, 100, -1]], 0.1, (1.0, 2.0), "map"))
    count = [0]
    node.tick_times = []  # wall clock of each publication: the rate actually sent

    def tick() -> None:
        count[0] += 1
        node.tick_times.append(time.monotonic())
        odometry.publish(odometry_message(seconds_to_time(count[0] * 0.05), "odom",
                                          "base_footprint", (1.5, -2.25, 0.5), (0.2, -0.1)))
        scans.publish(laser_scan([0.5, math.nan, 2.0], stamp=seconds_to_time(count[0] * 0.05),
                                 frame_id="base_scan", angle_min=0.0, angle_increment=0.1,
                                 range_min=0.1, range_max=3.5, scan_time=0.05))

    node.create_timer(0.05, tick)
    return node


@pytest.mark.slow
def test_topic_echo_hz_list_and_info_on_known_publishers(ros, talker):
    out = run_script_while_spinning(ros, "scripts/topic.py", "echo", "/probe_odom", "--once")
    assert "frame_id: odom" in out and "child_frame_id: base_footprint" in out
    assert "x: 1.5" in out and "y: -2.25" in out and out.rstrip().endswith("---")
    # Best effort publisher: the tool must subscribe best effort to hear it.
    out = run_script_while_spinning(ros, "scripts/topic.py", "echo", "/probe_scan", "--csv",
                                    "--count", "3")
    rows = list(csv.DictReader(io.StringIO(out)))
    assert len(rows) == 3
    assert rows[0]["header.frame_id"] == "base_scan" and float(rows[0]["ranges.0"]) == 0.5
    assert rows[0]["ranges.1"] == "nan" and float(rows[0]["ranges.2"]) == 2.0
    stamps = [int(r["header.stamp.nanosec"]) + 10**9 * int(r["header.stamp.sec"]) for r in rows]
    assert stamps == sorted(stamps) and len(set(stamps)) == 3
    # Latched: published once before the tool started, still received.
    out = run_script_while_spinning(ros, "scripts/topic.py", "echo", "/probe_map", "--once")
    assert "data: [0, 100, -1]" in out and "resolution: 0.1" in out
    begin = time.monotonic()
    out = run_script_while_spinning(ros, "scripts/topic.py", "hz", "/probe_odom", "--once",
                                    "--period", "2")
    rate = float(out.split("average rate:")[1].split()[0])
    # What the talker sent meanwhile (a 20 Hz timer runs slower on a loaded machine): hz reports
    # the rate received, which is the rate sent, within the jitter of a 2 s window.
    sent = [t for t in talker.tick_times if t >= begin]
    sent_rate = (len(sent) - 1) / (sent[-1] - sent[0])
    assert 0.75 * sent_rate < rate < 1.25 * sent_rate, (rate, sent_rate)
    # Discovery between processes can take one 3 s announcement period here.
    out = run_script_while_spinning(ros, "scripts/topic.py", "list", "-t", "--timeout", "5")
    assert "/probe_scan [sensor_msgs/msg/LaserScan]" in out.splitlines()
    out = run_script_while_spinning(ros, "scripts/topic.py", "info", "/probe_scan", "-v")
    assert "Publisher count: 1" in out and "PUBLISHER /probe_talker" in out
    assert "best effort, volatile" in out


@pytest.mark.slow
@pytest.mark.parametrize("command", [["echo", "/probe_odom"], ["echo", "/probe_odom", "--csv"],
                                     ["hz", "/probe_odom", "--period", "0.2"]])
def test_a_script_endings_ends_the_tool_quietly(ros, talker, command):
    """`topic.py echo /odom | head`: a traceback (BrokenPipeError) when head had its lines.

    It ends as `yes | head` does: no message, exit code 141 (128 + SIGPIPE).
    """
    import os
    process = subprocess.Popen([sys.executable, "scripts/topic.py", *command],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
    os.set_blocking(process.stdout.fileno(), False)
    heard = bytearray()

    def read() -> bytes:
        try:
            heard.extend(os.read(process.stdout.fileno(), 65536) or b"")
        except BlockingIOError:
            pass
        return bytes(heard)

    try:
        ros.spin_until(lambda: read().count(b"\n") >= 10 or process.poll() is not None, 30.0,
                       "ten lines")
        process.stdout.close()  # head has its lines
        ros.spin_until(lambda: process.poll() is not None, 10.0, "topic.py to end")
    finally:
        terminate(process, 2.0)
    err = process.stderr.read().decode()
    assert process.returncode == 141, err
    assert err == "", err


def test_rate_statistics():
    assert rate_statistics([0.0]) is None
    rate, low, high, std = rate_statistics([0.0, 0.1, 0.2, 0.4])
    assert rate == pytest.approx(3 / 0.4) and (low, high) == pytest.approx((0.1, 0.2))
    assert std == pytest.approx(math.sqrt(((0.1 - 0.4 / 3) ** 2 * 2 + (0.2 - 0.4 / 3) ** 2) / 3))


@pytest.mark.slow
def test_topic_tool_reports_a_missing_topic(ros):
    process = subprocess.run([sys.executable, "scripts/topic.py", "echo", "/nobody",
                              "--timeout", "0.5"], capture_output=True, text=True,
                             cwd=REPO, timeout=30)
    assert process.returncode == 1 and "/nobody not found" in process.stderr


@pytest.mark.parametrize("argv", [
    ["echo", "/scan", "--count", "-1"], ["echo", "/scan", "--count", "0"],
    ["echo", "/scan", "--count", "2.5"], ["echo", "/scan", "--once", "--count", "3"],
    ["echo", "/scan", "--timeout", "-1"], ["echo", "/scan", "--timeout", "nan"],
    ["info", "/scan", "--timeout", "inf"], ["list", "--timeout", "-0.5"],
    ["hz", "/scan", "--period", "0"], ["hz", "/scan", "--period", "-1"],
    ["hz", "/scan", "--window", "0"], ["echo", "/a b"], ["hz", "/scan/"],
    ["echo", "/scan", "--type", "sensor_msgs/msg/Nope"], ["echo", "/scan", "--type", "x"],
    ["info", "/scan", "--type", "sensor_msgs/msg/LaserScan"]])
def test_command_line_mistakes_are_one_line_errors(argv, capsys):
    with pytest.raises(SystemExit) as stopped:
        parse_args(argv)
    assert stopped.value.code == 2
    error = capsys.readouterr().err.splitlines()[-1]
    assert "error: " in error, error


def test_topic_names_are_made_absolute_and_types_complete():
    args = parse_args(["echo", "scan", "--type", "sensor_msgs/LaserScan", "--count", "2"])
    assert (args.topic, args.type, args.count) == ("/scan", "sensor_msgs/msg/LaserScan", 2)


@pytest.mark.slow
def test_echo_with_a_type_the_topic_does_not_carry_fails_at_once(ros, talker):
    """It waited forever (a subscription of another type never hears the publisher)."""
    process = subprocess.Popen([sys.executable, "scripts/topic.py", "echo", "/probe_scan",
                                "--type", "std_msgs/msg/String"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        ros.spin_until(lambda: process.poll() is not None, timeout=30.0,
                       message="topic.py echo to give up")
    finally:
        terminate(process, 2.0)
    _, err = process.communicate()
    assert process.returncode == 2
    assert err.strip() == ("topic.py: topic /probe_scan carries sensor_msgs/msg/LaserScan, not "
                           "--type std_msgs/msg/String")


def test_the_tools_command_line_never_reaches_rcl(monkeypatch, capfd):
    """A tool's own arguments are not rcl's (GraphProbe of topic.py, ros_graph.py, lifecycle.py).

    rclpy.init() reads sys.argv by default: a value like '__ns:=/evil' moved the probe node into
    that namespace, '__node:=evil' renamed it, 'a:=b' warned about a deprecated remap rule.
    """
    from amr_tools.introspection import GraphProbe
    monkeypatch.setattr(sys, "argv", ["topic.py", "echo", "/x", "a:=b", "__node:=evil",
                                      "__ns:=/evil"])
    probe = GraphProbe("topic")
    try:
        assert probe.node.get_namespace() == "/"
        assert probe.node.get_name().startswith("_topic_")
    finally:
        probe.close()
    assert "deprecated" not in capfd.readouterr().err


def test_echo_prints_fixed_size_arrays_as_plain_numbers():
    """A covariance (float64[36], a numpy array in rclpy) printed 'np.float64(0.0)' 36 times."""
    from geometry_msgs.msg import PoseWithCovarianceStamped

    from amr_tools.introspection import flatten, to_data, to_yaml
    message = PoseWithCovarianceStamped()
    message.pose.covariance[0] = 0.25
    message.pose.covariance[35] = -1.5
    text = to_yaml(to_data(message))
    assert "covariance: [0.25, " + "0.0, " * 34 + "-1.5]" in text
    assert "np." not in text
    row = flatten(to_data(message))
    assert row["pose.covariance.0"] == 0.25 and type(row["pose.covariance.0"]) is float
