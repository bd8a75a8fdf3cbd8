"""CARMEN logs (`.clf`, `.log`): the field's benchmark format, read into scans and odometry.

    log = read_carmen_log("intel.clf")
    for scan in log.scans:          # LaserScan-like: ranges, angle_min, angle_increment, ...
        mapper.update(scan, scan.odometry, scan.stamp)
    log.odometry                    # the ODOM lines: (stamp, pose, velocities)
    log.problems                    # "line 812: FLASER has 179 fields, expected 188" ...

What is read (the CARMEN readlog conventions, written down here; one line per message):
- `FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_stamp host logger_stamp`: a front
  laser scan; the first pose is the laser's, the second the robot's odometry. The geometry is
  not in the line: start at -90 deg, 1 deg apart for 180/181 readings, 0.5 deg for 360/361,
  0.25 deg for 400/401, else 180 deg spread over the readings; range_max 80 m (a SICK LMS: it
  reports no return as 81.83 / 81.91 m, beyond that).
- `ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode n r1..rn
  m e1..em laser_x laser_y laser_theta x y theta tv rv forward_safety side_safety turn_axis
  ipc_stamp host logger_stamp`: a scan with its own geometry (a reading at max_range is no
  return: range_max is set 1 mm below it).
- `ODOM x y theta tv rv accel ipc_stamp host logger_stamp`: an odometry pose.
- `PARAM robot_frontlaser_offset VALUE`: the laser's place ahead of the robot centre (m),
  for the scans after it (0 without).
Other messages (RLASER, RAWLASER, TRUEPOS, SYNC, NMEA ...) and `#` comments are skipped and
counted. Stamps are the ipc stamps (the relations of Kuemmerle et al. 2009 use them), kept as
they are: a log's scans may be stamped at or before the one before (the Intel log: 265 of its
first 5,505), and what to do with them is the reader's user's business. A malformed line
(too few fields, a number that is not one, NaN, a reading count that does not match) is left
out with a message naming its line number in `problems` (or, with strict=True, raises
CarmenLogError with that message); the rest of the log is read.
"""
from __future__ import annotations

import gzip
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

FLASER_START_ANGLE = -math.pi / 2.0
FLASER_RANGE_MAX_M = 80.0  # a SICK LMS's reach; its "no return" codes (81.83, 81.91 m) lie beyond
MAX_READINGS = 100_000  # more than any 2D LiDAR gives: a malformed count
NO_RETURN_MARGIN_M = 0.001  # ROBOTLASER1: readings this close to the maximum range are none


class CarmenLogError(ValueError):
    """A malformed line (strict reading) or a log that cannot be opened."""


@dataclass(frozen=True)
class CarmenScan:
    """One laser scan: the fields of a sensor_msgs/LaserScan the mapper reads, and its poses.

    odometry: the robot's odometry pose (x, y, theta) at the scan; laser_pose: the laser's pose
    as the line gives it (FLASER's first triple; the same frame as odometry);
    lidar_offset_x_m: the laser ahead of the robot centre (PARAM robot_frontlaser_offset).
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    stamp: float
    odometry: tuple[float, float, float]
    laser_pose: tuple[float, float, float]
    lidar_offset_x_m: float
    line: int
    kind: str  # "FLASER" or "ROBOTLASER1"
    scan_time: float = 0.0  # the log does not say how long a sweep took: taken at once


@dataclass(frozen=True)
class CarmenOdometry:
    """One ODOM line: the odometry pose, the velocities (m/s, rad/s) and the ipc stamp."""

    pose: tuple[float, float, float]
    velocity: tuple[float, float]
    stamp: float
    line: int


@dataclass
class CarmenLog:
    """Everything read from a log, in file order."""

    scans: list[CarmenScan] = field(default_factory=list)
    odometry: list[CarmenOdometry] = field(default_factory=list)
    params: dict[str, str] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)  # one message per left-out line
    skipped: Counter = field(default_factory=Counter)  # message name -> lines not read

    @property
    def duration_s(self) -> float:
        """Span of the scans' stamps (s), 0 for fewer than two."""
        if len(self.scans) < 2:
            return 0.0
        stamps = [scan.stamp for scan in self.scans]
        return max(stamps) - min(stamps)

    def stamps_not_increasing(self) -> int:
        """How many scans are stamped at or before the scan before them (in file order)."""
        stamps = np.array([scan.stamp for scan in self.scans])
        return int(np.count_nonzero(np.diff(stamps) <= 0.0)) if len(stamps) > 1 else 0


def flaser_geometry(readings: int) -> tuple[float, float]:
    """(angle_min, angle_increment) of a FLASER line with `readings` ranges (CARMEN's guess)."""
    if readings in (180, 181):
        return FLASER_START_ANGLE, math.pi / 180.0
    if readings in (360, 361):
        return FLASER_START_ANGLE, math.pi / 360.0
    if readings in (400, 401):
        return FLASER_START_ANGLE, math.pi / 720.0
    return FLASER_START_ANGLE, math.pi / max(readings - 1, 1)


class _LineError(ValueError):
    pass


def _numbers(fields: list[str], start: int, count: int, what: str) -> list[float]:
    if start + count > len(fields):
        raise _LineError(f"has {len(fields)} fields, too few for its {what}")
    values = []
    for text in fields[start:start + count]:
        try:
            value = float(text)
        except ValueError:
            raise _LineError(f"{what}: {text!r} is not a number") from None
        if not math.isfinite(value):
            raise _LineError(f"{what}: {text!r} is not finite")
        values.append(value)
    return values


def _count(fields: list[str], index: int, what: str) -> int:
    if index >= len(fields):
        raise _LineError(f"has {len(fields)} fields, too few for its {what}")
    try:
        value = int(fields[index])
    except ValueError:
        raise _LineError(f"{what} {fields[index]!r} is not a whole number") from None
    if not 0 <= value <= MAX_READINGS:
        raise _LineError(f"{what} {value} is not in 0..{MAX_READINGS}")
    return value


def _stamp(fields: list[str], index: int, expected: int, name: str) -> float:
    """The ipc stamp at fields[index]; the line has `expected` fields (host, logger stamp).

    Older logs end with the host: one field fewer is accepted.
    """
    if len(fields) not in (expected - 1, expected):
        raise _LineError(f"has {len(fields)} fields, expected {expected} for its readings")
    return _numbers(fields, index, 1, f"{name} stamp")[0]


def _flaser(fields: list[str], line: int, offset: float) -> CarmenScan:
    n = _count(fields, 1, "reading count")
    ranges = _numbers(fields, 2, n, "ranges")
    poses = _numbers(fields, 2 + n, 6, "poses")
    stamp = _stamp(fields, 8 + n, 11 + n, "FLASER")
    angle_min, increment = flaser_geometry(n)
    return CarmenScan(np.array(ranges), angle_min, increment, 0.0, FLASER_RANGE_MAX_M, stamp,
                      tuple(poses[3:6]), tuple(poses[0:3]), offset, line, "FLASER")


def _robotlaser(fields: list[str], line: int, offset: float) -> CarmenScan:
    start, fov, increment, range_max, _accuracy = _numbers(fields, 2, 5, "laser geometry")
    if increment == 0.0 or range_max <= 0.0:
        raise _LineError(f"angular resolution {increment} or maximum range {range_max} is "
                         "not usable")
    n = _count(fields, 8, "reading count")
    ranges = _numbers(fields, 9, n, "ranges")
    m = _count(fields, 9 + n, "remission count")
    _numbers(fields, 10 + n, m, "remissions")
    rest = 10 + n + m
    poses = _numbers(fields, rest, 6, "poses")
    _numbers(fields, rest + 6, 5, "velocities and safety distances")
    stamp = _stamp(fields, rest + 11, rest + 14, "ROBOTLASER1")
    # A reading at the maximum range is the laser's "no return" (CARMEN, SICK): the
    # LaserScan's range_max is set just below it, so that reading is left out as no return.
    return CarmenScan(np.array(ranges), start, increment, 0.0, range_max - NO_RETURN_MARGIN_M,
                      stamp, tuple(poses[3:6]), tuple(poses[0:3]), offset, line, "ROBOTLASER1")


def _odom(fields: list[str], line: int) -> CarmenOdometry:
    x, y, theta, tv, rv, _accel = _numbers(fields, 1, 6, "pose and velocities")
    stamp = _stamp(fields, 7, 10, "ODOM")
    return CarmenOdometry((x, y, theta), (tv, rv), stamp, line)


def parse_carmen_lines(lines: Iterable[str], strict: bool = False) -> CarmenLog:
    """A CarmenLog of the lines of a log (see the module docstring)."""
    log = CarmenLog()
    offset = 0.0
    for number, text in enumerate(lines, start=1):
        fields = text.split()
        if not fields or fields[0].startswith("#"):
            continue
        name = fields[0]
        try:
            if name == "FLASER":
                log.scans.append(_flaser(fields, number, offset))
            elif name == "ROBOTLASER1":
                log.scans.append(_robotlaser(fields, number, offset))
            elif name == "ODOM":
                log.odometry.append(_odom(fields, number))
            elif name == "PARAM":
                if len(fields) < 3:
                    raise _LineError("PARAM needs a name and a value")
                log.params[fields[1]] = fields[2]
                if fields[1] == "robot_frontlaser_offset":
                    offset = _numbers(fields, 2, 1, "robot_frontlaser_offset")[0]
            else:
                log.skipped[name] += 1
        except _LineError as exc:
            message = f"line {number}: {name} {exc}"
            if strict:
                raise CarmenLogError(message) from None
            log.problems.append(message)
    return log


def read_carmen_log(path: str | Path, strict: bool = False) -> CarmenLog:
    """Read a CARMEN log file (gzip-compressed if it ends in .gz, as logs are often shipped).

    CarmenLogError if it cannot be opened or is not text.
    """
    opener = gzip.open if str(path).endswith(".gz") else open
    try:
        with opener(path, "rt", encoding="utf-8", errors="strict") as stream:
            return parse_carmen_lines(stream, strict)
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise CarmenLogError(f"cannot read CARMEN log {path}: {exc}") from None


__all__ = ["CarmenLog", "CarmenLogError", "CarmenOdometry", "CarmenScan", "FLASER_RANGE_MAX_M",
           "flaser_geometry", "parse_carmen_lines", "read_carmen_log"]
