"""Planar geometry shared by every package: angles, planar poses, yaw <-> quaternion.

Pure math on floats (no message classes, no rclpy); amr_common.ros.ros_conversions applies it to
geometry_msgs. REP 103: x forward/east, y left/north, yaw counter-clockwise about +z.
"""
from __future__ import annotations

import math

import numpy as np
from transforms3d.euler import quat2euler

_MIN_QUATERNION_NORM = 1e-6


def wrap_angle(angle: float) -> float:
    """Angle wrapped to (-pi, pi] (pi stays pi, -pi becomes pi)."""
    return math.pi - ((math.pi - angle) % math.tau)


def angle_difference(a: float, b: float) -> float:
    """A - b taken the short way round, in (-pi, pi]."""
    return wrap_angle(a - b)


def wrap_angles(angles: np.ndarray) -> np.ndarray:
    """Angles of an array wrapped to [-pi, pi) (numpy's remainder: pi becomes -pi)."""
    return np.remainder(angles + math.pi, 2.0 * math.pi) - math.pi


def polyline_length(points: np.ndarray) -> float:
    """Length (m) of the polyline through (N, 2) points; 0 for fewer than two."""
    return float(np.hypot(*np.diff(points, axis=0).T).sum()) if len(points) > 1 else 0.0


def without_repeats(points: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
    """The (N, 2) points without those closer than `tolerance` to the point before (N >= 1)."""
    steps = np.hypot(*np.diff(points, axis=0).T)
    return points[np.concatenate([[True], steps > tolerance])]


def compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, ...]:
    """Planar pose b (x, y, yaw) expressed in a's parent: a * b."""
    ax, ay, ath = a
    bx, by, bth = b
    c, s = math.cos(ath), math.sin(ath)
    return ax + c * bx - s * by, ay + s * bx + c * by, wrap_angle(ath + bth)


def inverse(a: tuple[float, float, float]) -> tuple[float, float, float]:
    """The inverse planar transform of (x, y, yaw)."""
    x, y, th = a
    c, s = math.cos(th), math.sin(th)
    return -c * x - s * y, s * x - c * y, wrap_angle(-th)


def map_to_odom(map_to_base: tuple[float, float, float],
                odom_to_base: tuple[float, float, float]) -> tuple[float, float, float]:
    """Map -> odom that makes map -> odom -> base equal map_to_base (what a localizer sends)."""
    return compose(map_to_base, inverse(odom_to_base))


def yaw_to_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by `yaw` rad about +z: (0, 0, sin(yaw/2), cos(yaw/2))."""
    half = 0.5 * float(yaw)
    return 0.0, 0.0, math.sin(half), math.cos(half)


def quaternion_to_yaw(x: float, y: float, z: float, w: float) -> float:
    """Yaw in (-pi, pi] of a quaternion in ROS (x, y, z, w) order.

    A non-unit quaternion is normalised first (with math.hypot, so a norm of 1e300 neither
    overflows nor changes the yaw). Raises ValueError for non-finite or zero-norm input.
    """
    components = (x, y, z, w)
    if not all(math.isfinite(c) for c in components):
        raise ValueError(f"quaternion has non-finite components {components} (x, y, z, w)")
    norm = math.hypot(x, y, z, w)
    if not math.isfinite(norm) or norm < _MIN_QUATERNION_NORM:
        raise ValueError(f"quaternion {components} (x, y, z, w) has no usable norm ({norm:.3g})")
    # transforms3d orders quaternions (w, x, y, z); 'sxyz' returns (roll, pitch, yaw).
    _, _, yaw = quat2euler((w / norm, x / norm, y / norm, z / norm), "sxyz")
    return float(yaw)


__all__ = ["wrap_angle", "angle_difference", "wrap_angles", "polyline_length", "without_repeats",
           "compose", "inverse", "map_to_odom", "yaw_to_quaternion", "quaternion_to_yaw"]
