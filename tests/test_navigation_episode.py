"""Headless navigation episodes: the goal is reached and the robot rests on it."""
from __future__ import annotations

import json

import pytest

from amr_common.world.world import World, bundled_worlds
from amr_evaluation.navigation_episode import run_navigation_episode
from amr_evaluation.pose_sources import GroundTruthPose
from amr_planning.planner import Planner


@pytest.mark.parametrize("profile", ["ideal", "turtlebot3"])
def test_crosses_lab02_to_the_far_goal_and_rests_on_it(profile):
    result = run_navigation_episode("lab02", "outer", profile=profile, duration=120.0)
    assert result.goal == [0.6, -0.2] and result.path_length_m > 7.0
    assert result.goal_reached and result.stopped_time_s > result.goal_reached_time_s
    assert result.finish_reason == "stopped at the goal"
    assert result.collisions == 0 and result.min_clearance_m > 0.05
    assert result.final_position_error_m <= 0.01
    assert result.path_min_clearance_m >= 0.15
    assert result.cross_track_mean_m <= 0.01 and result.cross_track_max_m <= 0.03
    assert result.plans == 1 and result.planning_errors == []
    assert json.loads(json.dumps(result.to_dict()))["trajectory"][0][0] == 0.0


def test_wall_follower_until_localized_then_replanning_after_a_loss():
    source = GroundTruthPose(localized_after_s=6.0, lost_from_s=15.0, lost_until_s=22.0)
    result = run_navigation_episode("maze_deadends", "south_west", "north_east",
                                    pose_source=source, duration=200.0)
    assert result.pose_source == "GroundTruthPose"
    assert result.localized_time_s == pytest.approx(6.0)
    assert result.plans == 2, "planned when localized and again when relocalized"
    assert result.goal_reached and result.collisions == 0
    assert result.final_position_error_m <= 0.01
    # The path of the second plan starts where the robot was when relocalized, not at the start.
    assert result.path[0] != pytest.approx(result.trajectory[0][1:3], abs=0.05)


def test_duration_runs_out_before_the_goal():
    result = run_navigation_episode("maze_deadends", "south_west", duration=5.0)
    assert not result.goal_reached and result.finish_reason == "duration"
    assert result.stopped_time_s is None and result.sim_time_s == pytest.approx(5.0)
    assert "goal reached never" in result.summary()


def test_no_path_means_a_stall_reported_with_the_planning_error():
    class OnAWall:
        def update(self, sim, z_scan, z_v, z_w):
            return (0.0, -0.8, 0.0), True  # an estimate on lab02's wall: no plan from there

    result = run_navigation_episode("lab02", "outer", pose_source=OnAWall(), duration=60.0,
                                    stall_timeout_s=2.0)
    assert result.stalled and result.finish_reason == "stalled"
    assert result.sim_time_s == pytest.approx(2.0, abs=0.1) and result.distance_m == 0.0
    assert len(result.planning_errors) == 1 and "start (0.000, -0.800) is on a wall" in \
        result.planning_errors[0]


def test_bad_pose_source_is_a_clear_error():
    with pytest.raises(ValueError, match="pose_source must be 'truth', 'filter'"):
        run_navigation_episode("lab02", "outer", pose_source="oracle", duration=1.0)


# --- end to end with the particle filter (amr_localization) ------------------------------------

COURSE_STYLE = [w for w in ("lab02", "maze_deadends", "twin_maze", "twin_maze_small")
                if w in bundled_worlds()]  # 0.4 m corridors on a 0.4 m grid


def course_episodes(name: str) -> list[tuple[str, str, int]]:
    """(start, goal, seed): first start to the default goal, last start to another goal.

    Each episode has its own seed.
    """
    world = World.load(name)
    starts, goals = list(world.starts), list(world.goals)
    default = next(g for g in goals if world.goals[g] == world.goal)
    other = next((g for g in goals if g != default), default)
    return [(starts[0], default, 0), (starts[-1], other, 1)]


@pytest.mark.slow
@pytest.mark.parametrize("profile", ["ideal", "turtlebot3"])
@pytest.mark.parametrize("name", COURSE_STYLE)
def test_explore_localize_plan_and_stop_on_the_goal_with_the_particle_filter(name, profile):
    world = World.load(name)
    planner = Planner(world)
    for start, goal, seed in course_episodes(name):
        result = run_navigation_episode(world, start, goal, profile=profile, seed=seed,
                                        pose_source="filter", planner=planner, duration=300.0,
                                        record_trajectory=False)
        label = f"{name}/{start}->{goal}/{profile}/seed {seed}: {result.summary()}"
        assert result.goal_reached and result.finish_reason == "stopped at the goal", label
        assert result.collisions == 0 and not result.stalled, label
        assert result.final_position_error_m <= 0.05, label
        assert result.planning_errors == [], label


@pytest.mark.slow
@pytest.mark.parametrize("profile, kidnap", [("ideal", (35.0, -1.0, -1.0, 0.0)),
                                             ("turtlebot3", (40.0, 0.2, 1.0, 3.14159))])
def test_a_robot_kidnapped_on_the_way_relocalizes_replans_and_reaches_the_goal(profile, kidnap):
    result = run_navigation_episode("lab02", "outer", "inner_far", profile=profile,
                                    pose_source="filter", kidnap=kidnap, duration=300.0,
                                    record_trajectory=False)
    # Localized at about 27 s, at the goal at about 55 s if not kidnapped.
    assert result.localized_time_s < kidnap[0], "kidnapped while following the path"
    assert result.plans >= 2, "replanned from the relocalized pose"
    assert result.goal_reached and result.collisions == 0, result.summary()
    assert result.final_position_error_m <= 0.05
