"""The wall follower's perception (scan_sectors.LocalPointCloud over point_cloud_kernels).

Points from scans, carried with the odometry, held when an LDS-01 goes blind up close,
sectors, swept path, side distances and the fitted wall, checked against plain numpy.
"""
import math

import numpy as np
import pytest

from amr_common.jit import HAVE_NUMBA
from amr_control import point_cloud_kernels as kernels
from amr_control.scan_sectors import LocalPointCloud, PerceptionSpec, ScanGeometry
from tests.scan_helpers import LDS01_360, cast  # the synthetic LiDAR

SECTORS = {"front": 0.0, "left": 0.5 * math.pi, "right": -0.5 * math.pi, "back": math.pi}
RAYS_360 = ScanGeometry(0.0, 2.0 * math.pi / 360, 0.12, 3.5)   # LDS-01 convention


def make_cloud(side=-1.0, hold_time=0.6, hold_range=0.3):
    spec = PerceptionSpec(side, SECTORS, 0.1745, {"front": 25.0}, path_half_width_m=0.135,
                          side_window_m=0.03, side_open_m=0.32, fit_half_length_m=0.15)
    return LocalPointCloud(hold_time, hold_range, 0.0, spec)


def wall_scan(distance, angle=0.0, noise=0.0, seed=0):
    """LDS-01 ranges (0.0 = no return) of a straight wall on the right, with range noise.

    The wall is `distance` (m) from the robot, rotated by `angle` (rad) in the robot frame; the
    noise is Gaussian.
    """
    normal = (math.sin(angle), -math.cos(angle))        # from the robot to the wall
    along = (math.cos(angle), math.sin(angle))
    foot = (distance * normal[0], distance * normal[1])
    wall = [[foot[0] - 5 * along[0], foot[1] - 5 * along[1],
             foot[0] + 5 * along[0], foot[1] + 5 * along[1]]]   # longer than range_max
    r = cast(wall, LDS01_360)
    if noise:
        hit = r > 0.0
        r[hit] += np.random.default_rng(seed).normal(0.0, noise, int(hit.sum()))
        r[(r < RAYS_360.range_min) | (r > RAYS_360.range_max)] = 0.0
    return r


def test_straight_wall_gives_its_distance_angle_and_beside_distance():
    cloud = make_cloud()
    valid, p = cloud.step(0.0, 0.0, 0.05, wall_scan(0.2, angle=0.1), RAYS_360)
    assert valid > 100
    assert p.fit is not None
    assert p.fit.distance_m == pytest.approx(0.2, abs=1e-9)
    assert p.fit.angle_rad == pytest.approx(0.1, abs=1e-9)
    assert p.fit.residual_m < 1e-9
    # Right beside the robot (|x| <= 3 cm) the wall is at 0.2 / cos(0.1) laterally, or closer.
    assert 0.19 < p.beside_m <= 0.2 / math.cos(0.1) + 1e-9
    assert p.beside_other_m == math.inf          # nothing on the left
    # The closest point of the wall (0.2 m along its normal) lies inside the right sector.
    assert p.sectors["left"] == math.inf and p.sectors["right"] == pytest.approx(0.2, abs=1e-3)


def test_noisy_wall_fit_is_within_the_noise():
    cloud = make_cloud()
    _, p = cloud.step(0.0, 0.0, 0.05, wall_scan(0.25, noise=0.01, seed=3), RAYS_360)
    assert p.fit.distance_m == pytest.approx(0.25, abs=0.01)
    assert abs(p.fit.angle_rad) < 0.1
    assert 0.002 < p.fit.residual_m < 0.02


def test_points_move_with_the_odometry_between_scans():
    cloud = make_cloud()
    ranges = wall_scan(0.2)
    cloud.step(0.0, 0.0, 0.05, ranges, RAYS_360)
    # The robot turned 0.1 rad to the left in place and the LiDAR repeated its scan (held):
    # the points turn with the odometry, so the wall now lies at -0.1 rad.
    valid, p = cloud.step(0.0, 0.1, 0.05, ranges, RAYS_360)
    assert valid is None                         # a held scan is not merged again
    assert p.fit.angle_rad == pytest.approx(-0.1, abs=1e-9)
    assert p.fit.distance_m == pytest.approx(0.2, abs=1e-9)


def test_close_points_are_held_when_their_rays_go_blind_then_dropped():
    cloud = make_cloud(hold_time=0.6)
    cloud.step(0.0, 0.0, 0.05, wall_scan(0.2), RAYS_360)
    blind = np.zeros(360)                        # LDS-01 below 0.12 m: every ray reads 0.0
    valid, p = cloud.step(0.0, 0.0, 0.05, blind, RAYS_360)
    assert valid == 0
    assert p.fit is not None and p.fit.distance_m == pytest.approx(0.2, abs=1e-9)
    steps = 0
    while p.fit is not None and steps < 40:     # a new blind scan every step (varying by a bit)
        blind = np.zeros(360)
        blind[180 + steps % 2] = 0.01            # below range_min: still no return
        _, p = cloud.step(0.0, 0.0, 0.05, blind, RAYS_360)
        steps += 1
    assert 9 <= steps <= 13                      # gone once older than 0.6 s (12 steps of 50 ms)


def test_held_point_is_replaced_when_its_ray_returns_again():
    cloud = make_cloud()
    cloud.step(0.0, 0.0, 0.05, wall_scan(0.2), RAYS_360)
    cloud.step(0.0, 0.0, 0.05, np.zeros(360), RAYS_360)
    assert cloud.size > 0                        # held
    valid, _ = cloud.step(0.0, 0.0, 0.05, wall_scan(0.2), RAYS_360)
    assert cloud.size == valid                   # the fresh points only, no duplicates


@pytest.mark.parametrize("seed", range(5))
def test_sectors_and_path_match_a_plain_numpy_computation(seed):
    rng = np.random.default_rng(seed)
    rays = 240
    geometry = ScanGeometry(0.0, 2.0 * math.pi / rays, 0.016, 8.0)
    ranges = rng.uniform(0.1, 3.0, rays)
    ranges[rng.random(rays) < 0.1] = math.nan
    cloud = make_cloud()
    _, p = cloud.step(0.0, 0.0, 0.05, ranges, geometry)
    a = geometry.angle_increment * np.arange(rays)
    ok = np.isfinite(ranges)
    x, y, r, ang = ranges[ok] * np.cos(a[ok]), ranges[ok] * np.sin(a[ok]), ranges[ok], a[ok]
    for name, centre in SECTORS.items():
        offset = np.abs((ang - centre + math.pi) % (2 * math.pi) - math.pi)
        inside = np.sort(r[offset <= 0.1745])
        if name == "front":
            expected = inside[int(0.25 * (inside.size - 1))] if inside.size else math.inf
        else:
            expected = inside[0] if inside.size else math.inf
        assert p.sectors[name] == pytest.approx(expected, rel=1e-12), name
    ahead = x[(x > 0) & (np.abs(y) <= 0.135)]
    assert p.path_m == pytest.approx(ahead.min() if ahead.size else math.inf, rel=1e-12)


def test_side_gap_reports_the_end_of_the_wall_behind_and_the_points_ahead():
    cloud = make_cloud()
    ranges = wall_scan(0.2)
    a = RAYS_360.angle_increment * np.arange(360)
    x = ranges * np.cos(a)
    ranges[(ranges > 0) & (x > -0.1)] = 0.0      # the right wall ends 10 cm behind the robot
    cloud.step(0.0, 0.0, 0.05, ranges, RAYS_360)
    wall_end, ahead = cloud.side_gap(-1.0, 0.32)
    assert -0.11 < wall_end <= -0.1
    assert ahead.size == 0


def test_a_wrong_perception_spec_is_refused():
    with pytest.raises(ValueError, match="half-width"):
        PerceptionSpec(-1.0, SECTORS, 2.0, {}, path_half_width_m=0.1, side_window_m=0.03,
                       side_open_m=0.3, fit_half_length_m=0.15)
    with pytest.raises(ValueError, match="side_sign"):
        PerceptionSpec(0.5, SECTORS, 0.2, {}, path_half_width_m=0.1, side_window_m=0.03,
                       side_open_m=0.3, fit_half_length_m=0.15)


def test_kernels_are_compiled_by_numba():
    # The pinned environment has numba: the per-step cost depends on it (pure Python ~100x).
    assert HAVE_NUMBA
    assert hasattr(kernels.step_cloud, "signatures") and kernels.step_cloud.signatures
