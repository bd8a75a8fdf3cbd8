"""TurtleBot3 Burger: the one home of its constants and differential-drive kinematics.

Pure functions, no physics, no rclpy. Sources: turtlebot3.md (ROBOTIS jazzy branch, e-manual).

Inverse kinematics saturates the wheel speeds like the course robot: if a wheel would exceed
WHEEL_SPEED_MAX, both wheel speeds are scaled by the same factor, so the turning direction and the
curvature w / v are kept and only the speed drops.
"""
from __future__ import annotations

import math

from amr_common.jit import jit

WHEEL_RADIUS = 0.033  # m
TRACK = 0.16  # m, wheel separation
ROBOT_RADIUS = 0.105  # m, footprint
MAX_LINEAR_SPEED = 0.22  # m/s, official limit (also each wheel's rim speed limit)
MAX_ANGULAR_SPEED = 2.84  # rad/s, official limit
LINEAR_SPEED_MAX = MAX_LINEAR_SPEED  # the course template's name
WHEEL_SPEED_MAX = LINEAR_SPEED_MAX / WHEEL_RADIUS  # rad/s
LIDAR_OFFSET_X = -0.032  # m, base_scan from base_link along x (LDS-01 on the Burger)
LIDAR_HEIGHT = 0.182  # m, base_scan above base_footprint (base_link 0.010 + base_scan 0.172)
MASS = 1.0  # kg, Burger (affects only contact impulses; the drive reaches commands within a step)
# Measured speeds beyond the limits times this margin (noise, wheel slip, a push by hand) are
# physically impossible for the Burger: such odometry is corrupt and is rejected, not clipped.
PLAUSIBLE_SPEED_MARGIN = 3.0
MAX_PLAUSIBLE_LINEAR_SPEED = PLAUSIBLE_SPEED_MARGIN * MAX_LINEAR_SPEED  # 0.66 m/s
MAX_PLAUSIBLE_ANGULAR_SPEED = PLAUSIBLE_SPEED_MARGIN * MAX_ANGULAR_SPEED  # 8.52 rad/s

_HALF_TRACK = TRACK / 2.0
# Commands beyond this are absurd (simulator, kinematics); clipping first keeps v +- w * TRACK / 2
# finite.
COMMAND_CLIP = 1.0e6


def is_plausible_twist(v: float, w: float) -> bool:
    """True if a measured twist (v m/s, w rad/s) is finite and possible for the Burger.

    Possible: within MAX_PLAUSIBLE_LINEAR_SPEED and MAX_PLAUSIBLE_ANGULAR_SPEED.
    """
    return abs(v) <= MAX_PLAUSIBLE_LINEAR_SPEED and abs(w) <= MAX_PLAUSIBLE_ANGULAR_SPEED


def inverse_kinematics(v: float, w: float) -> tuple[float, float]:
    """Wheel speeds (wL, wR) in rad/s for a body twist (v m/s, w rad/s).

    Saturated at WHEEL_SPEED_MAX.
    """
    v = min(max(v, -COMMAND_CLIP), COMMAND_CLIP)
    w = min(max(w, -COMMAND_CLIP), COMMAND_CLIP)
    w_right = (v + w * TRACK / 2.0) / WHEEL_RADIUS
    w_left = (v - w * TRACK / 2.0) / WHEEL_RADIUS
    fastest = max(abs(w_left), abs(w_right))
    if fastest > WHEEL_SPEED_MAX:
        scale = WHEEL_SPEED_MAX / fastest
        w_left *= scale
        w_right *= scale
    return w_left, w_right


def forward_kinematics(w_left: float, w_right: float) -> tuple[float, float]:
    """Body twist (v m/s, w rad/s) from the wheel speeds (wL, wR) in rad/s."""
    v = WHEEL_RADIUS * (w_right + w_left) / 2.0
    w = WHEEL_RADIUS * (w_right - w_left) / TRACK
    return v, w


def saturate(v: float, w: float) -> tuple[float, float]:
    """The twist the robot executes for a command (v m/s, w rad/s).

    Unchanged while both wheels are within WHEEL_SPEED_MAX, else both wheel speeds scaled by one
    factor (the curvature kept).

    Equal to forward_kinematics(*inverse_kinematics(v, w)) up to rounding; a command within the
    limits comes back bit-for-bit (the simulator runs this every step).
    """
    w_right = (v + w * _HALF_TRACK) / WHEEL_RADIUS
    w_left = (v - w * _HALF_TRACK) / WHEEL_RADIUS
    fastest = max(abs(w_left), abs(w_right))
    if fastest > WHEEL_SPEED_MAX:
        scale = WHEEL_SPEED_MAX / fastest
        return (WHEEL_RADIUS * (w_right + w_left) * scale / 2.0,
                WHEEL_RADIUS * (w_right - w_left) * scale / TRACK)
    return v, w


def sinc_half(angle: float) -> float:
    """sin(angle/2) / (angle/2): chord length over arc length for a turn of `angle` rad."""
    half = 0.5 * angle
    if abs(half) < 1e-6:
        return 1.0 - half * half / 6.0
    return math.sin(half) / half


# --- the pose-integration step: every pose that moves by a (v, w) step moves with these -------
# A step that turns by dtheta moves the robot along the chord of its arc, at the mid heading
# theta + dtheta / 2. The exact unicycle chord is v dt sinc_half(w dt); the particle filter's
# motion model takes v dt (the arc for the chord: second-order close, and cheaper).

def arc_displacement(theta: float, chord: float, dtheta: float) -> tuple[float, float]:
    """(dx, dy) of a step of length `chord` (m) at the mid heading theta + dtheta / 2."""
    mid = theta + 0.5 * dtheta
    return chord * math.cos(mid), chord * math.sin(mid)


# The compiled twin, for numba kernels (the particle filter's motion model).
arc_displacement_kernel = jit(arc_displacement)


def arc_step(x: float, y: float, theta: float, chord: float,
             dtheta: float) -> tuple[float, float, float]:
    """The pose (x, y, theta) after a step along `chord` (m) that turns by dtheta (rad).

    The heading is not wrapped (callers keep theirs in their own range).
    """
    dx, dy = arc_displacement(theta, chord, dtheta)
    return x + dx, y + dy, theta + dtheta


def step_chord(dx: float, dy: float, theta: float, dtheta: float) -> float:
    """The chord of the step that moved the robot by (dx, dy) while it turned theta -> +dtheta.

    The displacement projected on the mid heading (arc_displacement's inverse; sideways motion,
    such as sliding along a wall, drops out). arc length = chord / sinc_half(dtheta).
    """
    mid = theta + 0.5 * dtheta
    return dx * math.cos(mid) + dy * math.sin(mid)


def unicycle_step(x: float, y: float, theta: float, v: float, w: float,
                  dt: float) -> tuple[float, float, float]:
    """Exact integration of the unicycle model over dt with a constant twist (v, w)."""
    dtheta = w * dt
    return arc_step(x, y, theta, v * dt * sinc_half(dtheta), dtheta)


def encoder_increments(ds: float, dtheta: float) -> tuple[float, float]:
    """Wheel angle increments (dphi_L, dphi_R) in rad for an arc of length ds and turn dtheta."""
    return (ds - dtheta * _HALF_TRACK) / WHEEL_RADIUS, (ds + dtheta * _HALF_TRACK) / WHEEL_RADIUS


def twist_from_increments(dphi_left: float, dphi_right: float, dt: float) -> tuple[float, float]:
    """Body twist (v m/s, w rad/s) the encoders report for wheel angle increments over dt."""
    return (WHEEL_RADIUS * (dphi_right + dphi_left) / (2.0 * dt),
            WHEEL_RADIUS * (dphi_right - dphi_left) / (TRACK * dt))
