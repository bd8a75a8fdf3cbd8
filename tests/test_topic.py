"""scripts/topic.py against known publishers: echo (YAML, CSV), hz, list, info."""
from __future__ import annotations

import csv
import io
import math
import subprocess
import sys

import pytest
from nav_msgs.msg import OccupancyGrid, Odometry
from sensor_msgs.msg import LaserScan

from amr_common.map_messages import occupancy_grid
from amr_common.qos import LATCHED, RELIABLE_10, scan_qos
from amr_common.ros_conversions import laser_scan, odometry_message, seconds_to_time
from tests.processes import REPO, run_script_while_spinning

sys.path.insert(0, str(REPO / "scripts"))
from topic import rate_statistics  # noqa: E402


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
    out = run_script_while_spinning(ros, "scripts/topic.py", "hz", "/probe_odom", "--once",
                                    "--period", "2")
    rate = float(out.split("average rate:")[1].split()[0])
    assert 15.0 < rate < 22.0  # a 20 Hz timer on a loaded 2-core machine
    # Discovery between processes can take one 3 s announcement period here.
    out = run_script_while_spinning(ros, "scripts/topic.py", "list", "-t", "--timeout", "5")
    assert "/probe_scan [sensor_msgs/msg/LaserScan]" in out.splitlines()
    out = run_script_while_spinning(ros, "scripts/topic.py", "info", "/probe_scan", "-v")
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
                             cwd=REPO, timeout=30)
    assert process.returncode == 1 and "/nobody not found" in process.stderr
