"""The Mapper's grid drawn with the LiDAR's range error (amr_mapping.range_error_rays)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.lidar_models import LDS01
from amr_common.map_raster import OCCUPIED
from amr_evaluation.episode import mapper_parameters
from amr_mapping.log_odds_grid import LogOddsGrid
from amr_mapping.loop_closure import draw
from amr_mapping.mapper_params import check_parameters
from amr_mapping.range_error_rays import range_error_rays
from amr_sim.profiles import get_profile

RES = 0.02
WALL_X = 1.0


def _wall_scan(pose, rng):
    """Points (LiDAR frame) of the wall x = WALL_X from an LDS-01 at its typical errors.

    Bias 0.5 x the datasheet's accuracy, noise sigma 0.5 x its precision.
    """
    angles = np.linspace(-1.2, 1.2, 121)
    true = (WALL_X - pose[0]) / np.cos(pose[2] + angles)
    accuracy, precision = LDS01.bounds(true)
    r = true + 0.5 * accuracy + rng.normal(0.0, 0.5 * precision)
    keep = (true > LDS01.sensing_min) & (true < LDS01.sensing_max)
    return np.column_stack([r * np.cos(angles), r * np.sin(angles)])[keep]


def _wall_map(lidar_model: str) -> tuple[LogOddsGrid, list]:
    """A grid of 60 scans of the wall from 3 m to 0.4 m away."""
    rng = np.random.default_rng(0)
    params = check_parameters({"lidar_model": lidar_model})
    grid = LogOddsGrid(RES, 10_000_000, 0.9, 0.4, 0.02, rays=range_error_rays(params))
    scans = []
    for k in range(60):
        pose = (-2.0 + 2.6 * k / 59, 0.3 * math.sin(k), 0.0)
        scans.append((pose, _wall_scan(pose, rng)))
        draw(grid, pose, scans[-1][1], 0.0)
    return grid, scans


def _occupied_x(grid: LogOddsGrid) -> np.ndarray:
    raster = grid.raster(0.6, -0.4, 0.2)
    _, cols = np.nonzero(raster.values == OCCUPIED)
    return raster.origin[0] + (cols + 0.5) * RES


def test_a_noisy_wall_is_drawn_thin_with_the_lidar_model_and_thick_without():
    plain = _occupied_x(_wall_map("none")[0])
    modelled = _occupied_x(_wall_map("LDS-01")[0])
    # As returned, the far returns (up to 3.5 % noise and 2.5 % bias) spread the wall over
    # cells far behind it; drawn by the model only the near returns mark it. (Cell centres:
    # the wall lies on a cell border, its two neighbours' centres 1 cm away.)
    plain_off, modelled_off = np.abs(plain - WALL_X), np.abs(modelled - WALL_X)
    assert np.mean(plain_off <= 0.0305) < 0.35 and plain_off.max() > 0.15
    assert np.mean(modelled_off <= 0.0305) > 0.9 and modelled_off.max() < 0.0505
    assert len(modelled) >= 30  # the wall is still there: 0.6 m of it seen from near


def test_a_scan_drawn_with_the_model_is_removed_exactly():
    grid, scans = _wall_map("LDS-01")
    assert grid.counts.any() and grid.hits.any()
    for pose, points in scans:
        draw(grid, pose, points, 0.0, -1)
    assert not grid.counts.any() and not grid.hits.any()


@pytest.mark.parametrize("profile, model", [
    ("ideal", "none"), ("turtlebot3_clean", "none"), ("turtlebot3", "LDS-01"),
    ("turtlebot3:randomized", "LDS-01"), ("turtlebot3_lds02", "LDS-02"),
    ("turtlebot3:off:scan_skew=1", "none")])
def test_episodes_give_the_mapper_the_simulated_lidars_range_error_model(profile, model):
    assert mapper_parameters(get_profile(profile))["lidar_model"] == model


def test_an_unknown_lidar_model_is_refused_naming_the_choices():
    with pytest.raises(ValueError, match="lidar_model"):
        check_parameters({"lidar_model": "LDS-03"})
