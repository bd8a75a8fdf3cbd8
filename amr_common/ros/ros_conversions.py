"""Building and reading the ROS messages the simulator, the controllers and the planner exchange.

Pure message helpers: no node, no publisher, no rclpy import (only message classes), so the
simulator node, the wall follower node and the real-robot estimator share one definition of
stamps, quaternions, LaserScan fields and Odometry layout.
"""
from __future__ import annotations

import array
import math
from typing import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import (
    Pose,
    PoseArray,
    PoseStamped,
    PoseWithCovarianceStamped,
    Quaternion,
    Twist,
    TwistStamped,
)
from nav_msgs.msg import Odometry, Path
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan

from amr_common import geometry
from amr_common.navigation_behaviour import NS_PER_S as _NS_PER_S
from amr_common.navigation_behaviour import stamp_ns

# --- time ---------------------------------------------------------------------------------

def seconds_to_time(seconds: float, stamp: Time | None = None) -> Time:
    """builtin_interfaces/Time of a time in seconds, rounded to the nanosecond.

    Rounding the total in nanoseconds (not the fraction) keeps consecutive stamps k*dt apart by
    exactly round(dt * 1e9) ns; a non-finite time raises ValueError. Fills `stamp` in place
    when given (building a Time costs more than the rest of this function).
    """
    if not math.isfinite(seconds):
        raise ValueError(f"cannot convert non-finite time {seconds!r} to a stamp")
    sec, nanosec = divmod(stamp_ns(seconds), _NS_PER_S)  # the headless episodes' stamps too
    if stamp is None:
        return Time(sec=int(sec), nanosec=int(nanosec))
    stamp.sec, stamp.nanosec = int(sec), int(nanosec)
    return stamp


def time_to_seconds(stamp: Time) -> float:
    """Seconds of a builtin_interfaces/Time (or any object with sec and nanosec)."""
    return stamp.sec + stamp.nanosec * 1e-9


def time_to_nanoseconds(stamp: Time) -> int:
    """Exact integer nanoseconds of a stamp (for comparing stamps without float rounding)."""
    return stamp.sec * _NS_PER_S + stamp.nanosec


def clock_message(seconds: float | Time) -> Clock:
    """rosgraph_msgs/Clock carrying a simulated time (seconds or a stamp)."""
    return Clock(clock=seconds if isinstance(seconds, Time) else seconds_to_time(seconds))


# --- orientation --------------------------------------------------------------------------

def yaw_to_quaternion(yaw: float, quaternion: Quaternion | None = None) -> Quaternion:
    """geometry_msgs/Quaternion of a rotation by `yaw` rad about +z (REP 103: counter-clockwise).

    Fills `quaternion` in place when given (saves building a message per step).
    """
    x, y, z, w = geometry.yaw_to_quaternion(yaw)
    if quaternion is None:
        return Quaternion(x=x, y=y, z=z, w=w)
    quaternion.x, quaternion.y, quaternion.z, quaternion.w = x, y, z, w
    return quaternion


def quaternion_to_yaw(quaternion: Quaternion) -> float:
    """Yaw in (-pi, pi] of a geometry_msgs/Quaternion.

    Normalised first; ValueError if unusable.
    """
    return geometry.quaternion_to_yaw(quaternion.x, quaternion.y, quaternion.z, quaternion.w)


# --- commands -----------------------------------------------------------------------------

def command_from_twist(message: Twist | TwistStamped) -> tuple[float, float]:
    """(v, w): forward speed (m/s) and yaw rate (rad/s) of a Twist or TwistStamped.

    Values are returned as sent (NaN included): deciding what a bad command means is the
    receiver's job.
    """
    twist = message.twist if isinstance(message, TwistStamped) else message
    return float(twist.linear.x), float(twist.angular.z)


def twist_stamped(v: float, w: float, stamp: Time | None = None,
                  frame_id: str = "base_footprint") -> TwistStamped:
    """TwistStamped command with forward speed v (m/s) and yaw rate w (rad/s)."""
    message = TwistStamped()
    if stamp is not None:
        message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.twist.linear.x = float(v)
    message.twist.angular.z = float(w)
    return message


# --- odometry -----------------------------------------------------------------------------

def odometry_message(stamp: Time, frame_id: str, child_frame_id: str,
                     pose: Sequence[float] | None = None,
                     velocity: Sequence[float] | None = None,
                     message: Odometry | None = None) -> Odometry:
    """nav_msgs/Odometry of a planar robot.

    pose: (x, y, theta) of child_frame_id in frame_id, or None for the identity pose.
    velocity: (v, w) body-frame forward speed and yaw rate, or None for a zero twist (as on an
    /odom that reports only a pose).
    message: an Odometry to fill in place and return (building one costs ~130 us, most of a
    simulation step; publishing copies it, so reusing it is safe).
    """
    if message is None:
        message = Odometry()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.child_frame_id = child_frame_id
    x, y, theta = pose if pose is not None else (0.0, 0.0, 0.0)
    position = message.pose.pose.position
    position.x, position.y = float(x), float(y)
    yaw_to_quaternion(theta, message.pose.pose.orientation)
    v, w = velocity if velocity is not None else (0.0, 0.0)
    message.twist.twist.linear.x = float(v)
    message.twist.twist.angular.z = float(w)
    return message


def pose_from_message(pose) -> tuple[float, float, float]:
    """(x, y, theta) of a geometry_msgs/Pose (theta = yaw)."""
    return float(pose.position.x), float(pose.position.y), quaternion_to_yaw(pose.orientation)


def fill_pose(pose, xyt: Sequence[float]) -> None:
    """Set a geometry_msgs/Pose to (x, y, theta) on the ground (z 0, theta as yaw)."""
    pose.position.x, pose.position.y = float(xyt[0]), float(xyt[1])
    pose.position.z = 0.0
    yaw_to_quaternion(float(xyt[2]), pose.orientation)


def pose_with_covariance(xyt: Sequence[float], covariance: np.ndarray, stamp: Time,
                         frame_id: str) -> PoseWithCovarianceStamped:
    """geometry_msgs/PoseWithCovarianceStamped (/amcl_pose) of (x, y, theta).

    The 3 x 3 covariance of (x, y, theta) is placed in ROS's 6 x 6 (x, y, z, roll, pitch, yaw).
    """
    message = PoseWithCovarianceStamped()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    fill_pose(message.pose.pose, xyt)
    full = np.zeros((6, 6))
    index = [0, 1, 5]
    full[np.ix_(index, index)] = covariance
    message.pose.covariance = full.ravel().tolist()
    return message


def pose_array(poses: np.ndarray, stamp: Time, frame_id: str) -> PoseArray:
    """geometry_msgs/PoseArray (/particles) of (N, 3) rows [x, y, theta]."""
    message = PoseArray()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    for xyt in poses:
        pose = Pose()
        fill_pose(pose, xyt)
        message.poses.append(pose)
    return message


# --- paths --------------------------------------------------------------------------------

def path_message(points: Sequence[Sequence[float]] | np.ndarray, stamp: Time,
                 frame_id: str = "map") -> Path:
    """nav_msgs/Path through the (K, 2) points, each pose facing the next point.

    The last pose keeps the previous heading. No points: an empty path ("no path").
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    message = Path()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    headings = np.arctan2(*np.diff(pts, axis=0)[:, ::-1].T) if len(pts) > 1 else np.zeros(0)
    headings = np.append(headings, headings[-1] if len(headings) else 0.0)
    poses = []
    for (x, y), heading in zip(pts, headings):
        pose = PoseStamped()
        pose.header = message.header
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        yaw_to_quaternion(float(heading), pose.pose.orientation)
        poses.append(pose)
    message.poses = poses
    return message


def path_points(message: Path) -> np.ndarray:
    """(K, 2) positions of a nav_msgs/Path's poses (may hold non-finite values: check them)."""
    return np.array([[p.pose.position.x, p.pose.position.y] for p in message.poses],
                    dtype=np.float64).reshape(-1, 2)


# --- laser scans --------------------------------------------------------------------------

def float32_array(values: Sequence[float] | np.ndarray) -> array.array:
    """array('f') of values, for a float32[] message field.

    Assigning one skips the per-element type checks rclpy runs on lists (~100x faster for a
    360-ray scan).
    """
    packed = array.array("f")
    packed.frombytes(np.ascontiguousarray(values, dtype=np.float32).tobytes())
    return packed


def laser_scan(ranges: Sequence[float] | np.ndarray, *, stamp: Time, frame_id: str,
               angle_min: float, angle_increment: float, range_min: float, range_max: float,
               scan_time: float, message: LaserScan | None = None) -> LaserScan:
    """sensor_msgs/LaserScan with every field filled.

    Rays are counter-clockwise from angle_min; angle_max is the angle of the LAST ray
    (angle_min + (n - 1) * increment), as the LDS drivers report it. time_increment spreads
    scan_time evenly over the rays. Ranges are copied as given (the sensor's encoding of "no
    return": NaN or 0.0). `message`: a LaserScan to fill in place and return.
    """
    n_rays = len(ranges)
    if n_rays == 0:
        raise ValueError("a LaserScan needs at least one ray")
    if message is None:
        message = LaserScan()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.angle_min = float(angle_min)
    message.angle_max = float(angle_min + (n_rays - 1) * angle_increment)
    message.angle_increment = float(angle_increment)
    message.time_increment = float(scan_time / n_rays)
    message.scan_time = float(scan_time)
    message.range_min = float(range_min)
    message.range_max = float(range_max)
    message.ranges = float32_array(ranges)
    return message


def laser_scan_from_profile(ranges: Sequence[float] | np.ndarray, profile, *, stamp: Time,
                            frame_id: str, scan_time: float,
                            message: LaserScan | None = None) -> LaserScan:
    """LaserScan of a simulated sensor described by an amr_sim.profiles.SensorProfile."""
    if len(ranges) != profile.scan_rays:
        raise ValueError(f"profile '{profile.name}' has {profile.scan_rays} rays, "
                         f"got {len(ranges)} ranges")
    return laser_scan(ranges, stamp=stamp, frame_id=frame_id, angle_min=profile.angle_min,
                      angle_increment=profile.angle_increment, range_min=profile.range_min,
                      range_max=profile.range_max, scan_time=scan_time, message=message)


def scan_ranges(message: LaserScan) -> np.ndarray:
    """The ranges of a LaserScan as a float64 numpy array (a copy)."""
    return np.frombuffer(message.ranges, dtype=np.float32).astype(np.float64) \
        if isinstance(message.ranges, array.array) \
        else np.asarray(message.ranges, dtype=np.float64)


def ray_angles(message: LaserScan) -> np.ndarray:
    """Angle (rad, in the scan frame) of every ray of a LaserScan, from its own fields."""
    return message.angle_min + message.angle_increment * np.arange(len(message.ranges))


__all__ = ["seconds_to_time", "time_to_seconds", "time_to_nanoseconds", "clock_message",
           "yaw_to_quaternion", "quaternion_to_yaw", "command_from_twist", "twist_stamped",
           "odometry_message", "pose_from_message", "path_message", "path_points",
           "float32_array", "laser_scan",
           "laser_scan_from_profile", "scan_ranges", "ray_angles"]
