"""run_robot.py's nodes drive a robot emulated by another DDS vendor (Eclipse Cyclone DDS).

The emulator (tests/robot_emulator.py) is a separate process that never imports rclpy: it speaks
to our Fast DDS nodes only over the wire, as the real TurtleBot3 bringup does. run_robot.py runs
as its own process too, exactly as a user starts it on the laptop.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.emulator_process import commands_in, read_log, running_emulator
from tests.processes import terminate, wait_for

RUN_ROBOT = Path(__file__).resolve().parent.parent / "scripts" / "run_robot.py"
pytestmark = pytest.mark.slow


def run_robot_process(tmp_path: Path):
    """Start scripts/run_robot.py in this test's domain (discovery as the environment says)."""
    output = open(tmp_path / "run_robot.log", "w")
    process = subprocess.Popen(
        [sys.executable, str(RUN_ROBOT), "--domain-id", os.environ["ROS_DOMAIN_ID"],
         "--cmd-vel", "stamped"], stdout=output, stderr=subprocess.STDOUT)
    return process, output


def stop(process, output, tmp_path) -> str:
    terminate(process, timeout=10)
    output.close()
    return (tmp_path / "run_robot.log").read_text()


def test_robot_graph_drives_the_emulated_robot_and_stops_when_scans_stop(ros, tmp_path):
    stop_scan_after = 9.0
    with running_emulator(tmp_path, "--wall-ahead-at", "0.9", "--corridor-width", "0.8",
                          "--range-noise", "0.01", "--seed", "1",
                          "--stop-scan-after", str(stop_scan_after), "--scan-clock", "motion"
                          ) as (emulator, log):
        robot, output = run_robot_process(tmp_path)
        try:
            # The scans stop stop_scan_after seconds after the robot first moves, however long
            # the graph took to start (numba's cache, discovery and a loaded machine vary).
            wait_for(lambda: any(e["event"] == "scan_stopped" for e in read_log(log)),
                     stop_scan_after + 40, "the emulator to stop its scans")
            time.sleep(2.0)  # commands that follow the loss of /scan
        finally:
            robot_log = stop(robot, output, tmp_path)
    events = read_log(log)
    commands = commands_in(log)
    assert "RMW=" in robot_log and "ROS_DOMAIN_ID=" in robot_log, robot_log  # says what it uses
    assert len(commands) > 20, f"commands must arrive over DDS; run_robot log:\n{robot_log}"

    # Finite and within the Burger's limits.
    for c in commands:
        v, w = c["linear"][0], c["angular"][2]
        assert math.isfinite(v) and math.isfinite(w)
        assert abs(v) <= 0.22 + 1e-9 and abs(w) <= 2.84 + 1e-9

    # It reacts to the wall ahead: no collision, it turns, and it does not drive on at full speed
    # when the wall is close ahead.
    assert not [e for e in events if e["event"] == "collision"]
    assert any(abs(c["angular"][2]) > 0.3 for c in commands), "it must turn at the wall"
    wall_x = 0.9
    far, near = [], []
    for c in commands:
        x, y, yaw = c["pose"]
        if math.cos(yaw) > 0.9:  # facing the wall
            gap = wall_x - x
            (far if gap > 0.5 else near if gap < 0.3 else []).append(c["linear"][0])
            assert gap > 0.2 or c["linear"][0] <= 0.05, \
                f"drives at {c['linear'][0]} m/s with the wall {gap:.2f} m ahead"
    assert far and near and max(near) < max(far), "it slows down as the wall gets close"

    # Scans stop: the command drops to zero within 1 s and stays there.
    t_stop = next(e["t"] for e in events if e["event"] == "scan_stopped")
    moving_before = [c for c in commands if c["t"] < t_stop and
                     (c["linear"][0] != 0.0 or c["angular"][2] != 0.0)]
    assert moving_before, "the robot must have been commanded to move before scans stopped"
    late = [c for c in commands if c["t"] > t_stop + 1.0]
    assert late, "run_robot must keep publishing (zero) commands while data is stale"
    assert all(c["linear"][0] == 0.0 and c["angular"][2] == 0.0 for c in late), late[:3]


# Ctrl-C at any moment of start-up: during the imports it used to be a KeyboardInterrupt
# traceback, and once the graph ran the exit code was 0. Each moment: exit code 130, no
# traceback; a controller that had been configured sends its zero command on the way down (the
# robot keeps its last command), and a zero is the last command the test hears; nothing at all
# if no node was built. The early moments are times (the script prints nothing while it imports
# and checks; on a fast machine the checks may be over by then: the rules above still hold);
# "running" waits until the test hears the controller (DDS discovery takes its time).
STARTUP_MOMENTS = {"importing": lambda text, elapsed, heard: elapsed > 0.3,
                   "checking the options": lambda text, elapsed, heard: elapsed > 1.5,
                   "nodes built": lambda text, elapsed, heard: "ROS_DOMAIN_ID=" in text,
                   "configuring": lambda text, elapsed, heard:
                       "'wall_follower': configure OK" in text,
                   "running": lambda text, elapsed, heard: "all nodes active" in text and heard}


@pytest.mark.parametrize("moment", list(STARTUP_MOMENTS))
def test_ctrl_c_at_any_moment_of_start_up_exits_130_with_a_final_zero(ros, tmp_path, moment):
    import signal

    from geometry_msgs.msg import TwistStamped

    from amr_common.ros.qos import RELIABLE_10
    commands = []
    ros.node("cmd_vel_listener").create_subscription(TwistStamped, "/cmd_vel", commands.append,
                                                     RELIABLE_10)
    log_path = tmp_path / "run_robot.log"
    with open(log_path, "w") as output:
        # With the particle filter: the longest start-up (its table is built when configuring).
        process = subprocess.Popen(
            [sys.executable, str(RUN_ROBOT), "--domain-id", os.environ["ROS_DOMAIN_ID"],
             "--cmd-vel", "stamped", "--localize", "--map", "lab02"],
            stdout=output, stderr=subprocess.STDOUT)
        started = time.monotonic()
        try:
            ready = STARTUP_MOMENTS[moment]
            ros.spin_until(lambda: ready(log_path.read_text(), time.monotonic() - started,
                                         bool(commands)) or process.poll() is not None,
                           60.0, moment)
            assert process.poll() is None, log_path.read_text()
            configured = "'wall_follower': configure OK" in log_path.read_text()
            process.send_signal(signal.SIGINT)
            ros.spin_until(lambda: process.poll() is not None, 30.0, "run_robot to exit")
            ros.spin_for(0.5)  # commands still in flight
        finally:
            terminate(process, 5.0)
    text = log_path.read_text()
    assert process.returncode == 130, f"{moment}: {text}"
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, f"{moment}: {text}"
    assert "run_robot: interrupted" in text, text
    if configured:
        assert "[wall_follower]: shutting down: commanding zero velocity" in text, text
    if commands:
        last = commands[-1].twist
        assert (last.linear.x, last.angular.z) == (0.0, 0.0), f"{moment}: {text}"
    if "ROS_DOMAIN_ID=" not in text:  # stopped before any node was built: none was
        assert not commands and "configure OK" not in text, f"{moment}: {text}"
