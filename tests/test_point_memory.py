"""The wall follower's scan de-skew and point memory (amr_control.point_memory_kernels).

De-skew: a scan whose rays were measured over a revolution while the robot moved (clockwise,
stamped at the end, as the LDS-01/02 drivers do) gives the walls where they are at the stamp.
Memory: one point per odometry-frame cell, the newest; forgotten after memory_time or beyond
memory_range; the compiled kernels equal their plain-Python twins.
"""
import math

import numpy as np
import pytest

from amr_common.robot import unicycle_step
from amr_control import point_memory_kernels as memory_kernels
from amr_control.scan_sectors import LocalPointCloud, PerceptionSpec, ScanGeometry, ScanTiming
from tests.scan_helpers import LDS01_360, cast

SECTORS = {"front": 0.0, "left": 0.5 * math.pi, "right": -0.5 * math.pi, "back": math.pi}
RAYS_360 = ScanGeometry(0.0, 2.0 * math.pi / 360, 0.12, 3.5)
REVOLUTION = 0.2


def make_cloud(timing=None):
    spec = PerceptionSpec(-1.0, SECTORS, 0.1745, {"front": 25.0}, path_half_width_m=0.135,
                          side_window_m=0.03, side_open_m=0.32, fit_half_length_m=0.15)
    return LocalPointCloud(0.6, 0.3, 0.0, spec, timing)


def skewed_scan(walls, v, w):
    """LDS-01 ranges of a robot at (0, 0, 0) at the stamp that drove (v, w) during the scan.

    Ray a (counter-clockwise) was measured REVOLUTION * a / (2 pi) s before the stamp, from
    the pose the robot had then.
    """
    ranges = np.empty(360)
    for i in range(360):
        age = REVOLUTION * i / 360
        pose = unicycle_step(0.0, 0.0, 0.0, v, w, -age)
        ranges[i] = cast(walls, LDS01_360, pose)[i]
    return ranges


@pytest.mark.parametrize("v, w, ahead", [(0.2, 0.0, (-0.3, -0.01)), (0.0, 1.5, (-0.6, 0.6)),
                                         (0.15, -1.0, (-0.3, -0.01))])
def test_a_skewed_scan_is_deskewed_to_the_walls_at_the_stamp(v, w, ahead):
    # A wall on the right, and one ahead (when driving straight, on the right half only: the
    # rays right of straight ahead are the oldest of the revolution, measured 0.2 s before the
    # stamp; turning left, the scanner never looked right-ahead: the whole width).
    walls = [[-3.0, -0.2, 3.0, -0.2], [0.5, ahead[0], 0.5, ahead[1]]]
    ranges = skewed_scan(walls, v, w)
    dt = 0.05
    fixed = make_cloud(ScanTiming(revolution_s=REVOLUTION))
    _, p = fixed.step(v * dt, w * dt, dt, ranges, RAYS_360)
    # Exact but for the chord of a turning step taken as its arc (second order: < 0.1 mm).
    assert p.fit.distance_m == pytest.approx(0.2, abs=1e-4)
    assert p.fit.angle_rad == pytest.approx(0.0, abs=1e-4)
    assert p.path_m == pytest.approx(0.5, abs=1e-4)
    _, raw = make_cloud().step(v * dt, w * dt, dt, ranges, RAYS_360)   # taken at once
    off = max(abs(raw.fit.distance_m - 0.2), abs(raw.fit.angle_rad), abs(raw.path_m - 0.5))
    assert off > 0.005                        # what the skew would cost without de-skew


def test_the_memory_keeps_the_newest_point_per_cell_and_forgets_old_and_far_points():
    cell, memory_time, memory_range = 0.02, 3.0, 0.7
    pose = np.array([0.0, 0.0, 0.0, 0.0])
    first = np.array([[0.301, 0.305, 0.5, 0.9], [0.001, 0.003, 0.2, 0.0], [0.0] * 4])
    memory = memory_kernels.remember(np.zeros((3, 0)), first, 4, pose, memory_time,
                                     memory_range, cell)
    # 0.301 and 0.305 share a cell: one of them (the later in the scan); 0.9 m is too far.
    assert memory.shape[1] == 2
    pose = np.array([0.1, 0.0, 0.5 * math.pi, 2.0])        # drove 0.1 m, turned left, 2 s on
    second = np.array([[0.3], [-0.2], [0.0]])                # robot frame: world (0.3, 0.3)
    memory = memory_kernels.remember(memory, second, 1, pose, memory_time, memory_range, cell)
    seen = sorted(map(tuple, np.round(memory.T, 6).tolist()))
    assert seen == sorted([(0.305, 0.003, 0.0), (0.5, 0.2, 0.0), (0.3, 0.3, 2.0)])
    pose[3] = 3.5                                             # the first scan's points expire
    memory = memory_kernels.remember(memory, np.zeros((3, 0)), 0, pose, memory_time,
                                     memory_range, cell)
    assert memory.T.tolist() == [[pytest.approx(0.3), pytest.approx(0.3), 2.0]]
    # In the robot frame (heading north from (0.1, 0)) that point is 0.3 m ahead, 0.2 m right.
    nothing = np.zeros((3, 0))
    assert memory_kernels.memory_path_distance(memory, pose, 0.135, nothing, 0.03,
                                               math.inf) == math.inf
    assert memory_kernels.memory_path_distance(memory, pose, 0.25, nothing, 0.03,
                                               math.inf) == pytest.approx(0.3)
    # The current cloud shows that place (a point within 3 cm): the cloud's figure stands.
    shown = np.array([[0.32], [-0.21], [0.0]])
    assert memory_kernels.memory_path_distance(memory, pose, 0.25, shown, 0.03, 0.32) == 0.32


def test_memory_off_keeps_nothing():
    cloud = np.array([[0.3], [0.0], [0.0]])
    assert memory_kernels.remember(np.zeros((3, 0)), cloud, 1, np.zeros(4), 0.0, 0.7,
                                   0.02).shape == (3, 0)


@pytest.mark.parametrize("seed", range(3))
def test_compiled_kernels_equal_their_plain_python_twins(seed):
    rng = np.random.default_rng(seed)
    for _ in range(50):
        x, y, angle = rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-7, 7)
        speed, turn = rng.uniform(-0.2, 0.2), rng.uniform(-2.6, 2.6)
        assert memory_kernels.deskew_point(x, y, angle, 0.2, speed, turn) == pytest.approx(
            memory_kernels.deskew_point.py_func(x, y, angle, 0.2, speed, turn), abs=1e-12)
    memory = np.vstack([rng.uniform(-1, 1, (2, 200)), rng.uniform(0, 4, (1, 200))])
    cloud = np.vstack([rng.uniform(-1, 1, (2, 300)), np.zeros((1, 300))])
    pose = np.array([0.1, -0.2, 0.7, 4.5])
    compiled = memory_kernels.remember(memory, cloud, 250, pose, 3.0, 0.7, 0.02)
    plain = memory_kernels.remember.py_func(memory, cloud, 250, pose, 3.0, 0.7, 0.02)
    assert compiled.shape[1] > 50
    np.testing.assert_allclose(compiled, plain, atol=0, rtol=0)
    for half_width in (0.135, 0.5):
        assert memory_kernels.memory_path_distance(compiled, pose, half_width, cloud[:, :20],
                                                   0.03, math.inf) == (
            memory_kernels.memory_path_distance.py_func(plain, pose, half_width, cloud[:, :20],
                                                        0.03, math.inf))
