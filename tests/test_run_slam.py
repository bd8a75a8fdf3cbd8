"""SLAM runs: run_sim.py --slam (map, report, plot, Ctrl-C), run_robot.py and evaluate.py --slam.

Option mistakes of each are one-line errors with exit code 2, before anything runs.
"""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.world.map_file import read_map
from amr_common.world.map_raster import OCCUPIED
from amr_common.world.world import World
from amr_evaluation.mapping_metrics import occupied_centres
from tests.emulator_process import running_emulator
from tests.processes import terminate, wait_for
from tests.test_cli_checks import _fails_with, _robot_fails_with

REPO = Path(__file__).resolve().parent.parent
SCRIPTS = REPO / "scripts"
sys.path.insert(0, str(SCRIPTS))
import evaluate  # noqa: E402
import run_sim  # noqa: E402

pytestmark = pytest.mark.slow


def test_slam_run_writes_the_map_the_report_and_the_plot(tmp_path, capsys):
    maps, report_path = tmp_path / "maps", tmp_path / "run.json"
    code = run_sim.main(["--profile", "turtlebot3", "--slam", "--map-out", str(maps),
                         "--duration", "45", "--report", str(report_path), "--plot",
                         str(tmp_path / "slam.png")])
    out = capsys.readouterr().out
    assert code == 0, out
    report = json.loads(report_path.read_text())
    slam = report["slam"]
    assert "slam" in report["nodes"] and report["interrupted"] is False
    assert slam["map_file"] == str(maps / "map.yaml") and "map written to" in out
    assert slam["map_saved"] is True and slam["map_error"] is None
    # The simulated LDS-01 unit was calibrated against a wall (it reads 2.5 % long at 1 m).
    assert len(slam["range_correction"]) == 6
    assert slam["range_correction"][3] == pytest.approx(-0.025, abs=0.002)
    # 45 s of 5 Hz scans, each mapped once (the lockstep simulator re-sends each 3 times).
    estimate = np.array(report["estimate"])
    assert slam["scans"] == len(estimate) and 220 <= len(estimate) <= 226
    assert np.allclose(estimate[:, 0] / 0.2, np.round(estimate[:, 0] / 0.2), atol=1e-6)
    assert slam["trajectory_rmse_m"] < 0.015 and slam["trajectory_max_m"] < 0.05
    assert slam["precision"] >= 0.95 and slam["recall"] >= 0.9
    # The map lies in the world's frame and loads as a world (its start: where mapping began).
    saved = read_map(maps / "map.yaml")
    centres = occupied_centres(saved.raster)
    assert np.mean(World.load("lab02").clearances(centres) <= 0.03) >= 0.95
    world = World.load(str(maps / "map.yaml"))
    assert world.starts["slam_start"] == pytest.approx([1.0, -1.0, math.pi / 2])
    assert (tmp_path / "slam.png").read_bytes()[:4] == b"\x89PNG"


def _sigint_when(tmp_path, ready, options=(), ros=None) -> tuple[int, str]:
    """run_sim.py --slam as a user runs it; SIGINT once ready(log text); (exit code, log).

    With `ros` (the test's ROS harness), the run joins the test's domain and the harness spins
    while it waits (ready may read what the test's subscriptions heard).
    """
    if ros is not None:
        options = ["--domain-id", os.environ["ROS_DOMAIN_ID"], *options]
    log_path = tmp_path / "run.log"
    with open(log_path, "w") as log:
        process = subprocess.Popen(
            [sys.executable, str(SCRIPTS / "run_sim.py"), "--profile", "turtlebot3_clean",
             "--slam", "--map-out", str(tmp_path / "maps"), "--duration", "3000", "--report",
             str(tmp_path / "run.json"), *options],
            cwd=REPO, env=dict(os.environ), stdout=log, stderr=subprocess.STDOUT)
        try:
            moment = lambda: ready(log_path.read_text()) or process.poll() is not None  # noqa: E731
            if ros is None:
                wait_for(moment, 60.0, "the moment to interrupt")
            else:
                ros.spin_until(moment, 120.0, "the moment to interrupt")
            assert process.poll() is None, log_path.read_text()
            process.send_signal(signal.SIGINT)
            process.wait(30.0)
        finally:
            terminate(process, 5.0)
    return process.returncode, log_path.read_text()


def test_ctrl_c_mid_mapping_keeps_the_map_so_far_and_the_report(ros, tmp_path):
    from rosgraph_msgs.msg import Clock

    from amr_common.ros.qos import scan_qos
    clock = []  # the simulated time, heard on /clock: interrupted after 10 s of mapping
    ros.node("clock_listener").create_subscription(
        Clock, "/clock", lambda msg: clock.append(msg.clock.sec + 1e-9 * msg.clock.nanosec),
        scan_qos())  # best effort: matches any publisher
    code, output = _sigint_when(tmp_path, lambda text: bool(clock) and clock[-1] >= 10.0,
                                ros=ros)
    assert code == 130, output
    assert "Traceback" not in output and "Error" not in output, output
    report = json.loads((tmp_path / "run.json").read_text())
    assert report["interrupted"] is True and 0 < report["sim_time_s"] < 3000
    assert report["slam"]["map_file"] == str(tmp_path / "maps" / "map.yaml")
    assert report["slam"]["scans"] == len(report["estimate"]) > 20
    assert (read_map(tmp_path / "maps" / "map.yaml").raster.values == OCCUPIED).any()


def test_ctrl_c_while_the_slam_graph_starts_writes_the_interrupted_report(tmp_path):
    code, output = _sigint_when(tmp_path, lambda text: "[slam]: configured" in text)
    assert code == 130, output
    assert "Traceback" not in output, output
    report = json.loads((tmp_path / "run.json").read_text())
    assert report["interrupted"] is True
    assert set(report["slam"]) >= {"trajectory_rmse_m", "precision", "recall", "map_file"}
    if report["slam"]["scans"] == 0:  # stopped before the first scan: no map to write
        assert report["slam"]["map_file"] is None and report["estimate"] == []


# The terminal closed or the SSH session dropped: SIGHUP to the run, and every later write to
# its terminal fails. It died at once (exit 129): no map, no report, no zero command.
TERMINAL_OF_ITS_OWN = ("import fcntl, os, sys, termios; fcntl.ioctl(0, termios.TIOCSCTTY, 0); "
                       "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])")


def test_a_closed_terminal_ends_the_slam_run_as_ctrl_c_does_with_exit_code_129(ros, tmp_path):
    import pty

    from geometry_msgs.msg import TwistStamped
    from rosgraph_msgs.msg import Clock

    from amr_common.ros.qos import RELIABLE_10, scan_qos
    clock, commands = [], []
    listener = ros.node("listener")
    listener.create_subscription(
        Clock, "/clock", lambda msg: clock.append(msg.clock.sec + 1e-9 * msg.clock.nanosec),
        scan_qos())
    listener.create_subscription(TwistStamped, "/cmd_vel", commands.append, RELIABLE_10)
    terminal, its_side = pty.openpty()
    with open(tmp_path / "stderr.log", "w") as stderr:
        # Its own session, the terminal its controlling one: closing it hangs the run up.
        process = subprocess.Popen(
            [sys.executable, "-c", TERMINAL_OF_ITS_OWN, str(SCRIPTS / "run_sim.py"),
             "--domain-id", os.environ["ROS_DOMAIN_ID"], "--profile", "turtlebot3_clean",
             "--slam", "--map-out", str(tmp_path / "maps"), "--duration", "3000", "--report",
             str(tmp_path / "run.json"), "--plot", str(tmp_path / "slam.png")],
            cwd=REPO, stdin=its_side, stdout=its_side, stderr=stderr, start_new_session=True)
    os.close(its_side)
    try:
        ros.spin_until(lambda: (clock and clock[-1] >= 8.0) or process.poll() is not None,
                       120.0, "8 s of mapping")
        assert process.poll() is None, (tmp_path / "stderr.log").read_text()
        os.close(terminal)
        ros.spin_until(lambda: process.poll() is not None, 30.0, "run_sim to end")
        ros.spin_for(0.3)  # the last commands in flight
    finally:
        terminate(process, 5.0)
    errors = (tmp_path / "stderr.log").read_text()
    assert process.returncode == 129, errors
    assert "Traceback" not in errors, errors
    report = json.loads((tmp_path / "run.json").read_text())
    assert report["interrupted"] is True and report["slam"]["map_saved"] is True
    assert (read_map(tmp_path / "maps" / "map.yaml").raster.values == OCCUPIED).any()
    assert (tmp_path / "slam.png").read_bytes()[:4] == b"\x89PNG"
    last = commands[-1].twist
    assert (last.linear.x, last.angular.z) == (0.0, 0.0), errors


def test_a_map_that_cannot_be_written_fails_the_run_and_says_why(tmp_path, capsys,
                                                                  monkeypatch):
    """The --map-out folder became a file during the run: exit code 3, said, in the report."""
    import sim_session
    maps = tmp_path / "maps"
    report_of = sim_session.SimSession._slam_report

    def folder_replaced(session):
        maps.rmdir()
        maps.write_text("")
        return report_of(session)

    monkeypatch.setattr(sim_session.SimSession, "_slam_report", folder_replaced)
    code = run_sim.main(["--profile", "turtlebot3_clean", "--slam", "--map-out", str(maps),
                         "--duration", "4", "--report", str(tmp_path / "run.json")])
    captured = capsys.readouterr()
    assert code == 3, captured
    slam = json.loads((tmp_path / "run.json").read_text())["slam"]
    assert slam["map_saved"] is False and slam["map_file"] is None
    assert "cannot write the map" in slam["map_error"]
    summary = next(line for line in captured.out.splitlines() if "SLAM:" in line)
    assert "map NOT written" in summary and "map written" not in summary, summary
    assert "run_sim: the map was not written" in captured.err, captured.err


def test_an_empty_map_out_is_refused(capsys):
    _fails_with(capsys, ["--slam", "--map-out", ""], "--map-out '': give a folder")
    _robot_fails_with(capsys, ["--slam", "--map-out", ""], "--map-out '': give a folder")


@pytest.mark.parametrize("argv, message", [
    (["--map-out", "x"], "--map-out needs --slam"),
    (["--slam-param", "loop_closure:=false"], "--slam-param needs --slam"),
    (["--slam", "--localize"], "--slam and --localize exclude each other"),
    (["--slam", "--goal", "inner_far"],
     "--slam and --goal exclude each other: map first, then localize and navigate on the saved "
     "map (--world DIR/map.yaml)"),
    (["--slam", "--slam-param", "no_such:=1"], "--slam-param no_such: no such slam parameter"),
    (["--slam", "--slam-param", "resolution_m:=-0.02"], "resolution_m must be > 0"),
    (["--slam", "--slam-param", "map_update_interval_s:=0"],
     "map_update_interval_s must be a number > 0"),
    (["--slam", "--slam-param", "loop_closure:=maybe"], "loop_closure must be true or false"),
    (["--slam", "--slam-param", "map_start_pose:=[0.0,0.0,0.0]"],
     "--slam-param map_start_pose: the script sets it from --start"),
    (["--slam", "--slam-param", "output_prefix:=/tmp/x"], "sets it from --map-out"),
    (["--slam", "--no-controller"], "--no-controller needs --realtime"),
])
def test_slam_option_mistakes_are_one_line_errors(capsys, argv, message):
    _fails_with(capsys, argv, message)


def test_map_out_must_be_a_writable_folder(capsys, tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    _fails_with(capsys, ["--slam", "--map-out", str(a_file)], "is a file, not a folder")
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "map.yaml").mkdir()  # where the map would go
    _fails_with(capsys, ["--slam", "--map-out", str(tmp_path / "maps")], "is a folder")


@pytest.mark.parametrize("argv, message", [
    (["--slam", "--map", "lab02"], "--slam and --map exclude each other"),
    (["--slam", "--localize", "--world", "lab02"], "--slam and --localize exclude each other"),
    (["--slam", "--goal", "-1.0,0.6"], "navigate on the saved map (--map DIR/map.yaml)"),
    (["--slam", "--slam-param", "output_prefix:=x"], "sets it from --map-out"),
    (["--slam", "--slam-param", "lidar_offset_x_m:=0.1"], "lidar_offset_x_m: the script"),
    (["--teleop", "--world", "lab02", "--goal", "-1.0,0.6"], "--no-controller and --goal"),
    (["--map-out", "x"], "--map-out needs --slam"),
])
def test_run_robot_checks_its_slam_options(capsys, argv, message):
    _robot_fails_with(capsys, argv, message)


def test_run_robot_maps_the_emulated_corridor_and_writes_the_map_on_ctrl_c(ros, tmp_path):
    """The robot graph (amr_odometry + wall follower + slam) on a robot over the wire."""
    from amr_msgs.msg import PoseStamped
    poses = []
    ros.node("listener").create_subscription(PoseStamped, "/slam_pose", poses.append, 50)
    maps = tmp_path / "maps"
    with running_emulator(tmp_path, "--wall-ahead-at", "0.9", "--corridor-width", "0.8",
                          "--range-noise", "0.01", "--seed", "1"):
        with open(tmp_path / "run_robot.log", "w") as log:
            robot = subprocess.Popen(
                [sys.executable, str(SCRIPTS / "run_robot.py"), "--domain-id",
                 os.environ["ROS_DOMAIN_ID"], "--cmd-vel", "stamped", "--slam", "--map-out",
                 str(maps)], stdout=log, stderr=subprocess.STDOUT)
            try:
                ros.spin_until(lambda: len(poses) >= 25 or robot.poll() is not None, 60.0,
                               "25 SLAM poses")
                assert robot.poll() is None, (tmp_path / "run_robot.log").read_text()
                robot.send_signal(signal.SIGINT)
                robot.wait(30.0)
            finally:
                terminate(robot, 5.0)
    output = (tmp_path / "run_robot.log").read_text()
    assert "map saved to" in output and "Traceback" not in output, output
    saved = read_map(maps / "map.yaml")
    # The emulator's corridor: walls at y = +-0.4 and across it at x = 0.9 (the map frame is
    # the odometry frame at the first scan: the robot's start).
    centres = occupied_centres(saved.raster)
    distance = np.minimum(np.abs(np.abs(centres[:, 1]) - 0.4), np.abs(centres[:, 0] - 0.9))
    assert len(centres) > 50 and np.mean(distance <= 0.03) >= 0.95, output


def test_a_robot_mapping_session_without_map_out_survives_a_dropped_ssh_session(ros, tmp_path):
    """run_robot.py --slam without --map-out, hung up: the map is kept, the robot stopped.

    The map goes to maps/DATE-TIME/ of the current folder (named at start and at the end), the
    robot gets its zero, exit code 129. The map was thrown away without a word; SIGHUP killed
    the script at once, leaving the Burger on its last command.
    """
    import re

    from amr_msgs.msg import PoseStamped
    from tests.emulator_process import commands_in
    poses = []
    ros.node("listener").create_subscription(PoseStamped, "/slam_pose", poses.append, 50)
    with running_emulator(tmp_path, "--wall-ahead-at", "0.9", "--corridor-width", "0.8",
                          "--range-noise", "0.01", "--seed", "1") as (_, emulator_log):
        with open(tmp_path / "run_robot.log", "w") as log:
            robot = subprocess.Popen(
                [sys.executable, str(SCRIPTS / "run_robot.py"), "--domain-id",
                 os.environ["ROS_DOMAIN_ID"], "--cmd-vel", "stamped", "--slam"],
                cwd=tmp_path, stdout=log, stderr=subprocess.STDOUT)
            try:
                ros.spin_until(lambda: len(poses) >= 25 or robot.poll() is not None, 60.0,
                               "25 SLAM poses")
                assert robot.poll() is None, (tmp_path / "run_robot.log").read_text()
                robot.send_signal(signal.SIGHUP)
                robot.wait(30.0)
            finally:
                terminate(robot, 5.0)
        commands = commands_in(emulator_log)
    output = (tmp_path / "run_robot.log").read_text()
    assert robot.returncode == 129, output
    assert "Traceback" not in output, output
    folders = list((tmp_path / "maps").iterdir())
    assert len(folders) == 1 and re.fullmatch(r"\d{4}-\d{2}-\d{2}-\d{6}", folders[0].name)
    map_yaml = folders[0] / "map.yaml"
    assert f"the map will be written to {map_yaml}" in output, output  # at start-up
    assert f"run_robot: map written to {map_yaml}" in output, output  # at the end
    assert len(occupied_centres(read_map(map_yaml).raster)) > 50
    assert commands and commands[-1]["linear"][0] == commands[-1]["angular"][2] == 0.0


def test_run_robot_says_where_the_map_went_and_fails_when_it_was_not_written(capsys):
    """A map the slam node could not write on the way down: exit code 3 (it was 130 or 0)."""
    from types import SimpleNamespace

    import run_robot
    full = "maps/x/map.yaml: cannot write the map: [Errno 28] No space left on device"
    assert run_robot.map_ending(SimpleNamespace(map_save_error=full, saved_maps=[])) == 3
    assert f"run_robot: the map was NOT written: {full}" in capsys.readouterr().err
    saved = SimpleNamespace(map_save_error=None, saved_maps=[Path("maps/x/map.yaml")])
    assert run_robot.map_ending(saved) == 0
    assert "run_robot: map written to maps/x/map.yaml" in capsys.readouterr().out


def test_evaluate_slam_runs_mapping_episodes_with_their_figures(capsys, tmp_path):
    out = tmp_path / "out"
    code = evaluate.main(["--slam", "--worlds", "lab02,twin_maze_small", "--starts",
                          "outer,south_east", "--profiles", "turtlebot3_clean", "--seeds", "0",
                          "--duration", "20", "--jobs", "2", "--out", str(out),
                          "--slam-param", "loop_closure:=false"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    episodes = json.loads((out / "results.json").read_text())["episodes"]
    assert [(e["world"], e["start"], e["loop_closure"]) for e in episodes] == [
        ("lab02", "outer", False), ("twin_maze_small", "south_east", False)]
    for e in episodes:
        assert e["trajectory_rmse_m"] < 0.015 and e["precision"] > 0.9 and e["recall"] > 0.8
    assert "| lab02 | outer | turtlebot3_clean | 0 | False |" in printed
    assert (out / "results.csv").read_text().startswith("world,")
    # Each episode's map, as Nav2 map files in the world's frame: its walls on the true ones,
    # and it reads back as a map (its start in a free cell).
    for e in episodes:
        assert e["map_file"].startswith("maps/") and "raster" not in e
        saved = World.load(str(out / e["map_file"]))
        assert saved.raster is not None and len(saved.starts) == 1
        world = World.load(e["world"])
        near_a_wall = world.clearances(occupied_centres(saved.raster)) <= 0.03
        assert near_a_wall.mean() > 0.9, e["map_file"]
    assert (out / "sheet.png").stat().st_size > 10_000 and "maps drawn in" in printed


@pytest.mark.parametrize("argv, message", [
    (["--slam-param", "loop_closure:=false"], "--slam-param needs --slam"),
    (["--slam", "--localize"], "--slam (mapping) excludes --localize and --goals"),
    (["--slam", "--goals", "all"], "--slam (mapping) excludes --localize and --goals"),
    (["--slam", "--slam-param", "resolution_m:=0"], "--slam-param: Mapper: resolution_m"),
])
def test_evaluate_slam_option_mistakes(capsys, tmp_path, argv, message):
    code = evaluate.main([*argv, "--duration", "1", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, err


def test_the_report_leaves_out_counts_a_mapper_does_not_give():
    import sim_report

    world = World.load("lab02")
    start = world.starts["inner"]
    trajectory = [[0.0, *start], [0.2, *start]]
    from amr_common.world.map_export import world_as_map
    raster, _ = world_as_map(world, 0.02)
    report = sim_report.slam_fields(world, "turtlebot3", trajectory, [[0.2, *start]], raster,
                                    {}, 3.5, {})  # a mapper whose statistics() gives nothing
    slam = report["slam"]
    assert slam["keyframes"] is None and slam["loop_closures"] is None  # not "0": not reported
    line = sim_report.slam_line(report)
    assert "pose RMSE 0.00 cm" in line and "loop closures" not in line


def test_the_slam_node_gets_the_lidars_parameters_and_only_those_its_mapper_takes():
    from types import SimpleNamespace

    from launch_slam import lidar_parameters

    def args(mapper=None, **given):
        return SimpleNamespace(slam_overrides=given, mapper=mapper, seed=3)
    robot = lidar_parameters(args())  # the Burger: its LDS-01, calibrated by the user
    assert robot["lidar_model"] == "LDS-01" and robot["smooth_half_window"] == 7
    assert robot["lidar_offset_x_m"] == pytest.approx(-0.032) and "range_correction" not in robot
    given = lidar_parameters(args(lidar_model="LDS-02", range_correction=[1.0, -0.02]))
    assert given["lidar_model"] == "LDS-02" and given["range_correction"] == [1.0, -0.02]
    simulated = lidar_parameters(args(), "turtlebot3:randomized")  # the unit of --seed 3
    assert simulated["range_correction"][3] == pytest.approx(-0.031, abs=0.002)
    assert lidar_parameters(args(), "turtlebot3_clean")["lidar_model"] == "none"
    # The Burger's speed limits (3x its top speeds), on the robot and in simulation; the
    # Mapper's own defaults suit faster robots.
    for values in (robot, simulated):
        assert values["max_linear_speed_mps"] == pytest.approx(0.66)
        assert values["max_angular_speed_rps"] == pytest.approx(8.52)
    own = lidar_parameters(args("examples.odometry_mapper:OdometryMapper"), "turtlebot3")
    assert "smooth_half_window" not in own and "lidar_offset_x_m" in own
    assert "max_linear_speed_mps" not in own
    assert "lidar_model" not in lidar_parameters(args("examples.odometry_mapper:OdometryMapper"))
