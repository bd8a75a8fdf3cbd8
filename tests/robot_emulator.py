"""A TurtleBot3 Burger emulated with Eclipse Cyclone DDS (not rclpy): an independent DDS peer.

Run as a separate process (it never imports rclpy, so it talks to our Fast DDS nodes only over
the wire, like the real robot's bringup):

    .venv/bin/python tests/robot_emulator.py --domain 42 --duration 10 --log emulator.jsonl

Options:
  --domain N            ROS_DOMAIN_ID to join (required; the ROS side must use the same).
  --duration S          stop after S seconds (default 0 = run until SIGINT/SIGTERM).
  --cmd-vel stamped|twist  /cmd_vel type: geometry_msgs/TwistStamped (Jazzy bringup, default)
                        or geometry_msgs/Twist (Humble bringup).
  --corridor-width W    the world is a straight corridor along +x, W metres wide, the robot
                        starting on its centre line at (0, 0) facing +x (default 0.8; 0 = no
                        side walls).
  --wall-ahead-at D     a wall across the corridor D metres ahead of the robot's centre at start
                        (default: none, the corridor is open ahead).
  --stop-scan-after S   stop publishing /scan S seconds after start; /odom continues.
  --scan-clock start|motion  what --stop-scan-after counts from: the emulator's start (default)
                        or the first command that moves the robot (robust to a slow start of
                        the graph under test on a loaded machine).
  --range-noise SIGMA   Gaussian range noise in metres (default 0; Gazebo's model uses 0.01).
  --seed N              seed of the range noise (default: random).
  --log FILE            JSON lines, one object per line, flushed at once (see below).

DDS side (as turtlebot3.md describes the real robot):
- publishes rt/odom, nav_msgs/Odometry, 20 Hz, reliable, volatile, KeepLast(10), frame odom ->
  base_footprint, pose integrated from the commands (a kinematic robot in the corridor), twist
  linear.x / angular.z = the velocities applied;
- publishes rt/scan, sensor_msgs/LaserScan, 5 Hz, best effort, KeepLast(5), frame base_scan
  (0.032 m behind the centre): 360 rays, angle_min 0, increment 1 deg, counter-clockwise, ranges
  ray-cast against the walls, 0.0 for no return (nothing within 0.12-3.5 m);
- subscribes rt/cmd_vel, reliable, KeepLast(10). Commands are applied like turtlebot3_node does:
  truncated to 0.01 steps and clamped to 0.22 m/s, 2.84 rad/s. The LAST COMMAND PERSISTS (the
  real robot has no command timeout). Non-finite commands are logged and ignored.
- The robot stops translating when it would come closer than 0.105 m (footprint radius) to a wall;
  each new contact is logged as a collision.
Cyclone is configured through CYCLONEDDS_URI (set here, before the participant is created):
interface lo only, multicast off, unicast peer 127.0.0.1, participant index auto (max 30).
Load: about 0.7 s CPU to start (imports), then about 1.5 % of one core.

Log lines (all have "event", "t" = seconds since the emulator started on the monotonic clock, the
clock of --duration and --stop-scan-after, and "time" = Unix time). Poses are [x, y, yaw] in the
odom frame, which is also the world frame (no drift). "start" is written once the DDS entities
exist; "cmd" records each command as received (raw values) with the pose at receipt and the
(v, w) applied from then on:
  {"event": "start", "domain": N, "cmd_vel": "stamped", "corridor_width": W,
   "wall_ahead_at": D|null, "stop_scan_after": S|null, "pid": P}
  {"event": "cmd", "linear": [x, y, z], "angular": [x, y, z], "stamp": [sec, nanosec]|null,
   "applied": [v, w], "pose": [x, y, yaw]}
  {"event": "collision", "pose": [x, y, yaw]}
  {"event": "scan_stopped"}
  {"event": "end", "odom_sent": n, "scan_sent": n, "cmds": n, "invalid_samples": n,
   "collisions": n, "cpu_s": s}          (invalid samples: writer gone / instance disposed)
"""
# No `from __future__ import annotations`: cyclonedds resolves IDL field annotations at run time.

import argparse
import json
import math
import os
import signal
import time
from dataclasses import dataclass, field
from typing import TextIO

import numpy as np
from cyclonedds.core import (
    InstanceState,
    Policy,
    Qos,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct, types
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

# --- robot facts (turtlebot3.md) -----------------------------------------------------------------
ODOM_PERIOD = 0.05
SCAN_PERIOD = 0.2
SCAN_RAYS = 360
RANGE_MIN, RANGE_MAX = 0.12, 3.5
SCANNER_OFFSET_X = -0.032  # base_scan behind base_link
FOOTPRINT_RADIUS = 0.105
MAX_LINEAR, MAX_ANGULAR = 0.22, 2.84
CORRIDOR_HALF_LENGTH = 100.0

CYCLONE_LOOPBACK_CONFIG = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
    '</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>'
    '<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30'
    '</MaxAutoParticipantIndex><Peers><Peer Address="127.0.0.1"/></Peers></Discovery>'
    '</Domain></CycloneDDS>')


# --- ROS message layouts as IDL (field order and types exactly as the .msg files) ----------------
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: types.int32
    nanosec: types.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: types.float64
    y: types.float64
    z: types.float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: types.float64
    y: types.float64
    z: types.float64
    w: types.float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: types.array[types.float64, 36]


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: types.float64
    y: types.float64
    z: types.float64


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: types.array[types.float64, 36]


@dataclass
class TwistStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TwistStamped_"):
    header: Header
    twist: Twist


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    header: Header
    angle_min: types.float32
    angle_max: types.float32
    angle_increment: types.float32
    time_increment: types.float32
    scan_time: types.float32
    range_min: types.float32
    range_max: types.float32
    ranges: types.sequence[types.float32]
    intensities: types.sequence[types.float32]


# --- the emulated world and robot (plain numpy) -------------------------------------------
def corridor_walls(width: float, wall_ahead_at: float | None) -> np.ndarray:
    """Wall segments (N x 4: x1, y1, x2, y2) of a corridor along x centred on y = 0."""
    walls = []
    if width > 0:
        half = width / 2.0
        walls += [(-CORRIDOR_HALF_LENGTH, half, CORRIDOR_HALF_LENGTH, half),
                  (-CORRIDOR_HALF_LENGTH, -half, CORRIDOR_HALF_LENGTH, -half)]
    if wall_ahead_at is not None:
        walls.append((wall_ahead_at, -CORRIDOR_HALF_LENGTH, wall_ahead_at, CORRIDOR_HALF_LENGTH))
    return np.array(walls, dtype=float).reshape(-1, 4)


def cast_rays(walls: np.ndarray, x: float, y: float, angles: np.ndarray) -> np.ndarray:
    """Distance from (x, y) along each world angle to the nearest wall; inf where none."""
    if len(walls) == 0:
        return np.full(angles.shape, np.inf)
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]  # rays x 1
    ex, ey = (walls[:, 2] - walls[:, 0])[None, :], (walls[:, 3] - walls[:, 1])[None, :]
    ox, oy = (walls[:, 0] - x)[None, :], (walls[:, 1] - y)[None, :]
    denominator = dx * ey - dy * ex  # 0 for rays parallel to a wall
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = (ox * ey - oy * ex) / denominator
        along_wall = (ox * dy - oy * dx) / denominator
    hit = (denominator != 0) & (distance > 0) & (along_wall >= 0) & (along_wall <= 1)
    return np.where(hit, distance, np.inf).min(axis=1)


def distance_to_walls(walls: np.ndarray, x: float, y: float) -> float:
    """Distance from (x, y) to the nearest wall segment."""
    if len(walls) == 0:
        return math.inf
    p1, p2 = walls[:, :2], walls[:, 2:]
    edge = p2 - p1
    s = np.clip(((np.array([x, y]) - p1) * edge).sum(axis=1) / (edge * edge).sum(axis=1), 0, 1)
    closest = p1 + s[:, None] * edge
    return float(np.hypot(closest[:, 0] - x, closest[:, 1] - y).min())


def apply_like_turtlebot3(v: float, w: float) -> tuple[float, float]:
    """turtlebot3_node sends int(v*100), int(w*100); the board clamps to the robot's limits."""
    v = max(-MAX_LINEAR, min(MAX_LINEAR, int(v * 100) / 100.0))
    w = max(-MAX_ANGULAR, min(MAX_ANGULAR, int(w * 100) / 100.0))
    return v, w


@dataclass
class Robot:
    walls: np.ndarray
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    v: float = 0.0
    w: float = 0.0
    in_contact: bool = False
    collisions: int = 0
    rng: np.random.Generator = field(default_factory=np.random.default_rng)

    def step(self, dt: float) -> bool:
        """Advance dt with the applied (v, w) (exact arc); True if a new collision began."""
        yaw_next = self.yaw + self.w * dt
        if abs(self.w) > 1e-9:
            x_next = self.x + self.v / self.w * (math.sin(yaw_next) - math.sin(self.yaw))
            y_next = self.y - self.v / self.w * (math.cos(yaw_next) - math.cos(self.yaw))
        else:
            x_next = self.x + self.v * dt * math.cos(self.yaw)
            y_next = self.y + self.v * dt * math.sin(self.yaw)
        self.yaw = math.remainder(yaw_next, math.tau)
        blocked = distance_to_walls(self.walls, x_next, y_next) < FOOTPRINT_RADIUS
        if not blocked:
            self.x, self.y = x_next, y_next
        new_contact = blocked and not self.in_contact
        self.in_contact = blocked
        self.collisions += new_contact
        return new_contact

    def scan(self, angles: np.ndarray, noise: float) -> np.ndarray:
        """LDS-01-like ranges (float32) from base_scan; 0.0 for no return."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        sx, sy = self.x + SCANNER_OFFSET_X * c, self.y + SCANNER_OFFSET_X * s
        ranges = cast_rays(self.walls, sx, sy, angles + self.yaw)
        if noise > 0:
            ranges = ranges + self.rng.normal(0.0, noise, ranges.shape)
        valid = (ranges >= RANGE_MIN) & (ranges <= RANGE_MAX)
        return np.where(valid, ranges, 0.0).astype(np.float32)


# --- DDS plumbing -----------------------------------------------------------------------------
def stamp(time_ns: int) -> Time:
    sec, nanosec = divmod(time_ns, 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def odom_message(robot: Robot, stamp_ns: int) -> Odometry:
    zeros = [0.0] * 36
    return Odometry(
        header=Header(stamp=stamp(stamp_ns), frame_id="odom"), child_frame_id="base_footprint",
        pose=PoseWithCovariance(pose=Pose(
            position=Point(x=robot.x, y=robot.y, z=0.0),
            orientation=Quaternion(x=0.0, y=0.0, z=math.sin(robot.yaw / 2),
                                   w=math.cos(robot.yaw / 2))), covariance=zeros),
        twist=TwistWithCovariance(twist=Twist(linear=Vector3(x=robot.v, y=0.0, z=0.0),
                                              angular=Vector3(x=0.0, y=0.0, z=robot.w)),
                                  covariance=zeros))


def scan_message(ranges: np.ndarray) -> LaserScan:
    increment = math.radians(1.0)
    return LaserScan(
        header=Header(stamp=stamp(time.time_ns()), frame_id="base_scan"),  # after the revolution
        angle_min=0.0, angle_max=increment * (SCAN_RAYS - 1), angle_increment=increment,
        time_increment=SCAN_PERIOD / SCAN_RAYS, scan_time=SCAN_PERIOD,
        range_min=RANGE_MIN, range_max=RANGE_MAX, ranges=ranges.tolist(),
        intensities=np.where(ranges > 0, 1000.0, 0.0).tolist())


class JsonLog:
    def __init__(self, path: str | None, start: float) -> None:
        self._file: TextIO | None = open(path, "a", buffering=1) if path else None
        self._start = start

    def write(self, event: str, **fields) -> None:
        if self._file is not None:
            record = {"event": event, "t": round(time.monotonic() - self._start, 6),
                      "time": time.time(), **fields}
            self._file.write(json.dumps(record) + "\n")

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--duration", type=float, default=0.0)
    parser.add_argument("--cmd-vel", choices=("stamped", "twist"), default="stamped")
    parser.add_argument("--corridor-width", type=float, default=0.8)
    parser.add_argument("--wall-ahead-at", type=float, default=None)
    parser.add_argument("--stop-scan-after", type=float, default=None)
    parser.add_argument("--scan-clock", choices=("start", "motion"), default="start")
    parser.add_argument("--range-noise", type=float, default=0.0)
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--log", default=None)
    args = parser.parse_args(argv)
    if not 0 <= args.domain <= 232:
        parser.error(f"--domain must be 0-232, got {args.domain}")
    for name in ("duration", "corridor_width", "range_noise"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= 0):
            parser.error(f"--{name.replace('_', '-')} must be a finite number >= 0")
    for name in ("wall_ahead_at", "stop_scan_after"):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value >= 0):
            parser.error(f"--{name.replace('_', '-')} must be a finite number >= 0")
    if args.wall_ahead_at is not None and args.wall_ahead_at <= FOOTPRINT_RADIUS:
        parser.error(f"--wall-ahead-at must leave room for the robot (> {FOOTPRINT_RADIUS} m)")
    if 0 < args.corridor_width <= 2 * FOOTPRINT_RADIUS:
        parser.error(f"--corridor-width must be 0 or wider than the robot "
                     f"(> {2 * FOOTPRINT_RADIUS} m)")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ["CYCLONEDDS_URI"] = CYCLONE_LOOPBACK_CONFIG
    stopping = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stopping.append(True))

    start = time.monotonic()
    log = JsonLog(args.log, start)
    robot = Robot(corridor_walls(args.corridor_width, args.wall_ahead_at),
                  rng=np.random.default_rng(args.seed))
    angles = np.radians(np.arange(SCAN_RAYS, dtype=float))

    participant = DomainParticipant(args.domain)
    odom_writer = DataWriter(participant, Topic(participant, "rt/odom", Odometry), Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10),
        Policy.Durability.Volatile))
    scan_writer = DataWriter(participant, Topic(participant, "rt/scan", LaserScan), Qos(
        Policy.Reliability.BestEffort, Policy.History.KeepLast(5), Policy.Durability.Volatile))
    cmd_type = TwistStamped if args.cmd_vel == "stamped" else Twist
    cmd_reader = DataReader(participant, Topic(participant, "rt/cmd_vel", cmd_type), Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10),
        Policy.Durability.Volatile))
    waitset = WaitSet(participant)
    waitset.attach(ReadCondition(cmd_reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    log.write("start", domain=args.domain, cmd_vel=args.cmd_vel,
              corridor_width=args.corridor_width, wall_ahead_at=args.wall_ahead_at,
              stop_scan_after=args.stop_scan_after, pid=os.getpid())

    odom_sent = scan_sent = commands = invalid_samples = 0
    next_odom = next_scan = start
    last_stamp_ns = time.time_ns()
    scanning = True
    # When --stop-scan-after starts counting: now, or at the first command that moves the robot.
    scan_clock_start = start if args.scan_clock == "start" else None

    def advance_robot() -> None:
        # Integrate over the wall time actually elapsed, up to each tick and each command, and
        # stamp /odom with that same instant: poses agree with their stamps (the estimator
        # differentiates by stamp) even when a tick runs late.
        nonlocal last_stamp_ns
        now_ns = time.time_ns()
        if robot.step(max(0, now_ns - last_stamp_ns) * 1e-9):
            log.write("collision", pose=[robot.x, robot.y, robot.yaw])
        last_stamp_ns = now_ns

    try:
        while not stopping:
            now = time.monotonic()
            if args.duration and now - start >= args.duration:
                break
            if now >= next_odom:
                advance_robot()
                odom_writer.write(odom_message(robot, last_stamp_ns))
                odom_sent += 1
                # After a stall (loaded machine) resume the rate instead of sending a burst.
                next_odom = max(next_odom + ODOM_PERIOD, now)
            if scanning and args.stop_scan_after is not None and scan_clock_start is not None \
                    and now - scan_clock_start >= args.stop_scan_after:
                scanning = False
                log.write("scan_stopped")
            if scanning and now >= next_scan:
                scan_writer.write(scan_message(robot.scan(angles, args.range_noise)))
                scan_sent += 1
                next_scan = max(next_scan + SCAN_PERIOD, now)
            # Sleep until the next tick, waking at once for commands.
            wait = min(next_odom, next_scan if scanning else next_odom) - time.monotonic()
            if wait > 0 and waitset.wait(duration(seconds=wait)) == 0:
                continue
            for sample in cmd_reader.take(N=64):
                if not isinstance(sample, cmd_type):  # InvalidSample: a state change, no data
                    invalid_samples += 1
                    continue
                twist = sample.twist if cmd_type is TwistStamped else sample
                linear = [twist.linear.x, twist.linear.y, twist.linear.z]
                angular = [twist.angular.x, twist.angular.y, twist.angular.z]
                if math.isfinite(linear[0]) and math.isfinite(angular[2]):
                    advance_robot()
                    robot.v, robot.w = apply_like_turtlebot3(linear[0], angular[2])
                    if scan_clock_start is None and (robot.v, robot.w) != (0.0, 0.0):
                        scan_clock_start = time.monotonic()
                header_stamp = ([sample.header.stamp.sec, sample.header.stamp.nanosec]
                                if cmd_type is TwistStamped else None)
                commands += 1
                # json writes NaN/Infinity tokens for non-finite values (Python's json reads them).
                log.write("cmd", linear=linear, angular=angular, stamp=header_stamp,
                          applied=[robot.v, robot.w], pose=[robot.x, robot.y, robot.yaw])
    finally:
        log.write("end", odom_sent=odom_sent, scan_sent=scan_sent, cmds=commands,
                  invalid_samples=invalid_samples, collisions=robot.collisions,
                  cpu_s=round(time.process_time(), 3))
        log.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
