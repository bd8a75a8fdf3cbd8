"""run_sim.py end to end: simulator + wall follower + lifecycle manager in one process.

Its option checks (nothing simulated) are in test_cli_checks.py.
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

from amr_common.ros.qos import RELIABLE_10
from tests.processes import terminate, wait_for

REPO = Path(__file__).resolve().parent.parent
SCRIPTS = REPO / "scripts"
sys.path.insert(0, str(SCRIPTS))
import run_sim  # noqa: E402

pytestmark = pytest.mark.slow


def test_wall_follower_laps_the_lab02_outer_corridor_without_touching(tmp_path):
    report_path = tmp_path / "lab02.json"
    exit_code = run_sim.main(["--world", "lab02", "--start", "outer", "--duration", "75",
                              "--report", str(report_path)])
    report = json.loads(report_path.read_text())
    assert exit_code == 0
    assert report["collisions"] == 0
    assert report["min_clearance_m"] > 0.03
    assert report["laps"] >= 1, f"distance {report['distance_m']:.1f} m, no full lap"
    assert report["steps"] == 1500 and report["sim_time_s"] == pytest.approx(75.0)
    trajectory = report["trajectory"]
    assert len(trajectory) == report["steps"] + 1
    assert [round(row[0], 6) for row in trajectory[:3]] == [0.0, 0.05, 0.1]


@pytest.mark.parametrize("world", ["lab02", "corridor_loop", "maze_deadends", "room_obstacles",
                                   "wide_maze"])
def test_report_and_plot_for_every_bundled_world(tmp_path, world):
    report_path, plot_path = tmp_path / "run.json", tmp_path / "run.png"
    run_sim.main(["--world", world, "--duration", "5", "--report", str(report_path),
                  "--plot", str(plot_path)])
    report = json.loads(report_path.read_text())
    for key in ("world", "start", "profile", "steps", "sim_time_s", "wall_time_s", "collisions",
                "min_clearance_m", "distance_m", "trajectory"):
        assert key in report, key
    assert report["world"] == world and report["steps"] == 100
    assert plot_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert plot_path.stat().st_size > 20_000  # a real picture, not an empty canvas


def test_bad_world_is_a_clear_error(tmp_path, capsys):
    broken = tmp_path / "broken.json"
    broken.write_text('{"metric": {"boundary": [[0, 0], [1, 0]]')
    assert run_sim.main(["--world", str(broken)]) == 2
    assert "broken.json" in capsys.readouterr().err


def test_realtime_turtlebot3_rehearsal_runs_the_robot_graph(tmp_path):
    report_path = tmp_path / "rehearsal.json"
    exit_code = run_sim.main(["--profile", "turtlebot3", "--realtime", "--duration", "12",
                              "--report", str(report_path)])
    report = json.loads(report_path.read_text())
    assert exit_code == 0 and report["collisions"] == 0
    assert report["nodes"] == ["amr_odometry", "wall_follower", "amr_simulator"]
    assert report["controller_mode"] == "robot (timer)"
    assert 0.6 < report["real_time_factor"] < 1.2
    assert report["distance_m"] > 1.0, "the robot graph must drive the simulated Burger"


def test_record_writes_an_mcap_that_an_independent_reader_opens(tmp_path, capsys):
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability, QosReliability
    from rosbags.typesys import Stores, get_typestore

    record = tmp_path / "run.mcap"
    run_sim.main(["--duration", "5", "--record", str(record)])
    with AnyReader([record], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        # The QoS each publisher offered, as rosbag2 stores it: `ros2 bag play` offers it again
        # (a latched /map and /tf_static stay latched, /scan stays best effort).
        offered = {c.topic: [(q.reliability, q.durability) for q in c.ext.offered_qos_profiles]
                   for c in reader.connections}
        stamps, log_times, frames = {}, {}, set()
        for connection, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            log_times.setdefault(connection.topic, []).append(timestamp)
            header = msg.transforms[0].header if connection.topic == "/tf" else \
                getattr(msg, "header", None)
            if header is not None:
                stamps.setdefault(connection.topic, []).append(
                    header.stamp.sec * 10**9 + header.stamp.nanosec)
            for transform in getattr(msg, "transforms", []):
                frames.add((transform.header.frame_id, transform.child_frame_id))
    for topic in ("/scan", "/odometry", "/cmd_vel", "/ground_truth", "/tf"):
        # One per step (+ the first measurement, + the final zero command on /cmd_vel).
        assert 99 <= counts[topic] <= 102, (topic, counts)
        steps = sorted(set(stamps[topic]))
        assert all(b - a == 50_000_000 for a, b in zip(steps, steps[1:])), topic
        # One time base, simulated time, from t = 0 (not the wall clock for the first ones).
        assert log_times[topic] == stamps[topic], topic
        assert min(log_times[topic]) == 0, topic
    assert max(stamps["/scan"]) == 5 * 10**9
    # The recording opens placed in Foxglove: map, the whole TF tree, all on simulated time.
    assert counts["/tf_static"] == counts["/map"] == counts["/map_markers"] == 1
    assert frames == {("base_footprint", "base_scan"), ("odom", "base_footprint"),
                      ("map", "base_footprint_truth"), ("map", "odom")}
    assert max(max(times) for times in log_times.values()) <= 5 * 10**9
    best_effort = (QosReliability.BEST_EFFORT, QosDurability.VOLATILE)
    latched = (QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)
    assert offered["/scan"] == [best_effort]
    assert offered["/tf_static"] == offered["/map"] == offered["/map_markers"] == [latched]
    assert offered["/cmd_vel"] == [(QosReliability.RELIABLE, QosDurability.VOLATILE)]
    # Every topic of the graph, as `ros2 bag record -a`: the clock and the nodes' logs too.
    assert {"/clock", "/rosout", "/parameter_events"} <= set(counts)
    total = sum(counts.values())
    assert f"run_sim: recording written: {record} ({total} messages, 5.0 s)" in \
        capsys.readouterr().out.splitlines()


def _commands_per_stamp(path) -> dict[int, int]:
    """How many /cmd_vel messages of a recording carry each stamp (ns)."""
    from collections import Counter

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    counts: Counter = Counter()
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, _, raw in reader.messages([c for c in reader.connections
                                                    if c.topic == "/cmd_vel"]):
            stamp = reader.deserialize(raw, connection.msgtype).header.stamp
            counts[stamp.sec * 10**9 + stamp.nanosec] += 1
    return dict(counts)


def _log_times(path):
    from rosbags.highlevel import AnyReader
    with AnyReader([path]) as reader:
        return {c.topic: [t for conn, t, _ in reader.messages([c])] for c in reader.connections}


def test_the_realtime_rehearsal_records_on_simulated_time_only(tmp_path):
    record = tmp_path / "rehearsal.mcap"
    run_sim.main(["--profile", "turtlebot3", "--realtime", "--duration", "3",
                  "--record", str(record)])
    times = _log_times(record)
    assert {"/scan", "/odom", "/odometry", "/cmd_vel"} <= set(times)
    every = sorted(t for topic_times in times.values() for t in topic_times)
    # The controller stamps its commands with the wall clock: logged at arrival, on the
    # simulated clock like the rest (a wall-clock log time would be ~1.8e18 ns).
    assert 0 <= every[0] and every[-1] <= 3.5e9, (every[0], every[-1])


def test_record_with_every_start_writes_one_file_per_start(tmp_path, capsys):
    from mcap.reader import make_reader
    record = tmp_path / "run.mcap"
    assert run_sim.main(["--world", "corridor_loop", "--start", "all", "--duration", "1",
                         "--record", str(record)]) == 0
    assert not record.exists()
    said = [line for line in capsys.readouterr().out.splitlines() if "recording written" in line]
    assert [line.split(": ")[2].split(" (")[0] for line in said] == [
        str(tmp_path / f"run-{start}.mcap") for start in ("south", "north", "corner")]
    assert all(line.endswith(" messages, 1.0 s)") for line in said), said
    for start in ("south", "north", "corner"):
        path = tmp_path / f"run-{start}.mcap"
        with open(path, "rb") as stream:
            metadata = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
        assert metadata["amr_sim"]["start"] == start
        assert 20 <= len(_log_times(path)["/scan"]) <= 21


def test_a_run_without_controller_says_the_teleop_command_that_drives_it(capsys):
    import shlex
    assert run_sim.main(["--profile", "turtlebot3", "--realtime", "--teleop",
                         "--duration", "1"]) == 0
    said = [line for line in capsys.readouterr().out.splitlines()
            if line.startswith("run_sim: no controller runs: drive from another terminal with ")]
    assert len(said) == 1, said
    argv = shlex.split(said[0].split(" with ", 1)[1])
    assert Path(argv[0]).resolve() == Path(sys.executable).resolve()
    assert Path(argv[1]).resolve() == SCRIPTS / "teleop.py"
    assert argv[2:] == ["--local", "--domain-id", os.environ["ROS_DOMAIN_ID"]]


def test_gui_runs_headless(tmp_path, monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    report = tmp_path / "gui.json"
    assert run_sim.main(["--duration", "3", "--gui", "--report", str(report)]) == 0
    assert json.loads(report.read_text())["steps"] == 60


def test_report_gives_the_time_of_the_first_collision(tmp_path):
    report_path = tmp_path / "crash.json"
    # lab02 outer: (1.0, -1.0) heading north, the outer wall at y = 1.2: the robot's edge
    # (radius 0.105 m) reaches it after 2.095 m, 10.5 s at 0.2 m/s.
    exit_code = run_sim.main(["--duration", "15", "--controller",
                              "tests.controllers:StraightController",
                              "--report", str(report_path)])
    report = json.loads(report_path.read_text())
    assert exit_code == 1 and report["collisions"] >= 1
    assert report["first_collision_time_s"] == pytest.approx(10.5, abs=0.2)


def test_a_course_map_runs_from_a_pose_with_negative_numbers(tmp_path, course_map):
    report_path = tmp_path / "run.json"
    code = run_sim.main(["--world", str(course_map), "--start", "-1.0,-1.0,1.57",
                         "--duration", "2", "--report", str(report_path)])
    report = json.loads(report_path.read_text())
    assert code == 0
    assert report["start"] == "-1,-1,1.57" and report["steps"] == 40
    assert report["trajectory"][0][1:] == pytest.approx([-1.0, -1.0, 1.57])


def test_an_integer_for_a_float_parameter_runs(tmp_path):
    report_path = tmp_path / "run.json"
    assert run_sim.main(["-p", "kp:=5", "-p", "wall_distance_m:=0.2", "--duration", "1",
                         "--report", str(report_path)]) == 0
    assert json.loads(report_path.read_text())["steps"] == 20


def test_the_printed_plot_path_is_the_file_written(capsys, tmp_path):
    assert run_sim.main(["--duration", "1", "--plot", str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    written = tmp_path / "run.png"
    assert f"plot written to {written}\n" in out
    assert written.read_bytes()[:4] == b"\x89PNG"


# --- Ctrl-C, as a user does it: a real process, SIGINT at different moments -------------------
# The whole run ends (not only the current start of --start all), without a traceback, with a
# zero command as the robot's last command and the partial report marked interrupted. Spec:
# within a second; the bound leaves room for a loaded 2-core machine (measured times: -s).
END_WITHIN_S = 3.0


def _start_run(tmp_path):
    log = open(tmp_path / "run_sim.log", "w+")
    # The test's own domain (conftest): the test hears the run's /cmd_vel.
    process = subprocess.Popen(
        [sys.executable, str(SCRIPTS / "run_sim.py"), "--world", "corridor_loop", "--start",
         "all", "--duration", "3000", "--report", str(tmp_path / "run.json")],
        cwd=REPO, env=dict(os.environ), stdout=log, stderr=subprocess.STDOUT)
    return process, log


def _read(log) -> str:
    log.flush()
    log.seek(0)
    return log.read()


def _interrupt(process, log, ros, ready, what: str, delay: float = 0.0) -> str:
    """SIGINT once ready() (then `delay` s); checks the clean, prompt exit; the run's output."""
    try:
        ros.spin_until(lambda: ready() or process.poll() is not None, 60.0, what)
        assert process.poll() is None, _read(log)
        ros.spin_for(delay)
        sent = time.monotonic()
        process.send_signal(signal.SIGINT)
        checked = _options_checked_at(process, Path(log.name).read_text, sent, ros.spin_for)
        ended = time.monotonic() - checked
        ros.spin_for(0.3)  # the last commands still in flight
    finally:
        terminate(process, 5.0)
    output = _read(log)
    print(f"run_sim ended {ended:.2f} s after SIGINT (or its option checks)")
    assert process.returncode == 130, output
    assert "Traceback" not in output and "Exception" not in output, output
    assert ended < END_WITHIN_S, output
    return output


def _options_checked_at(process, read, sent: float, wait) -> float:
    """Wait for the exit; when its options were checked (the graph settings line), or `sent`.

    A run interrupted before its options were checked finishes checking them (about 1 s on a
    quiet machine, several on a loaded one): the report needs them. The prompt end is measured
    from there.
    """
    checked = sent if "ROS_DOMAIN_ID=" in read() else None
    deadline = sent + 30.0
    while process.poll() is None and time.monotonic() < deadline:
        wait(0.02)
        if checked is None and "ROS_DOMAIN_ID=" in read():
            checked = time.monotonic()
    assert process.poll() is not None, "run_sim did not exit within 30 s of SIGINT"
    return checked if checked is not None else sent


@pytest.mark.parametrize("delay", [0.0, 0.5, 1.5])
def test_ctrl_c_mid_run_ends_everything_with_a_zero_command_and_a_report(ros, tmp_path, delay):
    commands = []
    ros.node("cmd_vel_listener").create_subscription(TwistStamped, "/cmd_vel", commands.append,
                                                     RELIABLE_10)
    process, log = _start_run(tmp_path)
    # Mid-run: the robot is driving (the test hears its commands).
    output = _interrupt(process, log, ros, lambda: len(commands) > 0, "commands", delay)
    reports = json.loads((tmp_path / "run.json").read_text())
    # --start all on corridor_loop has three starts: only the first one ran, partly.
    assert [r["start"] for r in reports] == ["south"], output
    assert reports[0]["interrupted"] is True and reports[0]["sim_time_s"] < 3000
    assert len(reports[0]["trajectory"]) == reports[0]["steps"] + 1
    last = commands[-1].twist
    assert (last.linear.x, last.angular.z) == (0.0, 0.0), output


@pytest.mark.parametrize("moment", ["importing", "building the graph"])
def test_ctrl_c_during_startup_ends_at_once_and_cleanly(ros, tmp_path, moment):
    process, log = _start_run(tmp_path)
    started = time.monotonic()
    if moment == "importing":
        output = _interrupt(process, log, ros, lambda: time.monotonic() - started > 0.3,
                            "0.3 s")
    else:  # the options are checked; the nodes are being created and configured
        output = _interrupt(process, log, ros, lambda: "ROS_DOMAIN_ID=" in _read(log),
                            "the graph settings line")
    # Whatever the moment, the first start is reported, marked interrupted.
    reports = json.loads((tmp_path / "run.json").read_text())
    assert len(reports) == 1 and reports[0]["interrupted"] is True, output


@pytest.mark.parametrize("buffering", ["unbuffered", "buffered"])
def test_a_script_endings_loses_neither_the_report_nor_the_plot(ros, tmp_path, buffering):
    """`run_sim.py ... | tee log`, then Ctrl-C: tee is gone when the run says it was stopped.

    Unbuffered (python -u) it died there on a BrokenPipeError: no report, no plot, a traceback;
    buffered, the flush at exit failed: "Exception ignored ... BrokenPipeError", exit code 120.
    """
    commands = []
    ros.node("cmd_vel_listener").create_subscription(TwistStamped, "/cmd_vel", commands.append,
                                                     RELIABLE_10)
    with open(tmp_path / "stderr.log", "w") as stderr:
        process = subprocess.Popen(
            [sys.executable, str(SCRIPTS / "run_sim.py"), "--duration", "3000", "--report",
             str(tmp_path / "run.json"), "--plot", str(tmp_path / "run.png")],
            cwd=REPO, env=dict(os.environ, PYTHONUNBUFFERED="1" if buffering == "unbuffered"
                               else ""),
            stdout=subprocess.PIPE, stderr=stderr)
    try:
        ros.spin_until(lambda: commands or process.poll() is not None, 60.0, "commands")
        assert process.poll() is None, (tmp_path / "stderr.log").read_text()
        process.stdout.close()  # tee ended with the Ctrl-C
        process.send_signal(signal.SIGINT)
        ros.spin_until(lambda: process.poll() is not None, 30.0, "run_sim to end")
        ros.spin_for(0.3)  # the last commands in flight
    finally:
        terminate(process, 5.0)
    errors = (tmp_path / "stderr.log").read_text()
    assert process.returncode == 130, errors
    assert "Traceback" not in errors and "Exception" not in errors, errors
    assert json.loads((tmp_path / "run.json").read_text())["interrupted"] is True
    assert (tmp_path / "run.png").read_bytes()[:4] == b"\x89PNG"
    last = commands[-1].twist
    assert (last.linear.x, last.angular.z) == (0.0, 0.0), errors


# Ctrl-C at any moment of start-up, in each graph: exit code 130 and the report, marked
# interrupted (during the node start-up of a --goal run it once ended in a KeyError, exit 1 and
# no report). The moments: fixed delays (imports, option checks), the graph settings line (the
# nodes are being built), the last control node configured (the graph starts).
STARTUP_GRAPHS = {"wall following": ([], "[wall_follower]: configured"),
                  "localize": (["--localize"], "[particle_filter]: configured"),
                  "goal": (["--goal", "inner_far"], "[planner]: configured")}


@pytest.mark.parametrize("graph", list(STARTUP_GRAPHS))
def test_ctrl_c_at_every_moment_of_start_up_writes_the_interrupted_report(tmp_path, graph):
    options, configured = STARTUP_GRAPHS[graph]
    moments = {"0.5 s": lambda text, elapsed: elapsed > 0.5,
               "1.5 s": lambda text, elapsed: elapsed > 1.5,
               "graph settings": lambda text, elapsed: "ROS_DOMAIN_ID=" in text,
               "configured": lambda text, elapsed: configured in text}
    for moment, ready in moments.items():
        report_path, log_path = tmp_path / f"{moment}.json", tmp_path / f"{moment}.log"
        with open(log_path, "w") as log:
            process = subprocess.Popen(
                [sys.executable, str(SCRIPTS / "run_sim.py"), "--world", "lab02", *options,
                 "--duration", "3000", "--report", str(report_path)],
                cwd=REPO, env=dict(os.environ), stdout=log, stderr=subprocess.STDOUT)
            started = time.monotonic()
            try:
                wait_for(lambda: ready(log_path.read_text(), time.monotonic() - started)
                         or process.poll() is not None, 60.0, moment)
                assert process.poll() is None, log_path.read_text()
                sent = time.monotonic()
                process.send_signal(signal.SIGINT)
                checked = _options_checked_at(process, log_path.read_text, sent, time.sleep)
                ended = time.monotonic() - checked
            finally:
                terminate(process, 5.0)
        output = log_path.read_text()
        print(f"{graph}, SIGINT at {moment}: ended {ended:.2f} s after it or the option checks")
        assert process.returncode == 130, f"{moment}: {output}"
        assert "Traceback" not in output and "Error" not in output, f"{moment}: {output}"
        assert ended < END_WITHIN_S, f"{moment}: {output}"
        report = json.loads(report_path.read_text())
        assert report["interrupted"] is True and report["collisions"] == 0, moment
        if graph != "wall following":
            assert report["localization"]["time_to_localized_s"] is None, moment
        if graph == "goal":
            assert report["goal"] == [0.6, -0.2] and report["goal_reached_time_s"] is None
            assert "path_length_m" in report and report["planning_error"] is None, moment


def test_an_unreachable_goal_ends_the_run_at_once_with_exit_1_and_the_report(tmp_path, capsys):
    # lab02 with inner_far walled in: the filter localizes in the ring, the planner finds no
    # path. The run once idled until --duration and exited 0.
    world = tmp_path / "lab02_walled_in.yaml"
    world.write_text((REPO / "amr_common" / "world" / "worlds" / "lab02.yaml").read_text().replace(
        "walls:\n", "walls:\n  - [[0.4, -0.4], [0.8, -0.4]]\n", 1))
    report_path = tmp_path / "nav.json"
    exit_code = run_sim.main(["--world", str(world), "--goal", "inner_far", "--duration", "600",
                              "--report", str(report_path)])
    err = capsys.readouterr().err
    report = json.loads(report_path.read_text())
    assert exit_code == 1
    assert "run_sim: no path to the goal: goal (0.600, -0.200) is unreachable" in err
    assert "unreachable" in report["planning_error"] and report["interrupted"] is False
    assert report["localized_time_s"] is not None
    assert report["sim_time_s"] < report["localized_time_s"] + 1.0, "ends once planned"


def test_the_scripts_own_command_line_never_reaches_rcl(tmp_path, monkeypatch, capfd):
    # rclpy.init() reads sys.argv by default: a '-p follow_side:=left' value warned as a remap
    # rule, '__node:=evil' renamed every node (StopIteration), '__ns:=/evil' moved them.
    monkeypatch.setattr(sys, "argv", ["run_sim.py", "follow_side:=left", "__node:=evil",
                                      "__ns:=/evil"])
    report_path = tmp_path / "run.json"
    assert run_sim.main(["--duration", "1", "--report", str(report_path)]) == 0
    assert json.loads(report_path.read_text())["nodes"] == ["wall_follower", "amr_simulator"]
    err = capfd.readouterr().err
    assert "deprecated" not in err and "/evil" not in err, err


def test_goal_values_with_signs_and_names_parse():
    assert run_sim.parse_args(["--goal", "-1.0,0.6"]).goal == "-1.0,0.6"
    assert run_sim.parse_args(["--goal=-1,-0.2", "--world", "lab02"]).goal == "-1,-0.2"
    assert run_sim.parse_args(["--goal", "inner_far"]).goal == "inner_far"


def test_a_goal_in_a_wall_is_a_clear_error(capsys):
    assert run_sim.main(["--world", "lab02", "--goal", "0.8,0.2"]) == 2
    assert "goal (0.8, 0.2) touches a wall" in capsys.readouterr().err


@pytest.mark.parametrize("world, start, goal, profile", [
    ("lab02", "outer", "inner_far", "ideal"),
    ("maze_deadends", "south_west", "3.0,2.2", "turtlebot3"),
])
def test_navigate_to_a_goal_with_the_five_node_graph(tmp_path, world, start, goal, profile):
    report_path, plot_path = tmp_path / "nav.json", tmp_path / "nav.png"
    record = tmp_path / "nav.mcap"
    exit_code = run_sim.main(["--world", world, "--start", start, "--goal", goal, "--profile",
                              profile, "--duration", "300", "--report", str(report_path),
                              "--plot", str(plot_path), "--record", str(record)])
    report = json.loads(report_path.read_text())
    # The handover: every lockstep step got exactly one command, from the wall follower until
    # localized, then from the pure pursuit (the last stamp also carries both nodes' final
    # zeros on the way down).
    per_stamp = _commands_per_stamp(record)
    # Every output of the graph, the planner's path among them.
    recorded = _log_times(record)
    assert all(recorded.get(t) for t in ("/path", "/pose", "/amcl_pose", "/particles")), \
        sorted(recorded)
    assert len(per_stamp) == report["steps"], "one stamp per step, no step without a command"
    last = max(per_stamp)
    assert all(n == 1 for stamp, n in per_stamp.items() if stamp != last), \
        {stamp: n for stamp, n in per_stamp.items() if n != 1}
    assert exit_code == 0 and report["collisions"] == 0
    assert report["nodes"] == ["wall_follower", "particle_filter", "planner", "pure_pursuit",
                               "amr_simulator"]
    assert report["localized_time_s"] < report["goal_reached_time_s"] < report["stopped_time_s"]
    assert report["sim_time_s"] < 300.0, "the run ends once the robot rests at the goal"
    assert report["final_position_error_m"] <= 0.05
    assert report["path_length_m"] > 1.0 and len(report["path"]) > 50
    assert plot_path.stat().st_size > 20_000


def test_kidnapped_on_the_way_the_graph_relocalizes_replans_and_reaches_the_goal(tmp_path):
    report_path = tmp_path / "kidnap.json"
    # Carried into the inner maze: relocalized there within seconds, far from where the first
    # path started (lab02's ring opening, about (-1.0, 0.25)). A kidnapping into the ring would
    # relocalize at that same opening again (the only place that tells the ring's sides apart),
    # so a replanned path would start within centimetres of the first one, whatever the seed.
    exit_code = run_sim.main(["--world", "lab02", "--goal", "inner_far", "--kidnap",
                              "40,-0.6,0.6,0", "--duration", "300", "--report",
                              str(report_path)])
    report = json.loads(report_path.read_text())
    assert exit_code == 0 and report["collisions"] == 0
    assert report["localized_time_s"] < 40.0 < report["goal_reached_time_s"]
    assert report["localization"]["loss_reported_after_s"] is not None
    assert report["localization"]["relocalization_times_s"][0] > 40.0
    assert report["path"][0] != pytest.approx([-1.0, 0.25], abs=0.1), "replanned from afar"
    assert report["path"][0] == pytest.approx([-0.6, 0.6], abs=0.3), "from where it was carried"
    assert report["final_position_error_m"] <= 0.05
