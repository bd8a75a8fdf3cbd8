"""The headless episodes (amr_evaluation) drive the ROS lockstep graph's trajectory.

The same episode (world, start, goal, profile, seed) runs through run_sim.py's lockstep graph
(the nodes in one process) and headless; the true trajectories must be identical, step for
step (bound 1e-9 m; measured: 0.0). Both call the rules of amr_common.navigation_behaviour and
see what crosses a topic (float32 scans, quaternion yaws, nanosecond stamps), so nothing is
left to differ.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import run_sim  # noqa: E402

pytestmark = pytest.mark.slow
BOUND_M = 1e-9


def _over_ros(tmp_path, *options: str) -> dict:
    report = tmp_path / "ros.json"
    run_sim.main([*options, "--seed", "0", "--report", str(report)])
    return json.loads(report.read_text())


def _assert_same_trajectory(over_ros, headless) -> None:
    ros, head = np.asarray(over_ros)[:, :3], np.asarray(headless)[:, :3]
    assert ros.shape == head.shape, "both runs end at the same step"
    assert np.abs(ros[:, 0] - head[:, 0]).max() < 1e-6  # the stamps (rounded to the us)
    gap = np.hypot(*(ros[:, 1:3] - head[:, 1:3]).T)
    first = int(np.argmax(gap > BOUND_M))
    assert gap.max() <= BOUND_M, f"apart by {gap.max():.3g} m from t = {ros[first, 0]:.2f} s"
    assert math.dist(ros[0, 1:3], ros[-1, 1:3]) > 0.5  # it did drive


@pytest.mark.parametrize("profile", ["ideal", "turtlebot3"])
def test_wall_following(tmp_path, profile):
    from amr_evaluation.episode import run_episode
    ros = _over_ros(tmp_path, "--world", "lab02", "--start", "inner", "--profile", profile,
                    "--duration", "20")
    headless = run_episode("lab02", "inner", profile=profile, seed=0, duration=20.0)
    _assert_same_trajectory(ros["trajectory"], headless.trajectory)


@pytest.mark.parametrize("profile", ["ideal", "turtlebot3"])
def test_localization_with_a_kidnapping(tmp_path, profile):
    """The estimate too: the filter is fed alike (new scans, odometry time, seed)."""
    from amr_evaluation.localization_episode import run_localization_episode
    kidnap = (10.0, 1.8, 0.2, math.pi)  # to south_east
    ros = _over_ros(tmp_path, "--world", "twin_maze_small", "--start", "north_west",
                    "--profile", profile, "--localize", "--duration", "20",
                    "--kidnap", ",".join(repr(v) for v in kidnap))
    headless = run_localization_episode("twin_maze_small", "north_west", profile=profile,
                                        seed=0, duration=20.0, kidnap=kidnap)
    _assert_same_trajectory(ros["trajectory"], headless.trajectory)
    # One /pose per measurement; the run ends before the last step's is answered.
    estimates = np.asarray(headless.estimate)[:len(ros["estimate"])]
    assert np.abs(estimates - np.asarray(ros["estimate"])).max() <= BOUND_M
    metrics = ros["localization"]  # its stamps are rounded to the microsecond
    assert headless.time_to_localized_s == pytest.approx(metrics["time_to_localized_s"], abs=1e-6)
    assert headless.time_to_localized_s < 10
    assert headless.loss_reported_after_s == pytest.approx(metrics["loss_reported_after_s"],
                                                           abs=1e-6)
    assert headless.loss_reported_after_s is not None


@pytest.mark.parametrize("profile, kidnap", [("ideal", None), ("turtlebot3", None),
                                             ("ideal", (40.0, -0.6, 0.6, 0.0))])
def test_navigation_to_the_goal(tmp_path, profile, kidnap):
    """Explore, localize, plan, follow, stop (kidnapped: lose, explore, replan): alike."""
    from amr_evaluation.navigation_episode import run_navigation_episode
    options = ["--kidnap", ",".join(repr(v) for v in kidnap)] if kidnap else []
    ros = _over_ros(tmp_path, "--world", "lab02", "--start", "outer", "--profile", profile,
                    "--goal", "inner_far", "--duration", "150", *options)
    headless = run_navigation_episode("lab02", "outer", goal="inner_far", profile=profile,
                                      seed=0, duration=150.0, pose_source="filter",
                                      kidnap=kidnap)
    _assert_same_trajectory(ros["trajectory"], headless.trajectory)
    assert headless.goal_reached_time_s == pytest.approx(ros["goal_reached_time_s"], abs=1e-9)
    assert headless.stopped_time_s == pytest.approx(ros["stopped_time_s"], abs=1e-9)
    assert headless.final_position_error_m == ros["final_position_error_m"] < 0.05
    assert headless.path == ros["path"]  # the last plan: replanned alike after a kidnapping
    assert headless.plans == (2 if kidnap else 1)


def test_navigation_among_people(tmp_path):
    """A world with movers: they walk, wait for the robot and are seen alike in both."""
    from amr_evaluation.navigation_episode import run_navigation_episode
    people = str(Path(__file__).resolve().parent.parent / "evaluations" / "worlds" /
                 "room_people.yaml")
    ros = _over_ros(tmp_path, "--world", people, "--map", "room_obstacles", "--start", "middle",
                    "--profile", "ideal", "--goal", "south_west", "--duration", "60")
    headless = run_navigation_episode(people, "middle", goal="south_west", profile="ideal",
                                      seed=0, duration=60.0, pose_source="filter",
                                      map="room_obstacles")
    _assert_same_trajectory(ros["trajectory"], headless.trajectory)
    assert headless.mover_waits == ros["mover_waits"]
    assert any(headless.mover_waits)  # somebody waited for the robot
    assert headless.collisions == ros["collisions"]
    assert headless.collisions_with_movers == ros["collisions_with_movers"]
    assert headless.goal_reached_time_s == pytest.approx(ros["goal_reached_time_s"], abs=1e-9)
