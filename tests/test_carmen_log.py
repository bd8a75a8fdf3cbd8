"""The CARMEN log reader: the field's benchmark format into scans and odometry.

On the shipped slice of the Intel log (tests/data/intel-1000-1399.clf.gz: 400 FLASER scans,
24 of them stamped at or before the scan before) and on hand-written lines: the geometry
CARMEN gives each message, stamps kept as they are, malformed lines left out with their line
number, or refused with strict=True.
"""
from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from amr_tools.carmen_log import (
    CarmenLogError,
    flaser_geometry,
    parse_carmen_lines,
    read_carmen_log,
)

DATA = Path(__file__).resolve().parent / "data"
INTEL = DATA / "intel-1000-1399.clf.gz"


def flaser(ranges, pose=(1.0, 2.0, 0.5), stamp=100.25, odom=None) -> str:
    odom = pose if odom is None else odom
    values = " ".join(f"{r:.2f}" for r in ranges)
    return (f"FLASER {len(ranges)} {values} {pose[0]} {pose[1]} {pose[2]} {odom[0]} {odom[1]} "
            f"{odom[2]} {stamp} nohost {stamp - 0.01}")


def test_the_intel_slice_reads_as_400_scans_with_their_stamps_as_logged():
    log = read_carmen_log(INTEL)
    assert len(log.scans) == 400 and not log.problems and not log.odometry
    assert log.params == {"robot_frontlaser_offset": "0.0"}
    first = log.scans[0]
    # 180 readings over 180 degrees from the robot's right, 1 degree apart (a SICK LMS)
    assert first.ranges.shape == (180,)
    assert first.angle_min == pytest.approx(-math.pi / 2)
    assert first.angle_increment == pytest.approx(math.radians(1.0))
    assert first.range_max == 80.0 and first.kind == "FLASER"
    assert first.lidar_offset_x_m == 0.0 and first.line == 6  # after 4 comments and PARAM
    # The log's disorder is kept: 24 scans stamped at or before the one before.
    stamps = np.array([scan.stamp for scan in log.scans])
    assert log.stamps_not_increasing() == 24 == np.count_nonzero(np.diff(stamps) <= 0)
    assert log.duration_s == pytest.approx(80.4, abs=0.05)
    # ... and the odometry poses follow each other smoothly in file order (no step > 0.25 m).
    odometry = np.array([scan.odometry for scan in log.scans])
    assert np.hypot(*np.diff(odometry[:, :2], axis=0).T).max() < 0.25


@pytest.mark.parametrize("readings,increment", [(180, 1.0), (181, 1.0), (360, 0.5), (361, 0.5),
                                                 (401, 0.25), (90, 180.0 / 89)])
def test_flaser_geometry_is_carmens(readings, increment):
    angle_min, step = flaser_geometry(readings)
    assert angle_min == pytest.approx(-math.pi / 2)
    assert step == pytest.approx(math.radians(increment))


def test_robotlaser_odom_and_param_lines():
    lines = [
        "# a comment",
        "PARAM robot_frontlaser_offset 0.12",
        "ODOM 1.5 -2.0 0.25 0.3 0.1 0.0 50.5 host 50.49",
        "ROBOTLASER1 0 -1.5708 3.1416 0.0175 81.9 0.01 0 3 1.0 2.0 81.9 0 "
        "1.62 -2.0 0.25 1.5 -2.0 0.25 0.3 0.1 0.5 0.3 1000.0 50.6 host 50.59",
        flaser([1.0, 1.1], stamp=50.7),
        "TRUEPOS 1 2 3 4 5 6 50.8 host 50.8",
    ]
    log = parse_carmen_lines(lines)
    assert not log.problems and log.skipped == {"TRUEPOS": 1}
    (odom,) = log.odometry
    assert odom.pose == (1.5, -2.0, 0.25) and odom.velocity == (0.3, 0.1) and odom.stamp == 50.5
    robot, front = log.scans
    assert robot.kind == "ROBOTLASER1" and robot.ranges.tolist() == [1.0, 2.0, 81.9]
    assert (robot.angle_min, robot.angle_increment) == (-1.5708, 0.0175)
    # 81.9 m, the maximum range, is the laser's "no return": just beyond range_max
    assert 81.8 < robot.range_max < 81.9
    assert robot.odometry == (1.5, -2.0, 0.25) and robot.laser_pose == (1.62, -2.0, 0.25)
    assert robot.stamp == 50.6 and robot.lidar_offset_x_m == 0.12 and robot.line == 4
    assert front.kind == "FLASER" and front.odometry == (1.0, 2.0, 0.5)


@pytest.mark.parametrize("bad,message", [
    ("FLASER 3 1.0 1.0 1.0 0 0 0", "has 8 fields, too few for its poses"),
    ("FLASER 3 1.0 1.0 x 0 0 0 0 0 0 5.0 host 4.9", "ranges: 'x' is not a number"),
    ("FLASER 3 1.0 1.0 1.0 0 0 nan 0 0 0 5.0 host 4.9", "poses: 'nan' is not finite"),
    ("FLASER three 1.0", "reading count 'three' is not a whole number"),
    ("FLASER -4 1.0", "reading count -4 is not in 0..100000"),
    ("FLASER 3 1.0 1.0 1.0 1.0 0 0 0 0 0 0 5.0 host 4.9", "expected 14 for its readings"),
    ("ODOM 1 2 3 4 5 6 seven host 7.0", "ODOM stamp: 'seven' is not a number"),
    ("ROBOTLASER1 0 -1.57 3.14 0.0 81.9 0.01 0 1 1.0 0 0 0 0 0 0 0 0 0 0 0 0 1.0 h 1.0",
     "angular resolution 0.0"),
    ("PARAM robot_frontlaser_offset", "PARAM needs a name and a value"),
    ("PARAM robot_frontlaser_offset far", "robot_frontlaser_offset: 'far' is not a number"),
])
def test_a_malformed_line_is_left_out_with_its_number(bad, message):
    log = parse_carmen_lines([flaser([1.0] * 3, stamp=1.0), bad, flaser([2.0] * 3, stamp=2.0)])
    assert [scan.stamp for scan in log.scans] == [1.0, 2.0]  # the rest is read
    assert len(log.problems) == 1
    assert log.problems[0].startswith("line 2: ") and message in log.problems[0], log.problems
    with pytest.raises(CarmenLogError, match="line 2: .*" + message.split(":")[0]):
        parse_carmen_lines([flaser([1.0] * 3), bad], strict=True)


def test_out_of_order_and_repeated_stamps_are_kept_as_logged():
    stamps = [10.0, 10.2, 10.1, 10.1, 10.4]
    log = parse_carmen_lines([flaser([1.0] * 4, stamp=t) for t in stamps])
    assert [scan.stamp for scan in log.scans] == stamps
    assert log.stamps_not_increasing() == 2


def test_a_file_that_is_not_a_log_is_refused_in_one_line(tmp_path):
    with pytest.raises(CarmenLogError, match="cannot read CARMEN log .*missing.clf"):
        read_carmen_log(tmp_path / "missing.clf")
    binary = tmp_path / "binary.clf"
    binary.write_bytes(b"\xff\xfe\x00FLASER")
    with pytest.raises(CarmenLogError, match="cannot read CARMEN log"):
        read_carmen_log(binary)
    broken = tmp_path / "broken.clf.gz"
    broken.write_bytes(gzip.compress(flaser([1.0] * 3).encode())[:20])
    with pytest.raises(CarmenLogError, match="cannot read CARMEN log"):
        read_carmen_log(broken)
    plain = tmp_path / "plain.log"
    plain.write_text(flaser([1.0] * 3) + "\n")
    assert len(read_carmen_log(plain).scans) == 1
