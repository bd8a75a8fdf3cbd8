"""The wall-following algorithm on synthetic scans (no ROS): decisions, robustness, limits."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from amr_control.wall_follower import WallFollower
from tests.scan_helpers import COURSE_240, LDS01_360, LDS02_ODD, cast

DT = 0.05
REPO = Path(__file__).resolve().parent.parent


def make(layout=COURSE_240, **params):
    wf = WallFollower(DT, **params)
    n, angle_min, range_min, range_max, _ = layout
    wf.set_scan_geometry(angle_min, 2.0 * math.pi / n, range_min, range_max)
    return wf


def drive(wf, segments, layout=COURSE_240, pose=(0.0, 0.0, 0.0), steps=100, rays=None):
    """Closed loop on an ideal unicycle: returns the poses, commands and states."""
    x, y, th = pose
    v = w = 0.0
    log = []
    for k in range(steps):
        n = rays(k) if callable(rays) else rays
        if n is not None:
            wf.set_scan_geometry(layout[1], 2.0 * math.pi / n, layout[2], layout[3])
        scan = cast(segments, layout, (x, y, th), rays=n)
        v, w = wf.compute_commands(scan, v, w)
        log.append(((x, y, th), (v, w), wf.state))
        x += v * DT * math.cos(th + 0.5 * w * DT)
        y += v * DT * math.sin(th + 0.5 * w * DT)
        th += w * DT
    return log


def right_wall(d=0.2):
    return [[-3.0, -d, 3.0, -d]]


def left_wall(d=0.2):
    return [[-3.0, d, 3.0, d]]


LAYOUTS = [COURSE_240, LDS01_360, LDS02_ODD]


# ---- straight walls -----------------------------------------------------------------------
@pytest.mark.parametrize("layout", LAYOUTS)
def test_straight_wall_on_the_right_drives_forward_and_corrects_toward_target(layout):
    for distance, sign in ((0.2, 0), (0.26, -1), (0.15, +1)):
        wf = make(layout)
        v, w = wf.compute_commands(cast(right_wall(distance), layout), 0.0, 0.0)
        assert wf.state == "follow_wall"
        assert v > 0.1
        assert wf.wall_distance_error == pytest.approx(distance - 0.2, abs=0.005)
        if sign == 0:
            assert abs(w) < 0.05
        else:
            assert w * sign > 0.2, (distance, w)   # too far: turn right (toward the wall)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_straight_wall_on_the_left_mirrors_when_following_left(layout):
    wf = make(layout, follow_side="left")
    v, w = wf.compute_commands(cast(left_wall(0.26), layout), 0.0, 0.0)
    assert v > 0.1 and w > 0.2                     # too far from the left wall: turn left
    wf = make(layout, follow_side="left")
    v, w = wf.compute_commands(cast(left_wall(0.15), layout), 0.0, 0.0)
    assert v > 0.1 and w < -0.2


def test_wall_distance_converges_in_closed_loop():
    wf = make()
    log = drive(wf, right_wall(0.2), pose=(-2.5, 0.07, 0.2), steps=200)   # 13 cm off, angled
    final_y = log[-1][0][1]
    assert final_y == pytest.approx(0.0, abs=0.01)  # 0.2 m from the wall at y = -0.2
    assert all(abs(p[1]) < 0.1 for p, _, _ in log)  # never closer than 0.1 m to the wall


# ---- corners, dead ends, junctions ----------------------------------------------------------
@pytest.mark.parametrize("layout", LAYOUTS)
def test_inner_corner_turns_away_from_the_wall_in_place(layout):
    walls = [[-3.0, -0.2, 0.2, -0.2], [0.2, -0.2, 0.2, 3.0]]   # right wall, then a wall ahead
    wf = make(layout)
    v, w = wf.compute_commands(cast(walls, layout, (0.005, 0.0, 0.0)), 0.0, 0.0)
    assert wf.state == "turn_inner"
    assert v == 0.0 and w > 0.3


@pytest.mark.parametrize("layout", LAYOUTS)
def test_outer_corner_goes_forward_then_turns_toward_the_wall(layout):
    walls = [[-3.0, -0.2, 0.0, -0.2], [0.0, -0.2, 0.0, -3.0]]   # the right wall turns away
    wf = make(layout)
    log = drive(wf, walls, layout, pose=(-0.6, 0.0, 0.0), steps=120)
    states = [s for _, _, s in log]
    first_turn = states.index("turn_outer")
    assert "outer_corner" in states[:first_turn]
    x_at_turn = log[first_turn][0][0]
    assert x_at_turn == pytest.approx(0.2, abs=0.03)    # the corner + wall_distance_m
    v, w = log[first_turn][1]
    assert v == 0.0 and w < -0.3                        # turning right, in place
    # Around the corner it follows the new wall (x = 0) at 0.2 m, heading south.
    (x, y, th), _, state = log[-1]
    assert state in ("approach", "follow_wall")
    assert x == pytest.approx(0.2, abs=0.03) and math.cos(th + math.pi / 2) > 0.98


@pytest.mark.parametrize("layout", LAYOUTS)
def test_dead_end_turns_around_in_place(layout):
    walls = [[-3.0, -0.2, 0.2, -0.2], [0.2, -0.2, 0.2, 0.2], [-3.0, 0.2, 0.2, 0.2]]
    wf = make(layout)
    log = drive(wf, walls, layout, pose=(-0.3, 0.0, 0.0), steps=120)
    states = [s for _, _, s in log]
    k = states.index("turn_around")
    assert log[k][1][0] == 0.0 and log[k][1][1] > 0.3   # in place, away from the right wall
    # It comes back out heading west, never touching the walls.
    (x, y, th), (v, _), _ = log[-1]
    assert math.cos(th) < -0.98 and v > 0.0
    assert max(p[0] for p, _, _ in log) < 0.2 - 0.105 - 0.03


def t_junction():
    """A stem corridor (x < 0, |y| < 0.2) ending at a crossing corridor (0 < x < 0.4)."""
    return [[-3.0, -0.2, 0.0, -0.2], [0.0, -0.2, 0.0, -3.0],     # stem's right wall, corner
            [-3.0, 0.2, 0.0, 0.2], [0.0, 0.2, 0.0, 3.0],         # stem's left wall, corner
            [0.4, -3.0, 0.4, 3.0]]                               # far wall of the crossing


@pytest.mark.parametrize("side, expected_turn_sign", [("right", -1), ("left", +1)])
def test_t_junction_takes_the_followed_side_deterministically(side, expected_turn_sign):
    runs = []
    for _ in range(2):
        wf = make(follow_side=side)
        log = drive(wf, t_junction(), pose=(-0.8, 0.0, 0.0), steps=220)
        runs.append([cmd for _, cmd, _ in log])
        (x, y, th), _, _ = log[-1]
        # Right-hand rule: into the right (south) branch; left-hand: the north branch.
        assert x == pytest.approx(0.2, abs=0.04)
        assert y * expected_turn_sign > 0.2
    assert runs[0] == runs[1]   # no randomness


# ---- invalid data ---------------------------------------------------------------------------
def test_all_invalid_scan_gives_a_safe_finite_command_and_nothing_touching():
    n = 240
    mixes = [np.full(n, np.nan), np.zeros(n), np.full(n, np.inf),
             np.tile([np.nan, 0.0, np.inf, -1.0, 1e9], n // 5)]
    for scan in mixes:
        wf = make()
        v, w = wf.compute_commands(scan, 0.0, 0.0)
        assert math.isfinite(v) and math.isfinite(w)
        assert (v, w) == (0.0, 0.0)
        assert wf.state == "no_data"
        assert all(d == math.inf for d in wf.distances.values())   # open, never "touching"


def test_invalid_sectors_are_open_not_touching():
    scan = cast(right_wall(0.2), COURSE_240)
    scan[100:140] = 0.0                       # no return behind-left: must read as open
    wf = make()
    v, w = wf.compute_commands(scan, 0.0, 0.0)
    assert wf.state == "follow_wall" and v > 0.1
    assert wf.distances["back"] == math.inf


def test_close_wall_going_invalid_is_still_a_wall():
    # LDS-01: a wall closer than 0.12 m reads 0.0. Right after it was seen close, the rays
    # going invalid must not turn it into open space (no outer corner toward it).
    wf = make(LDS01_360)
    scan = cast(right_wall(0.15), LDS01_360)
    wf.compute_commands(scan, 0.0, 0.0)
    blind = scan.copy()
    blind[200:340] = 0.0                      # everything on the right side stops returning
    for _ in range(4):
        v, w = wf.compute_commands(blind + 0.0, 0.0, 0.0)
        assert wf.state == "follow_wall"
        assert wf.distances["right"] < 0.2
        assert w > 0.0                        # too close: steer away from it


# ---- scan layouts ---------------------------------------------------------------------------
def test_layouts_240_360_and_variable_lds02_give_the_same_decisions():
    scenes = {
        "straight": (right_wall(0.24), (0.0, 0.0, 0.0)),
        "inner": ([[-3.0, -0.2, 0.2, -0.2], [0.2, -0.2, 0.2, 3.0]], (0.0, 0.0, 0.0)),
        "outer": ([[-3.0, -0.2, 0.0, -0.2], [0.0, -0.2, 0.0, -3.0]], (-0.3, 0.0, 0.0)),
        "dead_end": ([[-3.0, -0.2, 0.2, -0.2], [0.2, -0.2, 0.2, 0.2], [-3.0, 0.2, 0.2, 0.2]],
                     (-0.3, 0.0, 0.0)),
    }
    for name, (walls, pose) in scenes.items():
        outcomes = []
        for layout, rays in ((COURSE_240, None), (LDS01_360, None),
                             (LDS02_ODD, lambda k: 445 + (k * 7) % 11)):   # count varies
            wf = make(layout)
            log = drive(wf, walls, layout, pose=pose, steps=60, rays=rays)
            states = [s for _, _, s in log]
            outcomes.append((list(dict.fromkeys(states)), round(log[-1][0][0], 1),
                             round(log[-1][0][1], 1), round(math.cos(log[-1][0][2]), 1)))
        assert outcomes[0] == outcomes[1] == outcomes[2], (name, outcomes)


def test_without_geometry_the_course_convention_is_used():
    scan = cast(right_wall(0.26), COURSE_240)
    wf = WallFollower(DT)                     # no set_scan_geometry: ray 0 ahead, CCW
    v, w = wf.compute_commands(list(scan), 0.0, 0.0)
    assert v > 0.1 and w < -0.2


def test_geometry_disagreeing_with_the_scan_length_uses_the_given_angles():
    wf = WallFollower(DT)
    wf.set_scan_geometry(0.0, 2.0 * math.pi / 360, 0.12, 3.5)
    scan = cast(right_wall(0.26), LDS01_360)[:300]   # truncated scan, angles still 1 deg
    v, w = wf.compute_commands(scan, 0.0, 0.0)
    assert v > 0.1 and w < -0.2


def test_absurd_geometry_is_ignored():
    wf = WallFollower(DT)
    wf.set_scan_geometry(float("nan"), 0.0, 5.0, 1.0)
    v, w = wf.compute_commands(cast(right_wall(0.26), COURSE_240), 0.0, 0.0)
    assert v > 0.1 and w < -0.2


# ---- limits and safety ----------------------------------------------------------------------
def test_outputs_stay_finite_and_within_limits_on_random_garbage():
    rng = np.random.default_rng(1234)
    wf = make()
    for _ in range(600):
        n = int(rng.integers(0, 500))
        kind = rng.integers(0, 4)
        if kind == 0:
            scan = rng.uniform(-1.0, 10.0, n)
        elif kind == 1:
            scan = rng.choice([np.nan, np.inf, -np.inf, 0.0, 0.01, 0.2, 1e12, -5.0], n)
        elif kind == 2:
            scan = rng.uniform(0.0, 0.3, n)
        else:
            scan = [None, "x", {}, 3.0][int(rng.integers(0, 4))]
        if rng.random() < 0.2:
            wf.set_scan_geometry(rng.uniform(-7, 7), rng.uniform(-0.1, 0.1),
                                 rng.uniform(0, 1), rng.uniform(0, 10))
        z_v = rng.choice([np.nan, np.inf, rng.uniform(-1, 1)])
        z_w = rng.choice([np.nan, -np.inf, rng.uniform(-5, 5)])
        v, w = wf.compute_commands(scan, z_v, z_w)
        assert math.isfinite(v) and math.isfinite(w)
        assert abs(v) <= 0.22 and abs(w) <= 2.84
        # Both wheels within 0.22 m/s (track 0.16 m).
        assert abs(v) + abs(w) * 0.08 <= 0.22 + 1e-9


def test_never_drives_forward_into_a_close_obstacle():
    for distance in (0.10, 0.14):
        wf = make()
        walls = right_wall(0.2) + [[distance, -0.5, distance, 0.5]]
        v, _ = wf.compute_commands(cast(walls, COURSE_240), 0.0, 0.0)
        assert v <= 0.0


def test_a_thin_wall_end_seen_end_on_still_blocks_the_path():
    """The end of a zero-thickness wall, once the robot is on the wall's line, returns no ray.

    Every ray passes beside it (lab02 with its inner wall 5 cm north: the robot turned in the
    gap at (0.2, 0) toward the wall ending at (0, 0), drove on and touched it). The tip was in
    the scans taken from beside the line: it must stay an obstacle in the swept path.
    """
    wf = make(LDS01_360)
    walls = [[0.4, 0.0, 1.5, 0.0],            # the thin wall along the robot's future line
             [1.5, -1.0, 1.5, 1.0]]           # what the rays passing beside its end hit
    x, y, th = 0.0, 0.2 * math.sin(0.5), 0.0  # beside the line: the wall's end is seen
    moves = [(0.0, -1.0)] * 10 + [(0.2, 0.0)] * 20 + [(0.0, 1.0)] * 10   # onto the line
    v, w = 0.0, 0.0
    for v, w in moves:
        wf.compute_commands(cast(walls, LDS01_360, (x, y, th)), v, w)
        x += v * DT * math.cos(th + 0.5 * w * DT)
        y += v * DT * math.sin(th + 0.5 * w * DT)
        th += w * DT
    assert abs(y) < 1e-9 and abs(th) < 1e-9
    last = cast(walls, LDS01_360, (x, y, th))
    assert 0.0 < last[0] and abs(last[0] - (1.5 - x)) < 1e-9   # ray 0 passes the end
    v, _ = wf.compute_commands(last, v, w)
    assert wf.distances["path"] <= 0.4 - x + 0.01
    assert v <= 0.1


def test_slows_down_as_the_front_gap_closes():
    speeds = []
    for distance in (1.0, 0.29, 0.26, 0.23):
        wf = make()
        walls = right_wall(0.2) + [[distance, -0.1, distance, 0.5]]
        v, _ = wf.compute_commands(cast(walls, COURSE_240), 0.0, 0.0)
        speeds.append(v)
    assert speeds[0] == pytest.approx(0.2)
    assert speeds[0] > speeds[1] > speeds[2] > speeds[3] > 0.0


def test_exposes_state_and_wall_error_only_on_a_straight_wall():
    wf = make()
    wf.compute_commands(cast(right_wall(0.2), COURSE_240), 0.0, 0.0)
    assert isinstance(wf.wall_distance_error, float)
    walls = [[-3.0, -0.2, 0.2, -0.2], [0.2, -0.2, 0.2, 3.0]]
    wf.compute_commands(cast(walls, COURSE_240, (0.005, 0.0, 0.0)), 0.0, 0.0)
    assert wf.state == "turn_inner" and wf.wall_distance_error is None


# ---- parameters -----------------------------------------------------------------------------
def test_parameter_descriptions_cover_the_constructor_and_have_units():
    described = WallFollower.parameter_descriptions()
    assert {"wall_distance_m", "kp", "kd", "front_stop_distance_m", "max_linear_speed_mps",
            "turn_speed_radps", "settle_time_s", "sector_half_width_rad", "follow_side",
            "range_min_m", "range_max_m"} <= set(described)
    for name, (default, description) in described.items():
        assert isinstance(description, str) and len(description) > 10, name
        assert isinstance(default, (bool, int, float, str)), name
    WallFollower(DT, **{name: default for name, (default, _) in described.items()})


@pytest.mark.parametrize("bad", [{"follow_side": "up"}, {"kp": float("nan")}, {"kp": "fast"},
                                 {"wall_distance": 0.2}, {"front_stop_distance_m": 0.5},
                                 {"sector_half_width_rad": 0.0}, {"sector_half_width_rad": 2.0}])
def test_bad_parameters_raise_clear_errors(bad):
    with pytest.raises(ValueError, match="WallFollower"):
        WallFollower(DT, **bad)


@pytest.mark.parametrize("dt", [0.0, -0.05, float("nan")])
def test_bad_dt_raises(dt):
    with pytest.raises(ValueError, match="dt"):
        WallFollower(dt)


@pytest.mark.parametrize("name, simulation, slop", [("sim.yaml", True, 10.0),
                                                    ("turtlebot3.yaml", False, 0.15)])
def test_params_files_are_ros2_params_files_the_follower_accepts(name, simulation, slop):
    data = yaml.safe_load((REPO / "amr_control" / "params" / name).read_text())
    params = data["wall_follower"]["ros__parameters"]
    node_keys = {"simulation", "dt", "queue_size", "slop", "enable_localization",
                 "stop_when_localized", "cmd_vel_stamped", "angular_sign", "data_timeout",
                 "controller"}
    assert node_keys <= set(params)
    assert params["simulation"] is simulation and params["slop"] == slop
    tuning = {k: v for k, v in params.items() if k not in node_keys}
    described = WallFollower.parameter_descriptions()
    # sim.yaml leaves the LiDAR position and timing to run_sim.py / evaluate.py (the
    # profile's); the robot file states the real Burger's.
    expected = set(described) - ({"lidar_offset_x_m", "scan_revolution_s"} if simulation
                                 else set())
    assert set(tuning) == expected
    if not simulation:
        assert tuning["lidar_offset_x_m"] == -0.032
        assert tuning["scan_revolution_s"] == 0.2
    for key, value in tuning.items():   # same ROS type as the declared default
        assert type(value) is type(described[key][0]), key
    WallFollower(params["dt"], **tuning)


def test_repeated_bad_scans_and_geometry_warn_once_per_kind(caplog):
    wf = make()
    good = cast(right_wall(0.26), COURSE_240)
    with caplog.at_level("WARNING", logger="amr_control"):
        for _ in range(50):
            wf.set_scan_geometry(0.0, 2.0 * math.pi / 240, math.nan, 8.0)
            wf.compute_commands([0.5], 0.0, 0.0)
            wf.compute_commands(good, 0.0, 0.0)
    messages = [r.getMessage() for r in caplog.records]
    assert sum("geometry" in m for m in messages) == 1, messages
    assert sum("readings" in m for m in messages) == 1, messages


def test_look_around_chooses_the_open_wall_direction_or_the_longest_path():
    from amr_control.look_around import LookAround
    from amr_control.scan_sectors import WallFit

    look = LookAround()
    headings = np.linspace(0.0, 2.0 * math.pi, 84, endpoint=False)
    walls = math.radians(40.0)   # the walls run at 40 deg (+ quarter turns) in this frame
    for heading in headings:
        # Longest path along 220 deg, a longer one still on a diagonal (85 deg).
        path = 1.5 if abs(math.remainder(heading - math.radians(220.0), 2 * math.pi)) < 0.04 \
            else 2.0 if abs(math.remainder(heading - math.radians(85.0), 2 * math.pi)) < 0.04 \
            else 0.2
        fit = WallFit(0.2, math.remainder(walls - heading, 0.5 * math.pi), 0.005, 0.3, 20)
        look.observe(heading, path, fit)
    assert look.saw_walls
    assert math.remainder(look.choose() - math.radians(220.0), 2 * math.pi) == \
        pytest.approx(0.0, abs=1e-9)
    blind = LookAround()
    for heading in headings:
        blind.observe(heading, 2.0 if abs(heading - math.radians(85.0)) < 0.04 else 0.2)
    assert not blind.saw_walls
    assert abs(blind.choose() - math.radians(85.0)) < 0.04
    assert math.isnan(LookAround().choose())
