"""The real scanner's effects: noise and error by datasheet band, dropouts, scan skew, the LDS-02.

Each effect alone (the others off: `turtlebot3:off:...`), measured against the room's
analytic distances.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.robot import LIDAR_OFFSET_X
from amr_common.world.raycast import cast_rays_kernel, cast_rays_numpy
from amr_common.world.world import World
from amr_sim.lidar_effects import RealLidar, scan_rays_kernel, scan_rays_numpy
from amr_sim.profiles import get_profile
from amr_sim.reality import effects_of
from amr_sim.simulator import Simulator

W, H = 4.0, 3.0  # the room [0, 4] x [0, 3]
# Robot at (0.5, 0.4) facing +x: the LiDAR (32 mm behind) sees the bottom wall 0.4 m away at
# 270 deg and the back wall 0.468 m away at 180 deg (LDS-01 near band, < 0.5 m), the top wall
# 2.6 m away at 90 deg (far band), and the bottom wall at 350 deg grazing (80 deg incidence).
POSE = (0.5, 0.4, 0.0)
LIDAR = (POSE[0] + LIDAR_OFFSET_X, POSE[1])


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    path = tmp_path_factory.mktemp("worlds") / "room.yaml"
    path.write_text(f"boundary: [[0, 0], [{W}, 0], [{W}, {H}], [0, {H}]]\n")
    return World.load(path)


def distance(x, y, angle):
    """Distance from (x, y) along `angle` to the room's walls (analytic)."""
    c, s = math.cos(angle), math.sin(angle)
    tx = (W - x) / c if c > 1e-12 else (-x / c if c < -1e-12 else math.inf)
    ty = (H - y) / s if s > 1e-12 else (-y / s if s < -1e-12 else math.inf)
    return min(tx, ty)


def readings(room, spec, degrees, scans=2000, seed=0):
    """`scans` readings of the rays at `degrees` (increasing) by the robot at rest at POSE."""
    sim = Simulator(room, start=POSE, profile=spec, seed=seed)
    angles = np.radians(degrees)
    return np.array([sim.lidar.cast(0.0, angles) for _ in range(scans)])


def test_noise_sigma_follows_the_datasheet_bands(room):
    near_0, near_1, far = 0.4, LIDAR[0], H - LIDAR[1]
    r = readings(room, "turtlebot3:off:range_noise_share=1", [90.0, 180.0, 270.0])
    # LDS-01 precision: 10 mm below 0.5 m, 3.5 % of the range above.
    assert r[:, 1].std() == pytest.approx(0.010, rel=0.06)
    assert r[:, 2].std() == pytest.approx(0.010, rel=0.06)
    assert r[:, 0].std() == pytest.approx(0.035 * far, rel=0.06)
    assert r.mean(axis=0) == pytest.approx([far, near_1, near_0], abs=4e-3)
    half = readings(room, "turtlebot3:off:range_noise_share=0.5", [270.0])
    assert half.std() == pytest.approx(0.005, rel=0.06)


def test_range_error_grows_with_distance_by_band(room):
    r = readings(room, "turtlebot3:off:range_bias_share=1", [90.0, 270.0], scans=1)[0]
    # LDS-01 accuracy: 15 mm below 0.5 m, 5 % of the range above.
    assert r == pytest.approx([1.05 * (H - LIDAR[1]), 0.4 + 0.015], abs=1e-12)
    r = readings(room, "turtlebot3:off:range_bias_share=-0.5", [90.0, 270.0], scans=1)[0]
    assert r == pytest.approx([0.975 * (H - LIDAR[1]), 0.4 - 0.0075], abs=1e-12)


def test_dropouts_random_more_at_grazing_incidence_and_long_range(room):
    # 20 full scans: ~6,000 rays in range, the share within 0.02 of the setting.
    in_range = Simulator(room, start=POSE, profile="turtlebot3:off").lidar.scan(0.0) > 0.0
    sim = Simulator(room, start=POSE, profile="turtlebot3:off:dropout_share=0.3", seed=1)
    shares = [np.mean(sim.lidar.scan(0.0)[in_range] == 0.0) for _ in range(20)]
    assert np.mean(shares) == pytest.approx(0.3, abs=0.02)
    r = readings(room, "turtlebot3:off:dropout_grazing_share=1", [270.0, 350.0])
    grazing = (1.0 - 2.0 * math.cos(math.radians(80.0))) ** 2  # 80 deg incidence: 0.43
    assert np.mean(r[:, 0] == 0.0) == 0.0  # head-on: never
    assert np.mean(r[:, 1] == 0.0) == pytest.approx(grazing, abs=0.03)
    # Long range: (r / 3.5 m)^2 of the setting.
    r = readings(room, "turtlebot3:off:dropout_far_share=0.8", [90.0, 270.0])
    assert np.mean(r[:, 0] == 0.0) == pytest.approx(0.8 * (2.6 / 3.5) ** 2, abs=0.03)
    assert np.mean(r[:, 1] == 0.0) == pytest.approx(0.8 * (0.4 / 3.5) ** 2, abs=0.01)


def unicycle(pose, v, w, t):
    x, y, theta = pose
    heading = theta + w * t
    return (x + v / w * (math.sin(heading) - math.sin(theta)),
            y - v / w * (math.cos(heading) - math.cos(theta)), heading)


@pytest.mark.parametrize("dt", [0.05, 0.01])
def test_skewed_scan_equals_each_ray_cast_from_the_pose_at_its_time(room, dt):
    start, v, w = (1.5, 1.5, 0.0), 0.2, 1.5
    scans = {}
    for skew in (1, 0):
        sim = Simulator(room, start=start, dt=dt, profile=f"turtlebot3:off:scan_skew={skew}")
        for _ in range(round(0.4 / dt)):  # constant (v, w): a scan at 0.2 s and one at 0.4 s
            z, _, _ = sim.step(v, w)
        assert sim.scan_time == pytest.approx(0.4) and sim.collisions == 0
        scans[skew] = z
    expected = []
    for i in range(360):
        angle = math.radians(i)
        t = 0.4 - 0.2 * angle / (2 * math.pi)  # clockwise: ray 0 last, at the stamp
        x, y, theta = unicycle(start, v, w, t)
        expected.append(distance(x + LIDAR_OFFSET_X * math.cos(theta),
                                 y + LIDAR_OFFSET_X * math.sin(theta), theta + angle))
    expected = np.array(expected)
    valid = (expected > 0.12) & (expected < 3.5)
    error = np.abs(scans[1] - expected)[valid]
    assert np.percentile(error, 98) < 5e-4 and np.median(error) < 1e-4
    assert np.percentile(np.abs(scans[0] - expected)[valid], 50) > 0.02  # the skew is real


def test_lds02_rays_change_from_scan_to_scan_with_nan_for_no_return(room):
    sim = Simulator(room, start=POSE, profile="turtlebot3_lds02:off:dropout_share=0.05", seed=2)
    assert get_profile("turtlebot3_lds02").no_return != get_profile("turtlebot3_lds02").no_return
    counts, minima = set(), set()
    for scan in range(20):
        z = sim.lidar.scan(0.0)
        angle_min, increment, rays = sim.lidar.geometry
        assert len(z) == rays and 420 < rays < 500
        assert 0.0 <= angle_min < 0.05 and increment == pytest.approx(math.radians(0.78), rel=0.05)
        counts.add(rays)
        minima.add(angle_min)
        assert np.isnan(z).any() and not (z == 0.0).any()
        valid = ~np.isnan(z)
        assert ((z[valid] >= 0.16) & (z[valid] <= 8.0)).all()
        if scan >= 3:
            continue
        # Each ray holds a sample measured within its angular bin [a_i, a_i + increment).
        bins = angle_min + increment * (np.arange(rays)[:, None] + np.linspace(0, 1, 41))
        seen = np.vectorize(lambda t: distance(*LIDAR, t))(bins)
        lo, hi = seen.min(axis=1), seen.max(axis=1)
        smooth = valid & (hi - lo < 0.05)  # not at a corner
        assert ((z[smooth] >= lo[smooth] - 1e-5) & (z[smooth] <= hi[smooth] + 1e-5)).all()
    assert len(counts) > 3 and len(minima) > 3
    z, _, _ = sim.step(0.0, 0.0)
    assert sim.scan_geometry[2:] == (len(z), 0.0, 100.0)  # the driver's range_min, range_max


def test_compiled_scan_equals_its_numpy_twin(room):
    sim = Simulator("maze_deadends", profile="turtlebot3", seed=4)
    for k in range(13):
        sim.step(0.2, 2.0 * math.sin(k))
    lidar = sim.lidar
    rng = np.random.default_rng(0)
    gauss, uniform = rng.standard_normal(360), rng.random(360, dtype=np.float32)
    args = (lidar.walls, lidar.circles, lidar.history, lidar._head, lidar.angles, lidar._cos,
            lidar._sin, lidar.bands, lidar.params, gauss, uniform)
    fast, slow = np.empty(360), np.empty(360)
    scan_rays_kernel(*args, fast)
    scan_rays_numpy(*args, slow)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
    assert (fast == 0.0).sum() > 0 and (fast > 0.0).sum() > 100
    origins = rng.uniform(0.2, 3.0, (2, 500))
    headings = rng.uniform(-math.pi, math.pi, 500)
    out = [(np.empty(500), np.empty(500)) for _ in range(2)]
    for cast, (ranges, cos) in zip((cast_rays_kernel, cast_rays_numpy), out):
        cast(sim.world.segments, *origins, np.cos(headings), np.sin(headings), ranges, cos)
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=1e-12)
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=0, atol=1e-12)
    # The whole scanner without numba gives the same scans.
    profile = get_profile("turtlebot3_lds02")
    scanners = [RealLidar(room.segments, profile, effects_of(profile, 0),
                          np.random.default_rng(9), use_numba=numba) for numba in (True, False)]
    for scanner in scanners:
        scanner.reset(0.0, *POSE)
    a, b = (s.scan(0.0) for s in scanners)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
