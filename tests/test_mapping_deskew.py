"""The Mapper de-skews a real LiDAR's scans with the odometry (SLAM under the reality gap).

A Burger's LiDAR measures its rays clockwise over the 0.2 s before the scan's stamp: while the
robot turns, the pose at the stamp explains the early rays badly. Synthetic scans of a known
room, each ray cast from the pose at its own time, show the Mapper putting the walls where they
are with `deskew` and beside them without; the LDS-02's changing ray count and angles; bad
scan times and stamps. Small and fast: a few dozen scans each.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.sensors.lidar_models import revolution_ages
from amr_common.sensors.scan_deskew import MotionHistory
from amr_common.world.map_raster import OCCUPIED
from amr_mapping.mapper import Mapper
from amr_mapping.scan_points import Scan

ROOM = (-1.0, 1.5, -0.8, 1.2)  # x_min, x_max, y_min, y_max: a rectangle (no symmetry)
OFFSET = -0.032  # the Burger's LiDAR, behind the centre
REVOLUTION = 0.2
PERIOD = 0.2  # 5 Hz: each revolution starts at the last one's stamp


def room_ranges(x: float, y: float, theta: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Ranges of rays from the LiDAR of a robot at (x, y, theta[i]) in ROOM, at angles[i]."""
    lx, ly = x + OFFSET * np.cos(theta), y + OFFSET * np.sin(theta)
    c, s = np.cos(theta + angles), np.sin(theta + angles)
    x0, x1, y0, y1 = ROOM
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (x1 - lx) / c, (x0 - lx) / c)
        ty = np.where(s > 0, (y1 - ly) / s, (y0 - ly) / s)
    return np.minimum(np.abs(tx), np.abs(ty))


def turning_scans(w: float, v: float = 0.0, scans: int = 15, rays=None, seed: int = 0):
    """(scan, odometry pose, stamp, true pose) of a robot at rest for one scan, then turning.

    Each ray is cast from the pose at its own time (revolution_ages before the stamp); `rays`
    (LDS-02): per scan a random ray count and angle_min, some rays NaN (no return).
    """
    rng = np.random.default_rng(seed)

    def pose_at(t):  # at rest until PERIOD, then a constant twist (an arc)
        moving = np.maximum(np.asarray(t) - PERIOD, 0.0)
        theta = 0.3 + w * moving
        if abs(w) < 1e-12:
            return 0.2 + v * moving * math.cos(0.3), 0.1 + v * moving * math.sin(0.3), theta
        return (0.2 + v / w * (np.sin(theta) - math.sin(0.3)),
                0.1 - v / w * (np.cos(theta) - math.cos(0.3)), theta)

    out = []
    for k in range(scans):
        stamp = PERIOD * (k + 1)
        if rays is None:
            angle_min, increment, n = 0.0, 2 * math.pi / 360, 360
        else:
            n = int(rng.integers(*rays))
            increment = 2 * math.pi / 460
            angle_min = float(rng.uniform(0.0, 2 * math.pi - n * increment))
        angles = angle_min + increment * np.arange(n)
        x, y, theta = pose_at(stamp - revolution_ages(angles, REVOLUTION))
        # The LiDAR moves a little as the robot turns: cast from each ray's own position.
        ranges = np.array([room_ranges(float(xi), float(yi), np.array([ti]), np.array([ai]))[0]
                           for xi, yi, ti, ai in zip(np.broadcast_to(x, n),
                                                     np.broadcast_to(y, n), theta, angles)])
        if rays is not None:
            ranges[rng.random(n) < 0.05] = math.nan
        truth = tuple(float(np.asarray(c).reshape(-1)[0]) for c in pose_at(stamp))
        out.append((Scan(ranges, angle_min, increment, 0.12, 8.0 if rays else 3.5,
                         scan_time=REVOLUTION), truth, stamp, truth))
    return out


def occupied_wall_error(mapper: Mapper) -> float:
    """The 90th percentile distance (m) of the map's occupied cells from ROOM's walls.

    The map frame is the odometry frame, here the world's (the odometry is exact).
    """
    raster = mapper.occupancy_raster()
    rows, cols = np.nonzero(raster.values == OCCUPIED)
    x = raster.origin[0] + (cols + 0.5) * raster.resolution
    y = raster.origin[1] + (rows + 0.5) * raster.resolution
    x0, x1, y0, y1 = ROOM
    distance = np.minimum.reduce([np.abs(x - x0), np.abs(x - x1), np.abs(y - y0),
                                  np.abs(y - y1)])
    return float(np.percentile(distance, 90))


def mapped(scans, deskew: bool) -> tuple[Mapper, float]:
    """The Mapper after the scans, and its worst heading error (rad) against the truth."""
    mapper = Mapper({"lidar_offset_x_m": OFFSET, "deskew": deskew, "loop_closure": False,
                     "keyframe_angle_rad": 0.05})
    worst = 0.0
    for scan, odom, stamp, truth in scans:
        estimate = mapper.update(scan, odom, stamp)
        assert not estimate.status.startswith("rejected")
        worst = max(worst, abs(math.remainder(estimate.pose[2] - truth[2], 2 * math.pi)))
    return mapper, worst


def test_a_turning_robots_walls_land_where_they_are_with_deskew_and_beside_them_without():
    # Turning at 1.5 rad/s: a scan's first and last rays 0.3 rad apart.
    scans = turning_scans(w=1.5, scans=12)
    with_deskew, heading_on = mapped(scans, deskew=True)
    without, heading_off = mapped(scans, deskew=False)
    assert heading_on < 0.005  # the odometry is exact: the matcher keeps it
    assert occupied_wall_error(with_deskew) <= 0.02  # one cell
    # Without (seen: 0.08 rad, 15 cm): the scans are smeared and turned; matching them pulls
    # the pose off the odometry and the walls off their place.
    assert heading_off > 0.03
    assert occupied_wall_error(without) > 0.05


def test_lds02_scans_with_a_changing_ray_count_and_angles_are_deskewed_too():
    scans = turning_scans(w=-1.2, v=0.15, scans=12, rays=(430, 460), seed=3)
    counts = {len(scan.ranges) for scan, *_ in scans}
    assert len(counts) > 5  # the ray count changed from scan to scan
    mapper, heading = mapped(scans, deskew=True)
    assert heading < 0.005
    assert occupied_wall_error(mapper) <= 0.02
    x, y, _ = mapper.pose
    truth = scans[-1][3]
    assert math.hypot(x - truth[0], y - truth[1]) < 0.01
    assert mapped(scans, deskew=False)[1] > 0.03  # seen: 0.15 rad off without


@pytest.mark.parametrize("scan_time", [math.nan, math.inf, -0.2, 5.0, "fast", None])
def test_a_scan_time_that_is_not_a_revolution_time_maps_the_scan_as_measured(scan_time):
    scans = turning_scans(w=1.0, scans=4)
    mapper = Mapper({"lidar_offset_x_m": OFFSET})
    for k, (scan, odom, stamp, _) in enumerate(scans):
        bad = Scan(scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                   scan.range_max, scan_time=scan_time) if k == 2 else scan
        estimate = mapper.update(bad, odom, stamp)
        assert not estimate.status.startswith("rejected")
        assert all(math.isfinite(v) for v in estimate.pose)
    assert mapper.statistics()["bad_scan_time"] == 1
    assert np.isfinite(np.asarray(mapper.keyframe_poses())).all()


def test_out_of_order_and_repeated_stamps_are_mapped_and_leave_the_pose_sane():
    """A real log's stamps jitter: a scan stamped before (or at) the last one is still mapped.

    Its motion is the odometry's since the scan before it, taken over the typical interval
    between scans; a stamp that is not a number is refused.
    """
    scans = turning_scans(w=1.5, scans=7)
    mapper = Mapper({"lidar_offset_x_m": OFFSET})
    for scan, odom, stamp, _ in scans[:4]:
        mapper.update(scan, odom, stamp)
    scan, odom, stamp, truth = scans[4]
    for late in (stamp - 0.5, scans[3][2]):  # before, equal
        estimate = mapper.update(scan, odom, late)
        assert estimate.status == "matched"
        assert abs(math.remainder(estimate.pose[2] - truth[2], 2 * math.pi)) < 0.02
    assert mapper.update(scan, odom, math.nan).status.startswith("rejected")
    for scan, odom, stamp, truth in scans[5:]:
        estimate = mapper.update(scan, odom, stamp)
        assert estimate.status == "matched"
        assert abs(math.remainder(estimate.pose[2] - truth[2], 2 * math.pi)) < 0.005
    stats = mapper.statistics()
    assert stats["out_of_order"] == 2 and stats["rejected"] == {"non_finite": 1}


def test_an_odometry_step_is_kept_as_an_arc_and_a_bad_one_restarts_at_rest():
    history = MotionHistory()
    # 0.2 s of 0.2 m/s and 1.5 rad/s: the pose halfway lies on the arc.
    w, v, dt = 1.5, 0.2, 0.2
    end = (v / w * math.sin(w * dt), v / w * (1 - math.cos(w * dt)), w * dt)
    history.add_motion(end, dt)
    x, y, theta = history.relative_poses(np.array([0.1, 0.2]))
    half = (v / w * math.sin(w * 0.1), v / w * (1 - math.cos(w * 0.1)), w * 0.1)
    # The pose 0.1 s ago (halfway), in the frame now: the end's inverse composed with half.
    c, s = math.cos(end[2]), math.sin(end[2])
    dx, dy = half[0] - end[0], half[1] - end[1]
    assert x[0] == pytest.approx(c * dx + s * dy, abs=2e-4)
    assert y[0] == pytest.approx(-s * dx + c * dy, abs=2e-4)
    assert theta[0] == pytest.approx(half[2] - end[2], abs=1e-9)
    assert theta[1] == pytest.approx(-end[2], abs=1e-9)
    history.add_motion((math.nan, 0.0, 0.0), dt)
    assert np.allclose(history.relative_poses(np.array([0.1])), 0.0)
