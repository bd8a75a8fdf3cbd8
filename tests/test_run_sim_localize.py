"""run_sim.py --localize, run_robot.py --localize and evaluate.py --localize end to end."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import evaluate  # noqa: E402
import run_robot  # noqa: E402
import run_sim  # noqa: E402

pytestmark = pytest.mark.slow


def test_lockstep_graph_localizes_and_reports_every_pose(tmp_path):
    report_path, plot_path = tmp_path / "loc.json", tmp_path / "loc.png"
    exit_code = run_sim.main(["--world", "twin_maze_small", "--start", "north_west",
                              "--localize", "--duration", "25", "--report", str(report_path),
                              "--plot", str(plot_path)])
    report = json.loads(report_path.read_text())
    assert exit_code == 0
    assert report["nodes"] == ["wall_follower", "particle_filter", "amr_simulator"]
    # One /pose per synchronized pair: the first measurement and every step, stamped alike
    # (the run ends before the measurement after its last step is answered).
    estimate = report["estimate"]
    assert len(estimate) == report["steps"] == 500
    assert [round(row[0], 6) for row in estimate] == [round(0.05 * k, 6) for k in range(500)]
    assert [row[0] for row in estimate[:3]] == [0.0, 0.05, 0.1]
    metrics = report["localization"]
    assert metrics["false_localizations"] == 0
    assert metrics["time_to_localized_s"] is not None and metrics["time_to_localized_s"] < 20
    assert metrics["tracking_error_mean_m"] < 0.02
    assert report["particles_snapshot"], "the particles when the filter first declared a pose"
    assert report["collisions"] == 0, "the wall follower keeps exploring once localized"
    assert report["distance_m"] > 2.0
    assert plot_path.stat().st_size > 30_000


def test_kidnapping_in_the_ros_graph_is_reported_and_recovered(tmp_path):
    report_path = tmp_path / "kidnap.json"
    run_sim.main(["--world", "maze_deadends", "--start", "south_west", "--localize",
                  "--kidnap", f"15,1.4,1.0,{math.pi / 2}", "--duration", "45",
                  "--report", str(report_path)])
    metrics = json.loads(report_path.read_text())["localization"]
    assert metrics["time_to_localized_s"] < 15
    assert metrics["loss_reported_after_s"] <= 2.0
    assert metrics["relocalized_after_s"] is not None and metrics["relocalized_after_s"] < 30
    assert metrics["false_localizations"] == 0


def test_record_holds_pose_and_particles(tmp_path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    record = tmp_path / "loc.mcap"
    run_sim.main(["--world", "twin_maze_small", "--localize", "--duration", "3", "--record",
                  str(record)])
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with AnyReader([record], default_typestore=typestore) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        types = {c.topic: c.msgtype for c in reader.connections}
        map_to_odom = []  # the filter's, once per /pose; the simulator's truth would double it
        for connection, _, raw in reader.messages([c for c in reader.connections
                                                    if c.topic == "/tf"]):
            message = reader.deserialize(raw, connection.msgtype)
            map_to_odom += [t for t in message.transforms
                            if (t.header.frame_id, t.child_frame_id) == ("map", "odom")]
    assert 59 <= counts["/pose"] <= 61 and types["/pose"] == "amr_msgs/msg/PoseStamped"
    # The filter sends map -> odom with each /pose; the simulator's perfect one is off.
    assert 59 <= len(map_to_odom) <= 61
    assert counts["/particles"] >= 6 and types["/particles"] == "geometry_msgs/msg/PoseArray"
    assert counts["/amcl_pose"] >= 1


def test_realtime_rehearsal_runs_the_robot_graph_with_the_filter(tmp_path):
    report_path = tmp_path / "rehearsal.json"
    exit_code = run_sim.main(["--world", "twin_maze_small", "--profile", "turtlebot3",
                              "--realtime", "--localize", "--duration", "10",
                              "--report", str(report_path)])
    report = json.loads(report_path.read_text())
    assert exit_code == 0
    assert report["nodes"] == ["amr_odometry", "wall_follower", "particle_filter",
                               "amr_simulator"]
    # Real time: a /pose per synchronized /odometry + 5 Hz /scan pair.
    assert 35 <= len(report["estimate"]) <= 55
    assert report["localization"]["false_localizations"] == 0
    assert report["distance_m"] > 0.5


def test_the_simulated_robot_sets_the_scan_time_even_over_the_robots_params_file():
    # The rehearsal reads turtlebot3.yaml (the real LiDAR: 0.2 s); the clean profile
    # (turtlebot3_clean) does not skew its scans, and de-skewing them smeared the walls: the
    # rehearsal above drove 0.45 m in 10 s instead of more than 0.5 m. -p still sets it.
    from launch_common import ROBOT_PARAMS, SIM_PARAMS
    from launch_common import simulated_robot_parameters as _robot_parameters
    assert _robot_parameters({}, ROBOT_PARAMS, "turtlebot3_clean") == {"scan_revolution_s": 0.0}
    assert _robot_parameters({}, ROBOT_PARAMS, "turtlebot3") == {"scan_revolution_s": 0.2}
    assert _robot_parameters({"scan_revolution_s": 0.1}, ROBOT_PARAMS, "turtlebot3_clean") == {}
    assert _robot_parameters({}, SIM_PARAMS, "turtlebot3") == {
        "lidar_offset_x_m": -0.032, "scan_revolution_s": 0.2}


def test_run_robot_localize_needs_a_map(capsys):
    with pytest.raises(SystemExit):
        run_robot.parse_args(["--localize"])
    assert "--localize needs --map" in capsys.readouterr().err
    args = run_robot.parse_args(["--localize", "--map", "lab02", "--pf-param", "beams:=90"])
    assert args.localize and args.pf_overrides == {"beams": 90}


def test_evaluate_localize_writes_the_metrics_as_columns(tmp_path):
    out = tmp_path / "eval"
    exit_code = evaluate.main(["--localize", "--worlds", "twin_maze_small", "--starts",
                               "north_west", "--profiles", "ideal,turtlebot3", "--seeds", "0",
                               "--duration", "20", "--jobs", "1", "--out", str(out)])
    assert exit_code == 0
    data = json.loads((out / "results.json").read_text())
    assert data["summary"]["episodes"] == 2 and data["summary"]["false_localizations"] == 0
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    for column in ("time_to_localized_s", "false_localizations", "tracking_error_mean_m",
                   "tracking_error_p95_m", "heading_error_p95_deg", "relocalization_times_s"):
        assert column in header


def test_ctrl_c_while_the_filter_builds_a_big_maps_table_ends_the_run_with_its_report(tmp_path):
    """SIGINT, SIGINT, SIGTERM once did nothing for minutes while the table was built.

    A 10 x 10 m floor whose filter map is that floor at 2 cm with 1 % specks (the table: ~7 s
    of CPU). The Ctrl-C comes as the filter starts configuring (right after the node before it):
    the run stops there, writes its report (interrupted, nothing simulated), exits 130.
    """
    import signal
    import subprocess
    import threading

    from tests.processes import REPO, terminate, wait_for
    from tools.make_speckled_map import write_speckled_map
    world = tmp_path / "floor.yaml"
    world.write_text("boundary: [[0, 0], [10, 0], [10, 10], [0, 10]]\n"
                     "starts:\n  centre: [5.0, 5.0, 0.0]\n")
    map_path = write_speckled_map(tmp_path / "specks", 500, 0.01)
    report = tmp_path / "report.json"
    run = subprocess.Popen(
        [sys.executable, str(SCRIPTS / "run_sim.py"), "--world", str(world), "--map",
         str(map_path), "--localize", "--duration", "5", "--report", str(report)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=REPO)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(run.stdout.readline, "")),
                              daemon=True)
    try:
        reader.start()
        wait_for(lambda: any("'wall_follower': configure OK" in line for line in lines), 60,
                 "the node before the filter to configure")
        run.send_signal(signal.SIGINT)
        code = run.wait(timeout=60)
    finally:
        terminate(run, 2.0)
    reader.join(5)
    output = "".join(lines)
    assert code == 130, output
    assert "run_sim: interrupted" in output and "simulated in 0.0 s" in output
    assert "configure stopped: building the expected-range table was stopped" in output
    assert "[particle_filter]: configured" not in output and "Traceback" not in output
    written = json.loads(report.read_text())
    assert written["interrupted"] and written["steps"] == 0
