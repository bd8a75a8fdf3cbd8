"""LiDAR ranges against analytic distances in a known room, both profiles' encodings, noise."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from amr_common.world.world import World
from amr_sim.lidar import Lidar
from amr_sim.profiles import IDEAL, TURTLEBOT3, TURTLEBOT3_CLEAN, get_profile
from amr_sim.simulator import Simulator

ROOM = (4.0, 3.0)  # rectangular room [0, 4] x [0, 3]


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    path = tmp_path_factory.mktemp("worlds") / "room.yaml"
    w, h = ROOM
    path.write_text(f"boundary: [[0, 0], [{w}, 0], [{w}, {h}], [0, {h}]]\n")
    return World.load(path)


@pytest.fixture(scope="module")
def long_corridor(tmp_path_factory):
    path = tmp_path_factory.mktemp("worlds") / "corridor.yaml"
    path.write_text("boundary: [[0, 0], [20, 0], [20, 1], [0, 1]]\n")
    return World.load(path)


def room_distance(x, y, angle):
    """Distance from (x, y) along `angle` to the walls of the room (analytic)."""
    c, s = math.cos(angle), math.sin(angle)
    w, h = ROOM
    tx = (w - x) / c if c > 1e-12 else (-x / c if c < -1e-12 else math.inf)
    ty = (h - y) / s if s > 1e-12 else (-y / s if s < -1e-12 else math.inf)
    return min(tx, ty)


@pytest.mark.parametrize("pose", [(1.0, 1.0, 0.0), (1.0, 1.0, 0.3), (3.1, 2.2, -2.0),
                                  (2.0, 1.5, math.pi)])
def test_ideal_ranges_equal_analytic_distances(room, pose):
    sim = Simulator(room, start=pose, profile="ideal")
    z_scan, _, _ = sim.measure()
    n = IDEAL.scan_rays
    assert z_scan.shape == (240,)
    x, y, th = pose
    # front, left, back, right and a diagonal ray (45 deg to the left), CCW from straight ahead
    for index in (0, n // 4, n // 2, 3 * n // 4, n // 8):
        expected = room_distance(x, y, th + index * IDEAL.angle_increment)
        assert z_scan[index] == pytest.approx(expected, abs=1e-9), index
    expected_all = [room_distance(x, y, th + i * IDEAL.angle_increment) for i in range(n)]
    np.testing.assert_allclose(z_scan, expected_all, atol=1e-9)


def test_known_values_front_left_back_right(room):
    sim = Simulator(room, start=(1.0, 1.0, math.pi / 2), profile="ideal")  # facing +y
    z = sim.measure()[0]
    assert z[0] == pytest.approx(2.0)   # ahead: north wall at y = 3
    assert z[60] == pytest.approx(1.0)  # left: west wall at x = 0
    assert z[120] == pytest.approx(1.0)  # behind: south wall at y = 0
    assert z[180] == pytest.approx(3.0)  # right: east wall at x = 4
    # 45 deg left of north: reaches x = 0 after sqrt(2) m
    assert z[30] == pytest.approx(math.sqrt(2.0))


def test_ideal_no_return_is_nan_beyond_8_m(long_corridor):
    sim = Simulator(long_corridor, start=(1.0, 0.5, 0.0), profile="ideal")
    z = sim.measure()[0]
    assert math.isnan(z[0])  # 19 m ahead
    assert z[120] == pytest.approx(1.0)  # 1 m behind
    assert z[60] == pytest.approx(0.5)
    assert not np.isnan(z[1:]).all()


def test_turtlebot3_encoding_zero_beyond_3_5_m_and_below_0_12_m(long_corridor):
    noiseless = dataclasses.replace(TURTLEBOT3_CLEAN, range_noise_sigma=0.0)
    sim = Simulator(long_corridor, start=(1.0, 0.11, 0.0), profile=noiseless)
    z = sim.measure()[0]
    assert z.shape == (360,)
    assert z[0] == 0.0  # 19 m ahead: beyond range_max
    assert z[180] == pytest.approx(1.0 - 0.032)  # behind, from base_scan 32 mm behind the centre
    assert z[90] == pytest.approx(0.89)  # left: y = 1
    assert z[270] == 0.0  # right: 0.11 m < range_min
    assert np.all((z == 0.0) | ((z >= 0.12) & (z <= 3.5)))
    assert not np.isnan(z).any()


def test_turtlebot3_clean_noise_sigma_and_reproducibility(room):
    pose = (1.3, 1.1, 0.4)
    a = Simulator(room, start=pose, profile="turtlebot3_clean", seed=3).measure()[0]
    b = Simulator(room, start=pose, profile="turtlebot3_clean", seed=3).measure()[0]
    c = Simulator(room, start=pose, profile="turtlebot3_clean", seed=4).measure()[0]
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    lx, ly = pose[0] - 0.032 * math.cos(pose[2]), pose[1] - 0.032 * math.sin(pose[2])  # base_scan
    truth = np.array([room_distance(lx, ly, pose[2] + math.radians(i)) for i in range(360)])
    valid = truth < 3.4  # away from range_max, where noise can drop a reading
    err = a[valid] - truth[valid]
    assert valid.sum() > 250
    assert abs(err.mean()) < 0.003  # unbiased: 3 standard errors of the mean
    assert 0.0085 < err.std() < 0.0115  # sigma 0.01 m (standard error of the estimate ~0.0004)


def test_turtlebot3_scan_refreshes_at_5_hz(room):
    sim = Simulator(room, start=(1.0, 1.0, 0.0), profile="turtlebot3", dt=0.05)
    first = sim.measure()[0]
    scans = [sim.step(0.1, 0.2)[0] for _ in range(8)]
    # New scans at t = 0.2 s and 0.4 s (steps 4 and 8); the others repeat the newest one.
    for k in (0, 1, 2):
        np.testing.assert_array_equal(scans[k], first)
    assert not np.array_equal(scans[3], first)
    for k in (4, 5, 6):
        np.testing.assert_array_equal(scans[k], scans[3])
    assert not np.array_equal(scans[7], scans[3])
    assert sim.scan_time == pytest.approx(0.4)


@pytest.mark.parametrize("theta", [0.0, 0.7, -2.4])
def test_turtlebot3_scans_from_base_scan_32_mm_behind_the_centre(room, theta):
    noiseless = dataclasses.replace(TURTLEBOT3_CLEAN, range_noise_sigma=0.0)
    sim = Simulator(room, start=(2.0, 1.5, theta), profile=noiseless)
    lx, ly = sim.lidar_position
    assert (lx, ly) == pytest.approx((2.0 - 0.032 * math.cos(theta),
                                      1.5 - 0.032 * math.sin(theta)))
    z = sim.measure()[0]
    expected = [room_distance(lx, ly, theta + math.radians(i)) for i in range(360)]
    np.testing.assert_allclose(z, expected, atol=1e-9)
    # The ideal (course) robot scans from its centre.
    assert Simulator(room, start=(2.0, 1.5, theta), profile="ideal").lidar_position == (2.0, 1.5)


def test_numba_and_numpy_kernels_agree():
    world = World.load("room_obstacles")
    args = (world.segments, 360, 0.0, 2 * math.pi / 360, 0.12, 3.5, 0.0)
    fast, slow = Lidar(*args, use_numba=True), Lidar(*args, use_numba=False)
    for x, y, th in [(0.4, 0.4, 0.0), (1.2, 1.7, 1.0), (3.6, 2.7, -2.5)]:
        np.testing.assert_allclose(fast.scan(x, y, th), slow.scan(x, y, th), atol=1e-12)


def test_profiles():
    assert get_profile("ideal") is IDEAL and get_profile(TURTLEBOT3) is TURTLEBOT3
    assert IDEAL.angle_max == pytest.approx(2 * math.pi - 2 * math.pi / 240)
    assert TURTLEBOT3.angle_max == pytest.approx(math.radians(359))
    assert get_profile("turtlebot3_clean") is TURTLEBOT3_CLEAN
    with pytest.raises(ValueError, match="unknown profile 'gazebo'"):
        get_profile("gazebo")
