"""Ctrl-C on run_sim.py, as a user does it: a real process, SIGINT at different moments.

The whole run ends (not only the current start of `--start all`), without a traceback, with a
zero command as the robot's last command and the partial report marked interrupted.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from geometry_msgs.msg import TwistStamped

from amr_common.qos import RELIABLE_10

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow

# Spec: within a second. The bound leaves room for a loaded 2-core machine (several test
# processes at once); the measured times are printed (pytest -s).
END_WITHIN_S = 3.0


def _start(tmp_path, *args):
    log = open(tmp_path / "run_sim.log", "w+")
    # The test's own domain (conftest): the test hears the run's /cmd_vel.
    process = subprocess.Popen(
        [sys.executable, str(REPO / "scripts" / "run_sim.py"), "--world", "corridor_loop",
         "--start", "all", "--duration", "3000", "--report", str(tmp_path / "run.json"), *args],
        cwd=REPO, env=dict(os.environ), stdout=log, stderr=subprocess.STDOUT)
    return process, log


def _interrupt(process, log, ros, ready=lambda: True, delay=0.0):
    deadline = time.monotonic() + 60.0
    while not ready():
        assert process.poll() is None, _read(log)
        assert time.monotonic() < deadline, _read(log)
        ros.spin_for(0.05)
    ros.spin_for(delay)
    sent = time.monotonic()
    process.send_signal(signal.SIGINT)
    while process.poll() is None and time.monotonic() - sent < 30.0:
        ros.spin_for(0.02)
    ended = time.monotonic() - sent
    ros.spin_for(0.3)  # the last commands still in flight
    if process.poll() is None:
        process.kill()
    output = _read(log)
    print(f"run_sim ended {ended:.2f} s after SIGINT")
    assert process.returncode == 130, output
    assert "Traceback" not in output and "Exception" not in output, output
    assert ended < END_WITHIN_S, output
    return output


def _read(log) -> str:
    log.flush()
    log.seek(0)
    return log.read()


def _listen(ros):
    commands = []
    ros.node("cmd_vel_listener").create_subscription(TwistStamped, "/cmd_vel", commands.append,
                                                     RELIABLE_10)
    return commands


@pytest.mark.parametrize("delay", [0.0, 0.5, 1.5])
def test_ctrl_c_mid_run_ends_everything_with_a_zero_command_and_a_report(ros, tmp_path, delay):
    commands = _listen(ros)
    process, log = _start(tmp_path)
    # Mid-run: the robot is driving (the test hears its commands).
    output = _interrupt(process, log, ros, lambda: len(commands) > 0, delay)
    reports = json.loads((tmp_path / "run.json").read_text())
    # --start all on corridor_loop has three starts: only the first one ran, partly.
    assert [r["start"] for r in reports] == ["south"], output
    assert reports[0]["interrupted"] is True and reports[0]["sim_time_s"] < 3000
    assert len(reports[0]["trajectory"]) == reports[0]["steps"] + 1
    last = commands[-1].twist
    assert (last.linear.x, last.angular.z) == (0.0, 0.0), output


@pytest.mark.parametrize("moment", ["importing", "building the graph"])
def test_ctrl_c_during_startup_ends_at_once_and_cleanly(ros, tmp_path, moment):
    process, log = _start(tmp_path)
    if moment == "importing":
        output = _interrupt(process, log, ros, delay=0.3)
    else:  # the options are checked; the nodes are being created and configured
        output = _interrupt(process, log, ros, lambda: "ROS_DOMAIN_ID=" in _read(log))
    report_path = tmp_path / "run.json"
    if report_path.exists():  # whatever started is reported, marked interrupted
        reports = json.loads(report_path.read_text())
        reports = reports if isinstance(reports, list) else [reports]
        assert len(reports) == 1 and reports[0]["interrupted"] is True, output
    else:
        assert "interrupted before the simulation started (no report)" in output
