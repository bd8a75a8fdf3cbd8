"""scripts/calibrate_lidar.py: a LiDAR unit's range_correction from walls at tape distances.

The robot mode runs in-process against an in-test /scan publisher (this test's private domain,
conftest.py): a "robot" whose LiDAR reads a wall `SCALE` too far, moved to the next distance at
each prompt by a stand-in for the user (its stdin). Ctrl-C runs the script as its own process.
"""
from __future__ import annotations

import math
import os
import shlex
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from sensor_msgs.msg import LaserScan

from amr_common.ros.qos import scan_qos
from amr_common.sensors.range_calibration import RangeCorrection
from amr_mapping.mapper_params import check_parameters
from tests.processes import REPO, terminate, wait_for

sys.path.insert(0, str(REPO / "scripts"))
from calibrate_lidar import CalibrationError, main, parse_args, report  # noqa: E402
from run_robot import SLAM_SET  # noqa: E402

from launch_slam import slam_overrides  # noqa: E402

SCRIPT = REPO / "scripts" / "calibrate_lidar.py"
SCALE = 0.03  # the published unit reads 3 % long
STARTUP = 20.0  # s: interpreter + rclpy start on a loaded 2-core machine


def wall_scan(distance: float | None, rng: np.random.Generator, shape: str = "wall") -> LaserScan:
    """An LDS-01-like scan of a wall `distance` m ahead, read SCALE long with 3 mm noise.

    360 rays from straight ahead, 0 = no return; shape 'none': nothing ahead, 'zigzag': the
    returns ahead alternately 40 % short and long, not a line.
    """
    scan = LaserScan()
    scan.header.frame_id = "base_scan"
    scan.angle_min, scan.angle_increment = 0.0, 2 * math.pi / 360
    scan.angle_max = scan.angle_increment * 359
    scan.range_min, scan.range_max = 0.12, 3.5
    angles = np.arctan2(np.sin(scan.angle_increment * np.arange(360)),
                        np.cos(scan.angle_increment * np.arange(360)))
    ranges = distance / np.cos(angles) * (1.0 + SCALE) + rng.normal(0.0, 0.003, 360)
    ranges = np.where(np.abs(angles) < 0.5, ranges, 0.0)
    if shape == "none":
        ranges[:] = 0.0
    elif shape == "zigzag":
        ranges *= np.where(np.arange(360) % 2, 0.6, 1.4)
    scan.ranges = ranges.astype(np.float32).tolist()
    return scan


class Robot:
    """A /scan publisher (its own thread, 20 Hz) whose wall is where the user last put it."""

    def __init__(self, ros, topic: str, shapes: dict[float, str] | None = None) -> None:
        self.publisher = ros.node("lds01").create_publisher(LaserScan, topic, scan_qos())
        self.shapes = shapes or {}
        self.distance: float | None = None  # nothing published before the first placement
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._publish, daemon=True)
        self._thread.start()

    def _publish(self) -> None:
        rng = np.random.default_rng(5)
        while not self._done.wait(0.05):
            distance = self.distance
            if distance is not None:
                self.publisher.publish(wall_scan(distance, rng, self.shapes.get(distance, "wall")))

    def close(self) -> None:
        self._done.set()
        self._thread.join()


class User:
    """The stdin of the script: at each prompt, puts the robot at the next distance, Enter."""

    def __init__(self, robot: Robot | None, distances: list[float],
                 misplaced: dict[float, float] | None = None) -> None:
        self.robot, self.distances = robot, list(distances)
        self.misplaced = misplaced or {}  # asked for -> where the user puts it

    def readline(self) -> str:
        if not self.distances:
            return ""  # the end of the input
        distance = self.distances.pop(0)
        if self.robot is not None:
            self.robot.distance = self.misplaced.get(distance, distance)
        return "\n"

    def isatty(self) -> bool:
        return False


def run_robot_mode(ros, monkeypatch, topic: str, distances: list[float], *options: str,
                   shapes: dict[float, str] | None = None,
                   misplaced: dict[float, float] | None = None) -> int:
    robot = Robot(ros, topic, shapes)
    monkeypatch.setattr(sys, "stdin", User(robot, distances, misplaced))
    try:
        return main(["--topic", topic, "--scans", "5", *options])
    finally:
        robot.close()


def printed_values(out: str) -> list[float]:
    """range_correction as the --slam-param line gives it, checked as run_robot.py checks it."""
    line = next(line for line in out.splitlines() if "--slam-param" in line)
    item = shlex.split(line.split("--slam-param", 1)[1])[0]
    return slam_overrides([item], SLAM_SET)["range_correction"]


def test_simulated_unit_recovered_and_its_params_file_taken_by_the_slam_node(ros, tmp_path,
                                                                              capsys):
    from amr_mapping.slam_node import SlamNode
    from amr_sim.profiles import get_profile
    from amr_sim.reality import effects_of
    path = tmp_path / "calibration" / "lds01.yaml"
    profile = "turtlebot3:randomized"
    assert main(["--simulate", profile, "--seed", "3", "--out", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.count("m (tape): reads") == 3
    values = printed_values(out)
    correction = RangeCorrection.from_list(values)
    share = effects_of(get_profile(profile), 3).range_bias_share
    for distance in (1.0, 2.0):  # the unit reads share * 5 % long
        reading = distance * (1.0 + 0.05 * share)
        assert correction.apply(np.array([reading]))[0] - reading == \
            pytest.approx(-0.05 * share * distance, abs=0.002)
    node = ros.add(SlamNode(context=ros.context,
                            cli_args=["--ros-args", "--params-file", str(path)]))
    from_file = list(node.get_parameter("range_correction").value)
    assert from_file == values
    assert list(check_parameters({"range_correction": from_file})["range_correction"]) == values
    assert node.trigger_configure().name == "SUCCESS"  # the node's Mapper takes it


def test_robot_mode_measures_the_scale_error_of_the_wall_it_sees(ros, monkeypatch, tmp_path,
                                                                  capsys):
    path = tmp_path / "lds01.yaml"
    assert run_robot_mode(ros, monkeypatch, "/calib_wall", [0.3, 1.0, 2.0],
                          "--out", str(path)) == 0
    out = capsys.readouterr().out
    assert out.count("Put the Burger so its LiDAR centre is") == 3
    assert "1 m (tape): reads 1.03" in out and "error +30." in out
    expected = [v for d in (0.3, 1.0, 2.0) for v in (d * (1 + SCALE), -SCALE * d)]
    assert printed_values(out) == pytest.approx(expected, abs=0.002)
    assert f"range_correction: {printed_values(out)}".replace("'", "") in path.read_text()


@pytest.mark.parametrize("shape, why", [
    ("none", "only 0 returns there"),
    ("zigzag", "returns are not on one straight line (something in front of the wall?"),
])
def test_a_wall_not_seen_exits_1_and_writes_nothing(ros, monkeypatch, tmp_path, capsys,
                                                    shape, why):
    path = tmp_path / "lds01.yaml"
    code = run_robot_mode(ros, monkeypatch, f"/calib_{shape}", [0.3, 1.0], "--distances",
                          "0.3,1", "--out", str(path), shapes={1.0: shape})
    captured = capsys.readouterr()
    assert code == 1
    assert "0.3 m (tape): reads 0.309" in captured.out
    assert "no straight wall within +-10 deg ahead at 1 m: " in captured.err
    assert why in captured.err
    assert not path.exists()


def test_a_reading_beyond_any_lidars_error_exits_1_and_writes_nothing(ros, monkeypatch,
                                                                     tmp_path, capsys):
    path = tmp_path / "lds01.yaml"
    code = run_robot_mode(ros, monkeypatch, "/calib_misplaced", [0.3, 2.0], "--distances",
                          "0.3,2", "--out", str(path), misplaced={2.0: 1.0})
    assert code == 1
    assert "the wall 2 m away reads 1.030 m: more than any LiDAR's error" in \
        capsys.readouterr().err
    assert not path.exists()
    args = parse_args(["--out", str(path)])
    with pytest.raises(CalibrationError, match="the readings do not fit one correction"):
        report({1.0: 1.05, 1.1: 1.04}, args, "two readings the wrong way round")
    assert not path.exists()


def test_no_scan_is_a_clear_timeout_and_an_early_end_of_input_an_error(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", User(None, [0.3]))
    assert main(["--topic", "/calib_silent", "--timeout", "0.5"]) == 1
    assert "no scan on /calib_silent within 0.5 s (robot bringup running?" in \
        capsys.readouterr().err
    monkeypatch.setattr(sys, "stdin", User(None, []))
    assert main(["--topic", "/calib_silent"]) == 1
    assert "the input ended before the wall at 0.3 m was measured; nothing written" in \
        capsys.readouterr().err


def test_ctrl_c_or_a_hang_up_at_the_prompt_or_while_collecting_exits_without_a_traceback(
        tmp_path):
    """Runs side by side: one waits for Enter, two for scans that never come.

    Ctrl-C: exit code 130. A hang-up (the terminal closed, SIGHUP) killed it at once; now it
    ends as Ctrl-C does, with exit code 129.
    """
    signals = [signal.SIGINT, signal.SIGINT, signal.SIGHUP]
    runs = [subprocess.Popen([sys.executable, str(SCRIPT), "--topic", "/calib_ctrl_c", "--out",
                              str(tmp_path / f"{i}.yaml")], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
            for i in range(len(signals))]
    outputs = [bytearray() for _ in runs]  # read as it comes: the prompt ends without a newline
    readers = [threading.Thread(target=lambda r=r, o=o: [
        o.extend(chunk) for chunk in iter(lambda: os.read(r.stdout.fileno(), 4096), b"")],
        daemon=True) for r, o in zip(runs, outputs)]
    try:
        for reader in readers:
            reader.start()
        for run in runs[1:]:
            run.stdin.write(b"\n")
            run.stdin.flush()
        wait_for(lambda: b"Put the Burger" in outputs[0], STARTUP, "the prompt")
        for output in outputs[1:]:
            wait_for(lambda: b"collecting 25 scans" in output, STARTUP, "the scans wait")
        time.sleep(0.3)
        for run, signum in zip(runs, signals):
            run.send_signal(signum)
        codes = [run.wait(timeout=10) for run in runs]
    finally:
        for run in runs:
            terminate(run, 2.0)
    for run, code, signum in zip(runs, codes, signals):
        err = run.stderr.read().decode()
        assert code == (129 if signum == signal.SIGHUP else 130), err
        assert "interrupted; nothing written" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("options, message", [
    (["--distances", "1"], "give at least 2 distances (a scale needs two)"),
    (["--distances", "0.3,x"], "'x' is not a number"),
    (["--distances", "-1,2"], "--distances: must be > 0 (got '-1')"),
    (["--distances", "0,1"], "must be > 0 (got '0')"),
    (["--distances", "1,nan"], "must be > 0 (got 'nan')"),
    (["--distances", "1,2,1"], "a distance is given twice"),
    (["--distances", ",".join(str(0.2 * n) for n in range(1, 10))],
     "at most 8 distances (the slam node's range_correction takes 8 pairs)"),
    (["--scans", "0"], "--scans: must be >= 1"),
    (["--scans", "100000000"], "--scans: at most 1000 (got '100000000'): that is 200 s of scans "
                               "per wall at the LDS-01's 5 Hz"),
    (["--simulate", "turtlebot3", "--distances", "0.05,1"],
     "--distances 0.05: too close: the simulated Burger's body keeps its LiDAR's centre at "
     "least 0.138 m from the wall"),
    (["--simulate", "ideal", "--distances", "1,3.1"],
     "--distances 3.1: too far for the simulated calibration room (at most 3.094 m)"),
    (["--timeout", "0"], "--timeout: must be > 0"),
    (["--seed", "3"], "--seed needs --simulate"),
    (["--simulate", "nope"], "--simulate: unknown profile 'nope'"),
    (["--simulate", "turtlebot3", "--local"], "--local: for the robot"),
    (["--simulate", "turtlebot3", "--seed", "-1"], "--seed: must be >= 0"),
    (["--out", "calibration.txt"], "a ROS params file is YAML: name it .yaml"),
    (["--domain-id", "300"], "must be within 0-232"),
])
def test_command_line_mistakes(options, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        parse_args(options)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("profile", ["turtlebot3_clean", "ideal"])
def test_the_simulated_robot_stands_at_every_distance_the_checks_let_through(profile):
    from amr_evaluation.lidar_calibration import distance_limits, wall_reading
    closest, farthest = distance_limits(profile)
    for distance in (closest, farthest):  # the robot fits there and sees the wall
        assert wall_reading(profile, 0, distance, 2) == pytest.approx(distance, abs=0.05)
    for distance in (closest - 0.002, farthest + 0.002):  # the body would be in a wall
        with pytest.raises(ValueError, match="touches a wall"):
            wall_reading(profile, 0, distance, 2)


def test_an_out_folder_or_a_distance_outside_the_simulated_room_is_a_command_line_mistake(
        tmp_path, capsys):
    (tmp_path / "lds01.yaml").mkdir()
    with pytest.raises(SystemExit) as exit_info:
        main(["--out", str(tmp_path / "lds01.yaml")])
    assert exit_info.value.code == 2 and "is a folder: give a file name" in \
        capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main(["--simulate", "turtlebot3", "--distances", "1,3.4", "--out",
              str(tmp_path / "x.yaml")])
    captured = capsys.readouterr()
    assert exit_info.value.code == 2 and captured.out == ""
    assert "--distances 3.4: too far for the simulated calibration room" in captured.err
    assert not (tmp_path / "x.yaml").exists()


def test_a_command_line_mistake_exits_2_before_anything_runs():
    result = subprocess.run([sys.executable, str(SCRIPT), "--distances", "1"],
                            capture_output=True, text=True, cwd=REPO, timeout=30,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.splitlines() == [
        "calibrate_lidar.py: error: argument --distances: give at least 2 distances (a scale "
        "needs two), got '1' (--help lists the options)"]
