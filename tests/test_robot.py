"""Robot kinematics, wheel-speed saturation, encoders and walls that stop the robot."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common import robot
from amr_sim.simulator import Simulator

EXACT_TOL = 1e-9  # m and rad: free motion is the exact unicycle solution up to rounding


def exact_unicycle(x0, y0, th0, v, w, t):
    if abs(w) < 1e-12:
        return x0 + v * t * math.cos(th0), y0 + v * t * math.sin(th0), th0
    return (x0 + v / w * (math.sin(th0 + w * t) - math.sin(th0)),
            y0 - v / w * (math.cos(th0 + w * t) - math.cos(th0)), th0 + w * t)


def angle_diff(a, b):
    return math.remainder(a - b, 2 * math.pi)


@pytest.mark.parametrize("world, start, v, w, steps", [
    ("room_obstacles", (1.2, 1.7, math.pi / 2), 0.2, 0.0, 20),     # straight
    ("room_obstacles", (2.0, 0.5, 0.0), 0.1, 0.5, 20),               # arc to the left
    ("room_obstacles", (0.5, 2.0, -2.5), 0.15, -0.8, 40),            # arc to the right
    ("room_obstacles", (0.5, 2.0, 1.0), 0.0, 1.2, 60),               # spin in place
])
def test_free_motion_matches_exact_unicycle(world, start, v, w, steps):
    sim = Simulator(world, start=start, dt=0.05)
    for _ in range(steps):
        _, z_v, z_w = sim.step(v, w)
    t = steps * 0.05
    x, y, th = exact_unicycle(*start, v, w, t)
    px, py, pth = sim.pose
    assert math.hypot(px - x, py - y) < EXACT_TOL
    assert abs(angle_diff(pth, th)) < EXACT_TOL
    # Encoders see the same motion: twist, wheel angles and the dead-reckoned odometry.
    assert z_v == pytest.approx(v, abs=EXACT_TOL) and z_w == pytest.approx(w, abs=EXACT_TOL)
    left, right = sim.wheel_angles
    assert right == pytest.approx((v + w * robot.TRACK / 2) / robot.WHEEL_RADIUS * t, abs=1e-7)
    assert left == pytest.approx((v - w * robot.TRACK / 2) / robot.WHEEL_RADIUS * t, abs=1e-7)
    ox, oy, oth = sim.odometry_pose  # odom frame = the start pose
    c, s = math.cos(start[2]), math.sin(start[2])
    assert ox == pytest.approx(c * (x - start[0]) + s * (y - start[1]), abs=1e-7)
    assert oy == pytest.approx(-s * (x - start[0]) + c * (y - start[1]), abs=1e-7)
    assert angle_diff(oth, th - start[2]) == pytest.approx(0.0, abs=1e-9)
    assert sim.distance == pytest.approx(abs(v) * t, rel=1e-3, abs=1e-9)
    assert sim.collisions == 0


@pytest.mark.parametrize("v, w", [(0.2, 0.0), (0.1, 0.5), (-0.15, -0.8), (0.0, 1.2)])
def test_the_shared_step_is_the_exact_unicycle_and_step_chord_inverts_it(v, w):
    x, y, th = 0.3, -0.2, 2.9
    for _ in range(40):
        x1, y1, th1 = robot.unicycle_step(x, y, th, v, w, 0.05)
        # Its chord back from the displacement, its arc length back from the chord.
        chord = robot.step_chord(x1 - x, y1 - y, th, th1 - th)
        assert chord / robot.sinc_half(th1 - th) == pytest.approx(v * 0.05, abs=1e-15)
        x, y, th = x1, y1, th1
    ex, ey, eth = exact_unicycle(0.3, -0.2, 2.9, v, w, 2.0)
    assert math.hypot(x - ex, y - ey) < EXACT_TOL and abs(angle_diff(th, eth)) < EXACT_TOL
    # The compiled twin gives the same bits.
    assert robot.arc_displacement_kernel(2.9, 0.01, 0.04) == robot.arc_displacement(2.9, 0.01,
                                                                                     0.04)


@pytest.mark.parametrize("v, w", [(0.22, 1.0), (-0.3, -2.0), (0.1, 5.0), (0.0, -9.0), (1e12, 1e12),
                                  (-0.22, 0.5)])
def test_saturation_keeps_turning_direction_and_curvature(v, w):
    w_left, w_right = robot.inverse_kinematics(v, w)
    assert max(abs(w_left), abs(w_right)) <= robot.WHEEL_SPEED_MAX * (1 + 1e-12)
    v_out, w_out = robot.forward_kinematics(w_left, w_right)
    assert math.isfinite(v_out) and math.isfinite(w_out)
    assert (math.copysign(1, w_out) == math.copysign(1, w)
            and math.copysign(1, v_out) == math.copysign(1, v)) or v == 0
    if v != 0:
        assert w_out / v_out == pytest.approx(w / v, rel=1e-9)  # same curvature, same path
    assert max(abs(w_left), abs(w_right)) == pytest.approx(robot.WHEEL_SPEED_MAX)


def test_within_limits_commands_are_untouched():
    assert robot.saturate(0.1, 0.5) == pytest.approx((0.1, 0.5))
    assert robot.saturate(0.22, 0.0) == pytest.approx((0.22, 0.0))


def test_saturated_command_in_simulator_keeps_curvature():
    sim = Simulator("room_obstacles", start=(2.0, 2.6, 0.0))
    _, z_v, z_w = sim.step(0.5, 2.0)  # both over the limits
    assert z_w / z_v == pytest.approx(4.0, rel=1e-9)
    assert z_v < 0.22 and z_w > 0


def drive(sim, v, w, seconds):
    for _ in range(int(round(seconds / sim.dt))):
        sim.step(v, w)


@pytest.mark.parametrize("profile", ["ideal", "turtlebot3_clean"])  # equal wheels, no slip
def test_robot_cannot_pass_through_a_wall(profile):
    # lab02 outer ring, 0.6 m south of the north wall (y = 1.2), driving north at full speed.
    sim = Simulator("lab02", start=(1.0, 0.6, math.pi / 2), profile=profile)
    drive(sim, 0.22, 0.0, 5.0)
    resting = sim.pose
    drive(sim, 0.22, 0.0, 5.0)  # keep pushing for 5 more seconds (10 s in all)
    x, y, th = sim.pose
    assert (x, y) == pytest.approx(resting[:2], abs=1e-6), "the robot stopped at the wall"
    penetration = y + robot.ROBOT_RADIUS - 1.2
    assert penetration < 0.005
    assert -0.005 < sim.min_clearance <= 0.0, "in contact: clearance <= 0, no sinking"
    assert sim.collisions == 1 and sim.in_contact
    assert sim.collision_points[0] == pytest.approx((1.0, 1.2), abs=1e-3)
    _, z_v, z_w = sim.step(0.22, 0.0)
    assert abs(z_v) < 1e-6 and abs(z_w) < 1e-9, "encoders report the actual (blocked) motion"
    drive(sim, -0.1, 0.0, 1.0)  # back off: the contact ends, a new push is a new collision
    assert not sim.in_contact
    drive(sim, 0.2, 0.0, 2.0)
    assert sim.collisions == 2


def test_the_burger_with_the_reality_gap_pushes_at_a_wall_without_sinking():
    # Its right wheel 0.5 % larger: a straight command curves left, so the pushing robot turns
    # and slides along the wall (5 cm in 5 s) instead of resting; it never sinks into it.
    sim = Simulator("lab02", start=(1.0, 0.6, math.pi / 2), profile="turtlebot3")
    for _ in range(200):
        sim.step(0.22, 0.0)
        assert sim.pose[1] + robot.ROBOT_RADIUS - 1.2 < 0.005
        assert sim.min_clearance > -0.005
    assert sim.in_contact and sim.collisions >= 1


def test_corner_and_oblique_contacts_do_not_sink():
    # Into the north-east corner of lab02 at 45 deg, then sliding along the east wall.
    sim = Simulator("lab02", start=(0.95, 0.95, math.pi / 4))
    drive(sim, 0.22, 0.0, 4.0)
    x, y, _ = sim.pose
    assert x + robot.ROBOT_RADIUS - 1.2 < 0.005 and y + robot.ROBOT_RADIUS - 1.2 < 0.005
    assert sim.collisions == 1 and sim.min_clearance > -0.005
    sim = Simulator("lab02", start=(1.0, -0.6, math.pi / 2 - 0.4))
    drive(sim, 0.22, 0.0, 3.0)
    x, y, _ = sim.pose
    assert x + robot.ROBOT_RADIUS - 1.2 < 0.005
    assert y > -0.6 + 0.3, "slides along the wall instead of sticking"
    assert sim.collisions == 1


def test_random_commands_never_leave_the_world_nor_sink():
    rng = np.random.default_rng(7)
    sim = Simulator("lab02", start="inner", profile="ideal")
    for _ in range(500):
        v, w = rng.uniform(-1, 1), rng.uniform(-6, 6)
        for _ in range(int(rng.integers(1, 30))):
            sim.step(v, w)
    x, y, _ = sim.pose
    assert sim.world.contains(x, y)
    assert sim.min_clearance > -0.005
    assert sim.collisions >= 1


def test_velocity_constraint_kernel_matches_python_version():
    from amr_sim.contact import constrain_velocity, constrain_velocity_python

    segments = np.array([[0.0, 0.0, 2.0, 0.0], [0.0, 0.0, 0.0, 2.0]])  # a corner at the origin
    for px, py, vx, vy in [(1.0, 0.106, 0.0, -0.3), (0.106, 0.106, -0.2, -0.2),
                           (1.0, 1.0, 0.2, 0.1), (0.5, 0.104, 0.3, -0.3)]:
        no_circles = np.zeros((0, 3))
        fast = constrain_velocity(segments, no_circles, px, py, vx, vy, 0.05, 0.105, 0.0005)
        slow = constrain_velocity_python(segments, no_circles, px, py, vx, vy, 0.05, 0.105,
                                         0.0005)
        assert fast == pytest.approx(slow, abs=1e-12)
        # never ends deeper than the allowed 0.5 mm in either wall
        assert py + fast[1] * 0.05 >= 0.105 - 0.0005 - 1e-12 or py < 0.105
        assert px + fast[0] * 0.05 >= 0.105 - 0.0005 - 1e-12
