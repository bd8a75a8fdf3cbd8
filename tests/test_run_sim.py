"""run_sim.py end to end: simulator + wall follower + lifecycle manager in one process."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
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
