"""Runs on a map world: the wall follower, the particle filter, the planner and the ROS graph.

The map is lab02 converted at 2 cm (scripts/world_to_map.py). Its walls lie within half a cell
(1 cm) of lab02's and its corners within half a cell diagonal (1.4 cm); the wall follower steers
by what its LiDAR sees, so its path may move by as much. Bound for "the same trajectory": every
point of either run within 2 cm of the other run's path (1.4 cm + 0.6 cm for the controller's
response to a moved wall). Compared as paths, not time by time: a 1 cm shift changes the speed
in the corners, and the runs drift apart in time (~0.2 m after 120 s) along the same path.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.geometry import without_repeats
from amr_common.world.map_file import world_as_map, write_map
from amr_common.world.world import World
from amr_evaluation.episode import run_episode
from amr_evaluation.localization_episode import run_localization_episode
from amr_evaluation.navigation_episode import distances_to_polyline, run_navigation_episode
from amr_sim.lidar import Lidar
from amr_sim.simulator import Simulator

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import bench_map_world  # noqa: E402
import run_sim  # noqa: E402

SAME_PATH_M = 0.02


@pytest.fixture(scope="module")
def lab02_map(tmp_path_factory) -> str:
    raster, extras = world_as_map(World.load("lab02"), 0.02)
    yaml_path, _ = write_map(raster, tmp_path_factory.mktemp("maps") / "lab02", extras=extras)
    return str(yaml_path)


def path_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance from a point of either trajectory to the other's path (m)."""
    return max(float(distances_to_polyline(a, without_repeats(b)).max()),
               float(distances_to_polyline(b, without_repeats(a)).max()))


@pytest.mark.parametrize("profile", ["ideal", "turtlebot3"])
def test_the_wall_follower_drives_lab02_as_a_map_as_in_lab02(lab02_map, profile):
    runs = [run_episode(world, start="outer", profile=profile, duration=120.0, seed=0)
            for world in ("lab02", lab02_map)]
    polygon, mapped = runs
    assert polygon.collisions == 0 and mapped.collisions == 0
    assert mapped.laps == polygon.laps == 2
    assert mapped.explored_fraction == polygon.explored_fraction
    trajectories = [np.array(run.trajectory)[:, 1:3] for run in runs]
    assert path_gap(*trajectories) <= SAME_PATH_M
    assert abs(mapped.distance_m - polygon.distance_m) <= 0.01 * polygon.distance_m


def test_a_slam_like_map_is_ray_marched_with_the_same_scans(lab02_map):
    polygon = World.load("lab02")
    raster = bench_map_world.slam_like(World.load(lab02_map).raster,
                                       keep_clear=polygon.starts.values())
    world = World.from_raster(raster, starts=polygon.starts)
    sim = Simulator(world, start="outer", profile="turtlebot3_clean", seed=2)
    assert sim.lidar.grid is not None  # World.march_grid: 1,366 segments
    p = sim.profile
    by_segments = Lidar(world.segments, p.scan_rays, p.angle_min, p.angle_increment,
                        p.range_min, p.range_max, p.no_return)
    for v, w in [(0.1, 0.0)] * 20 + [(0.0, 1.0)] * 20:
        sim.step(v, w)
        x, y = sim.lidar_position
        np.testing.assert_allclose(sim.lidar.scan(x, y, sim.pose[2]),
                                   by_segments.scan(x, y, sim.pose[2]), rtol=0, atol=1e-9)


def test_the_particle_filter_localizes_on_a_map_world(lab02_map):
    result = run_localization_episode(lab02_map, start="outer", profile="turtlebot3",
                                      duration=45.0, seed=1)
    assert result.collisions == 0 and result.false_localizations == 0
    assert result.time_to_localized_s is not None and result.time_to_localized_s < 40.0
    # The map's walls are 1 cm off the true ones in places; the filter still tracks to ~1 cm.
    assert result.tracking_error_p95_m < 0.02


def test_the_planner_and_the_pursuit_reach_a_goal_on_a_map_world(lab02_map):
    result = run_navigation_episode(lab02_map, start="outer", goal="inner_far",
                                    profile="turtlebot3", duration=150.0, seed=1,
                                    pose_source="filter")
    assert result.finish_reason == "stopped at the goal", result.finish_reason
    assert result.collisions == 0 and result.final_position_error_m <= 0.05
    world = World.load(lab02_map)
    # The planned path keeps the inflation radius from the map's walls (its cell edges).
    assert result.path_min_clearance_m >= 0.105 + 0.03 - 0.01
    assert world.contains_points(np.array(result.path)).all()


def test_run_sim_navigates_on_a_map_yaml_with_the_ros_graph(lab02_map, tmp_path):
    report_path = tmp_path / "nav.json"
    exit_code = run_sim.main(["--world", lab02_map, "--start", "outer", "--goal", "inner_far",
                              "--duration", "200", "--report", str(report_path)])
    report = json.loads(report_path.read_text())
    assert exit_code == 0 and report["collisions"] == 0
    assert report["final_position_error_m"] <= 0.05
