"""Headless mapping episodes and their figures (trajectory error, map precision and recall)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from amr_common.world.map_raster import Raster
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world import World
from amr_evaluation.episode import mapper_parameters
from amr_evaluation.mapping_episode import (
    AUTO_DRIFT,
    TYPICAL_DRIFT,
    DriftingOdometry,
    OdometryDrift,
    episode_drift,
    run_mapping_episode,
)
from amr_evaluation.mapping_metrics import (
    RayHits,
    map_precision,
    map_recall,
    trajectory_errors,
)
from amr_mapping.mapper import Mapper

LIDAR = (0.0, 2 * math.pi / 360, 360, 0.12, 3.5)


@pytest.fixture(scope="module")
def lab02_seen():
    world = World.load("lab02")
    hits = RayHits(world, *LIDAR)
    for x, y in [(1.0, -1.0), (1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (0.6, -0.6), (0.2, 0.6)]:
        for theta in (0.0, 1.0):
            hits.add(x, y, theta)
    return world, hits


def test_a_true_map_scores_full_precision_and_recall_and_a_shifted_one_does_not(lab02_seen):
    world, hits = lab02_seen
    truth = OccupancyGrid.from_world(world, 0.02).raster()
    start = (0.0, 0.0, 0.0)  # map frame = world frame
    assert map_precision(truth, world, start) == 1.0
    recall, seen = map_recall(truth, world, start, hits)
    assert recall == 1.0 and seen > 10.0
    shifted = Raster(truth.values, truth.resolution,
                     (truth.origin[0] + 0.05, truth.origin[1] + 0.05))
    assert map_precision(shifted, world, start) < 0.5
    assert map_recall(shifted, world, start, hits)[0] < 0.5
    # The same map in a start frame: (1.0, -1.0, pi/2) with the raster expressed in it.
    empty = Raster(np.full((3, 3), -1, dtype=np.int8), 0.02, (0.0, 0.0))
    assert math.isnan(map_precision(empty, world, start))
    assert map_recall(empty, world, start, hits)[0] == 0.0


def test_only_walls_that_rays_hit_count_for_recall():
    world = World.load("lab02")
    hits = RayHits(world, *LIDAR)
    hits.add(1.0, -1.0, math.pi / 2)  # one scan from the outer corridor's south-east corner
    truth = OccupancyGrid.from_world(world, 0.02).raster()
    recall, seen = map_recall(truth, world, (0.0, 0.0, 0.0), hits)
    total = float(np.hypot(*(world.segments[:, 2:] - world.segments[:, :2]).T).sum())
    assert recall == 1.0 and 1.0 < seen < 0.5 * total


def test_trajectory_errors_align_the_start():
    start = (1.0, -1.0, math.pi / 2)
    truth = np.array([start, (1.0, -0.5, math.pi / 2), (0.5, -0.5, math.pi)])
    in_start_frame = np.array([(0.0, 0.0, 0.0), (0.5, 0.0, 0.0), (0.5, 0.5, math.pi / 2)])
    errors = trajectory_errors(start, truth, in_start_frame)
    assert errors["trajectory_rmse_m"] == pytest.approx(0.0, abs=1e-12)
    off = in_start_frame + np.array([0.0, 0.03, 0.0])
    errors = trajectory_errors(start, truth, off)
    assert errors["trajectory_rmse_m"] == pytest.approx(0.03)
    assert errors["trajectory_max_m"] == pytest.approx(0.03)


def test_drifting_odometry_is_exact_without_drift_and_seeded_with_it():
    motion = [(0.01 * k, 0.0005 * k * k, 0.02 * k) for k in range(50)]
    exact = DriftingOdometry(None, 0)
    assert [exact.step(m, 0.05) for m in motion] == motion
    runs = []
    for _ in range(2):
        odometry = DriftingOdometry(TYPICAL_DRIFT, 7)
        runs.append([odometry.step(m, 0.05) for m in motion])
    assert runs[0] == runs[1]
    final = runs[0][-1]
    assert 0.0 < math.hypot(final[0] - motion[-1][0], final[1] - motion[-1][1]) < 0.05
    biased = DriftingOdometry(OdometryDrift(gyro_bias_rad_s=0.01), 0)
    for _ in range(20):
        pose = biased.step((0.0, 0.0, 0.0), 0.05)
    assert pose[2] == pytest.approx(19 * 0.05 * 0.01)  # standing still, the heading drifts


@pytest.mark.slow
def test_a_short_mapping_episode_meets_the_figures():
    result = run_mapping_episode("lab02", profile="turtlebot3_clean", seed=0, duration=60.0)
    assert result.odometry_max_error_m > 0.05  # the drift is there to be corrected
    assert result.trajectory_rmse_m <= 0.015 and result.trajectory_max_m <= 0.05
    assert result.precision >= 0.95 and result.recall >= 0.95
    assert result.loop_closures >= 1 and result.collisions == 0
    assert result.scans == 301  # 5 Hz for 60 s, and the first scan
    json.dumps(result.to_dict())  # a report can be written


@pytest.mark.parametrize("profile, deskew, drift", [
    ("turtlebot3_clean", False, TYPICAL_DRIFT), ("ideal", False, TYPICAL_DRIFT),
    ("turtlebot3", True, None), ("turtlebot3_lds02:randomized", True, None),
    ("turtlebot3:off", False, None)])
def test_the_mapper_deskews_what_the_profile_skews_and_odometry_drifts_once(profile, deskew,
                                                                            drift):
    from amr_sim.profiles import get_profile
    prof = get_profile(profile)
    values = mapper_parameters(prof, Mapper)
    assert values["deskew"] is deskew
    assert values["max_linear_speed_mps"] == pytest.approx(0.66)  # every profile's a Burger
    # A profile with the reality gap drifts its own odometry (wheels, slip, IMU): nothing added.
    assert episode_drift(AUTO_DRIFT, prof) == drift
    assert episode_drift(None, prof) is None
    with pytest.raises(ValueError, match="drift"):
        episode_drift("typical", prof)


def test_an_lds02_episode_feeds_each_scans_own_geometry_and_scan_time():
    result = run_mapping_episode("lab02", profile="turtlebot3_lds02", seed=1, duration=15.0)
    stats = result.statistics
    assert result.drift is None and stats["rejected"] == {} and stats["bad_scan_time"] == 0
    assert result.scans >= 70  # about 5 Hz, none lost (lockstep)
    # Each scan mapped at its own angles (seen: 12.5 cm off with the profile's nominal ones).
    assert result.trajectory_max_m < 0.08  # 3.7 cm


def test_the_loop_closure_benchmark_refuses_a_session_without_closures():
    """Its line timed closures that never happened ('median 0.0 ms ... 0 closures ... 0x')."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
    import bench_mapping
    # twin_maze: the wall follower comes back after loop_min_travel_m only after ~100 s.
    with pytest.raises(RuntimeError, match="loop closure: none in 60 s on twin_maze with the "
                                           "branch_and_bound search"):
        bench_mapping.bench_loop_closure(60.0)
    assert min(bench_mapping.LOOP_SESSION_S) >= 200.0


def test_a_map_that_cannot_be_saved_is_said_and_counted(tmp_path, capsys):
    from amr_common.world.map_export import world_as_map
    from amr_evaluation.mapping_evaluation import save_maps
    raster, _ = world_as_map(World.load("lab02"), 0.02)
    episode = {"world": "lab02", "start": [1.0, -1.0, 1.57], "profile": "turtlebot3_clean",
               "seed": 3, "sim_time_s": 20.0, "raster": raster,
               "trajectory": [[0.0, 1.0, -1.0, 1.57]]}
    results = [dict(episode), {**episode, "seed": 4}, {"world": "lab02", "error": "boom"}]
    assert save_maps(results, tmp_path, "amr_mapping.mapper:Mapper") == 0
    assert [r.get("map_file") for r in results] == [
        "maps/lab02-1,-1,1.57-turtlebot3_clean-seed3.yaml",
        "maps/lab02-1,-1,1.57-turtlebot3_clean-seed4.yaml", None]
    saved = World.load(str(tmp_path / results[0]["map_file"]))
    assert saved.starts == {"slam_start": (1.0, -1.0, 1.57)}
    (tmp_path / "blocked").mkdir()
    (tmp_path / "blocked" / "maps").write_text("a file where the folder would go")
    results = [dict(episode)]
    assert save_maps(results, tmp_path / "blocked", "amr_mapping.mapper:Mapper") == 1
    assert results[0]["map_file"] is None and "cannot write the map" in results[0]["map_error"]
    assert "evaluate: map NOT saved:" in capsys.readouterr().err
