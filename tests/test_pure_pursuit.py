"""The regulated pure pursuit on a perfect pose.

Tracking precision on an L-shaped and a zig-zag path, a clean stop, the Burger's limits, and
its safety rules.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.robot import MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED, TRACK, unicycle_step
from amr_control.pure_pursuit import PurePursuit, scan_clearance, scan_free_ahead
from amr_evaluation.navigation_episode import distances_to_polyline

DT = 0.05
L_PATH = np.array([[0.0, 0.0], [1.2, 0.0], [1.2, 0.8]])
ZIGZAG = np.array([[0.0, 0.0], [0.4, 0.4], [0.8, 0.0], [1.2, 0.4], [1.6, 0.0], [2.0, 0.4]])
# A planner-style path: dense samples with a rounded corner (radius 0.2 m).
ARC = np.vstack([np.column_stack([np.linspace(0, 0.8, 41), np.zeros(41)]),
                 np.column_stack([0.8 + 0.2 * np.sin(np.linspace(0, math.pi / 2, 17)[1:]),
                                  0.2 - 0.2 * np.cos(np.linspace(0, math.pi / 2, 17)[1:])]),
                 np.column_stack([np.ones(30), 0.2 + np.linspace(0, 0.6, 31)[1:]])])


def drive(path, pose, steps=3000, clearance=None, **params):
    """Follow `path` from `pose` with exact kinematics; (positions, commands, pursuit)."""
    pursuit = PurePursuit(DT, **params)
    pursuit.set_path(path)
    x, y, theta = pose
    positions, commands = [(x, y)], []
    for _ in range(steps):
        v, w = pursuit.compute_commands(x, y, theta, clearance)
        commands.append((v, w, pursuit.state))
        x, y, theta = unicycle_step(x, y, theta, v, w, DT)
        positions.append((x, y))
        if len(commands) > 40 and all(c[:2] == (0.0, 0.0) for c in commands[-40:]):
            break
    return np.array(positions), commands, pursuit


@pytest.mark.parametrize("name, path", [("L", L_PATH), ("zig-zag", ZIGZAG), ("arc", ARC)])
def test_tracks_within_a_centimetre_and_stops_on_the_goal(name, path):
    heading = math.atan2(*(path[1] - path[0])[::-1])
    positions, commands, pursuit = drive(path, (*path[0], heading))
    cross_track = distances_to_polyline(positions, path)
    assert cross_track.mean() <= 0.01 and cross_track.max() <= 0.03, \
        (cross_track.mean(), cross_track.max())
    assert math.dist(positions[-1], path[-1]) <= 0.03
    assert pursuit.arrived and pursuit.state == "arrived"
    # Settled: zero commands from the stop on, and no backing up or dithering before it.
    stop = next(i for i, c in enumerate(commands) if c[2] == "arrived")
    assert all(c[:2] == (0.0, 0.0) for c in commands[stop:])
    assert all(v >= 0.0 for v, _, _ in commands)
    approach = [v for v, _, state in commands[max(0, stop - 10):stop] if state == "track"]
    assert approach == sorted(approach, reverse=True), "speed falls monotonically into the stop"


def test_commands_respect_the_burger_limits_and_the_wheel_speed_limit():
    _, commands, _ = drive(ZIGZAG, (0.0, 0.0, 2.5))
    for v, w, _ in commands:
        assert abs(v) <= MAX_LINEAR_SPEED + 1e-12 and abs(w) <= MAX_ANGULAR_SPEED + 1e-12
        assert abs(v) + abs(w) * TRACK / 2 <= MAX_LINEAR_SPEED + 1e-9
    assert max(v for v, _, _ in commands) == pytest.approx(MAX_LINEAR_SPEED, rel=0.01)


def test_turns_in_place_first_when_facing_away_from_the_path():
    positions, commands, pursuit = drive(L_PATH, (0.0, 0.0, math.pi))
    turning = [c for c in commands[:20] if c[2] == "rotate"]
    assert len(turning) >= 10 and all(v == 0.0 and w != 0.0 for v, w, _ in turning)
    assert distances_to_polyline(positions, L_PATH).max() <= 0.01
    assert pursuit.arrived


def test_slows_near_obstacles():
    free = PurePursuit(DT)
    tight = PurePursuit(DT)
    for pursuit in (free, tight):
        pursuit.set_path(L_PATH)
    for _ in range(30):  # accelerate on the straight
        v_free, _ = free.compute_commands(0.0, 0.0, 0.0, None)
        v_tight, _ = tight.compute_commands(0.0, 0.0, 0.0, 0.015)
    assert v_free == pytest.approx(MAX_LINEAR_SPEED)
    assert v_tight == pytest.approx(0.25 * v_free)


def test_far_from_the_path_it_stops_and_recovers_when_back():
    pursuit = PurePursuit(DT)
    pursuit.set_path(L_PATH)
    assert pursuit.compute_commands(0.5, 0.5, 0.0) == (0.0, 0.0)
    assert pursuit.state == "off_path" and pursuit.cross_track_error == pytest.approx(0.5)
    assert pursuit.compute_commands(0.0, 0.01, 0.0) != (0.0, 0.0)


def test_no_path_non_finite_pose_and_a_lone_goal_point():
    pursuit = PurePursuit(DT)
    assert pursuit.compute_commands(0.0, 0.0, 0.0) == (0.0, 0.0) and pursuit.state == "idle"
    pursuit.set_path(L_PATH)
    assert pursuit.compute_commands(float("nan"), 0.0, 0.0) == (0.0, 0.0)
    positions, _, lone = drive([[0.5, 0.0]], (0.0, 0.0, 0.0))
    assert lone.arrived and math.dist(positions[-1], (0.5, 0.0)) <= 0.01
    with pytest.raises(ValueError, match="at least one point, all finite"):
        pursuit.set_path([[0.0, 0.0], [float("inf"), 1.0]])
    with pytest.raises(ValueError):
        pursuit.set_path(np.zeros((0, 2)))


def test_a_new_path_after_arriving_is_followed():
    positions, _, pursuit = drive(L_PATH, (0.0, 0.0, 0.0))
    pursuit.set_path([L_PATH[-1], [0.6, 0.8]])
    assert not pursuit.arrived and pursuit.state == "rotate"


@pytest.mark.parametrize("params, problem", [
    ({"min_lookahead_m": 0.3}, "max_lookahead_m must be >= min_lookahead_m"),
    ({"heading_tolerance_rad": 1.0}, "heading_tolerance_rad must be below"),
    ({"goal_tolerance_m": -0.1}, "goal_tolerance_m must be > 0 \\(got -0.1\\)"),
    ({"max_linear_speed_mps": 0}, "max_linear_speed_mps must be > 0"),
    ({"speed": 1.0}, "unknown parameter"),
])
def test_bad_parameters_are_clear_errors(params, problem):
    with pytest.raises(ValueError, match=problem):
        PurePursuit(DT, **params)
    assert PurePursuit(DT, max_linear_speed_mps=5).params["max_linear_speed_mps"] == \
        MAX_LINEAR_SPEED


def test_scan_clearance_from_the_lidar_position_ignoring_invalid_rays():
    ranges = np.full(360, np.nan)
    ranges[0] = 0.3       # ahead
    ranges[180] = 0.2     # behind
    ranges[90] = 0.0      # LDS-01 "no return"
    increment = 2 * math.pi / 360
    # The LiDAR sits 3.2 cm behind the centre: the wall behind is 0.232 m from the centre.
    assert scan_clearance(ranges, 0.0, increment, 0.12, 3.5, -0.032, 0.105) == \
        pytest.approx(0.232 - 0.105)
    assert scan_clearance(np.zeros(360), 0.0, increment, 0.12, 3.5, 0.0, 0.105) is None
    # A scan whose range_min is 0 (some drivers): 0.0 is still "no return", not a wall at the
    # LiDAR (the pursuit slowed to its crawl on it).
    assert scan_clearance(ranges, 0.0, increment, 0.0, 3.5, -0.032, 0.105) == \
        pytest.approx(0.232 - 0.105)


# --- an obstacle the map lacks, in the way -------------------------------------------------

RAYS = 360
INCREMENT = 2 * math.pi / RAYS


def scan_of_points(pose, points, noise=0.0, rng=None):
    """A 360-ray scan (LiDAR at the centre) that sees each world point on its nearest ray."""
    x, y, theta = pose
    ranges = np.full(RAYS, np.inf)
    for px, py in points:
        r = math.hypot(px - x, py - y)
        k = round((math.atan2(py - y, px - x) - theta) / INCREMENT) % RAYS
        ranges[k] = min(ranges[k], r + (rng.normal(0.0, noise) if noise else 0.0))
    return ranges


def drive_with_obstacle(path, pose, obstacle, steps=1200, noise=0.0, removed_at=None):
    """Follow `path` with the scan of `obstacle` points; (positions, commands, pursuit)."""
    rng = np.random.default_rng(0)
    pursuit = PurePursuit(DT)
    pursuit.set_path(path)
    x, y, theta = pose
    positions, commands = [(x, y)], []
    for step in range(steps):
        seen = obstacle if removed_at is None or step < removed_at else []
        scan = scan_of_points((x, y, theta), seen, noise, rng)
        geometry = (scan, 0.0, INCREMENT, 0.12, 3.5, 0.0, 0.105)
        v, w = pursuit.compute_commands(x, y, theta, scan_clearance(*geometry),
                                        scan_free_ahead(*geometry))
        commands.append((v, w, pursuit.state))
        x, y, theta = unicycle_step(x, y, theta, v, w, DT)
        positions.append((x, y))
        if pursuit.arrived:
            break
    return np.array(positions), commands, pursuit


def test_free_ahead_is_the_room_of_the_footprint_straight_on():
    def free(points, offset=0.0):
        ranges = scan_of_points((offset, 0.0, 0.0), points)  # the LiDAR at (offset, 0)
        return scan_free_ahead(ranges, 0.0, INCREMENT, 0.12, 3.5, offset, 0.105)

    assert free([(0.4, 0.0)]) == pytest.approx(0.4 - 0.105)
    # Off-centre: the footprint's edge meets it later (the circle's chord).
    ahead, side = 0.4 * math.cos(INCREMENT * 12), 0.4 * math.sin(INCREMENT * 12)
    assert free([(ahead, side)]) == pytest.approx(ahead - math.sqrt(0.105**2 - side**2))
    assert free([(0.3, 0.2), (-0.3, 0.0), (0.0, -0.3)]) == math.inf  # beside and behind
    assert free([(0.3, 0.0)], offset=-0.032) == pytest.approx(0.3 - 0.105)
    assert free([(0.05, 0.0)], offset=-0.1) == 0.0  # inside the footprint already
    assert scan_free_ahead(np.zeros(RAYS), 0.0, INCREMENT, 0.12, 3.5, 0.0, 0.105) is None


def test_a_box_in_the_way_stops_the_robot_short_of_it_until_it_goes():
    box = [(0.6 + dx, dy) for dx in np.linspace(0.0, 0.2, 11) for dy in np.linspace(-0.1, 0.1, 11)]
    positions, commands, pursuit = drive_with_obstacle(L_PATH, (0.0, 0.0, 0.0), box, steps=300)
    assert not pursuit.arrived and pursuit.state == "blocked"
    assert all(c[:2] == (0.0, 0.0) for c in commands[-100:])  # waits there, no creeping
    front = 0.6 - positions[-1][0] - 0.105  # footprint to the box's near face
    assert 0.015 <= front <= 0.03, front
    # The way clears: the pursuit drives on to the goal.
    positions, commands, pursuit = drive_with_obstacle(L_PATH, (0.0, 0.0, 0.0), box,
                                                       removed_at=300, steps=3000)
    assert pursuit.arrived and math.dist(positions[-1], L_PATH[-1]) <= 0.03
    assert (np.array(positions)[:300, 0] <= 0.6 - 0.105).all()


def test_a_wall_just_beyond_the_goal_does_not_stop_it_short():
    # The goal keeps GOAL_CLEARANCE (0.135 m) from the wall straight ahead of the last leg: the
    # footprint has 3 cm of room at the goal, beyond the stop the path asks for.
    wall = [(L_PATH[-1][0] + dx, L_PATH[-1][1] + 0.135) for dx in np.linspace(-0.4, 0.4, 81)]
    exact, noisy = (drive_with_obstacle(L_PATH, (0.0, 0.0, 0.0), wall, noise=noise, steps=3000)
                    for noise in (0.0, 0.01))
    for positions, _, pursuit in (exact, noisy):
        assert pursuit.arrived and math.dist(positions[-1], L_PATH[-1]) <= 0.01
    assert "blocked" not in {c[2] for c in exact[1]}
    # 1 cm range noise (the LDS-01's) on every ray: at most a few halting steps on the way in.
    assert len(noisy[1]) <= len(exact[1]) + 20
