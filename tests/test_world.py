"""World loading: bundled worlds, the course's map JSON, named goals, clear WorldErrors."""
from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from amr_common.robot import ROBOT_RADIUS
from amr_common.world.world import GOAL_CLEARANCE, SAFETY_MARGIN, World, WorldError, bundled_worlds

REQUIRED_WORLDS = {"lab02", "corridor_loop", "maze_deadends", "room_obstacles", "wide_maze"}


def test_required_worlds_are_bundled():
    assert REQUIRED_WORLDS <= set(bundled_worlds())


@pytest.mark.parametrize("name", bundled_worlds())
def test_bundled_world_loads_closed_with_valid_starts(name):
    world = World.load(name)
    assert world.name == name
    assert world.segments.shape[1] == 4 and len(world.segments) >= 4
    assert world.boundary is not None and len(world.starts) >= 2
    for start_name, (x, y, theta) in world.starts.items():
        assert world.contains(x, y), start_name
        assert world.clearance(x, y) >= ROBOT_RADIUS, start_name
        assert world.resolve_start(start_name) == (x, y, theta)
    # Closed: a point just outside the boundary polygon is outside; the boundary polyline has no
    # gap
    xmin, ymin, xmax, ymax = world.bounds
    assert not world.contains(xmax + 0.01, 0.5 * (ymin + ymax))
    # Corridors no narrower than 0.4 m: every free cell centre keeps the robot off the walls.
    assert len(world.free_cells()) > 0


def test_lab02_has_the_course_starts_on_a_0_4_m_grid():
    world = World.load("lab02")
    assert world.starts["outer"] == pytest.approx((1.0, -1.0, math.pi / 2))
    assert world.starts["inner"] == pytest.approx((0.6, -0.6, 3 * math.pi / 2))
    grid = world.segments / 0.4
    assert np.allclose(grid, np.round(grid), atol=1e-9), "lab02 walls lie on multiples of 0.4 m"
    # Start poses sit in the middle of 0.4 m corridors: 0.2 m from the nearest wall.
    for x, y, _ in world.starts.values():
        assert world.clearance(x, y) == pytest.approx(0.2)


def test_course_map_json_loads(tmp_path):
    path = tmp_path / "map.json"
    path.write_text(json.dumps({"metric": {
        "boundary": [[0, 0], [2, 0], [2, 1], [0, 1]],
        "holes": [[[0.8, 0.4], [1.2, 0.4], [1.2, 0.6], [0.8, 0.6]]]}}))
    world = World.load(str(path))
    assert len(world.segments) == 8
    assert world.bounds == (0.0, 0.0, 2.0, 1.0)
    assert world.clearance(0.5, 0.5) == pytest.approx(0.3)
    assert world.resolve_start((0.3, 0.3, 0.0)) == (0.3, 0.3, 0.0)
    with pytest.raises(WorldError, match="inside obstacle"):
        world.resolve_start((1.0, 0.5, 0.0))


def test_yaml_world_with_pi_angles_open_walls_and_goal(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text("boundary: [[0, 0], [2, 0], [2, 2], [0, 2], [0, 0]]\n"
                    "walls: [[[1, 0], [1, 1.2]]]\n"
                    "starts: {a: [0.5, 0.5, 3*pi/2], b: [1.5, 0.5, -pi/4]}\n"
                    "goal: [1.5, 1.5]\n")
    world = World.load(path)
    assert world.name == "w" and len(world.segments) == 5  # the repeated closing point is dropped
    assert world.starts["a"][2] == pytest.approx(3 * math.pi / 2)
    assert world.starts["b"][2] == pytest.approx(-math.pi / 4)
    assert world.goal == (1.5, 1.5)


GOOD = "boundary: [[0, 0], [2, 0], [2, 2], [0, 2]]\n"


def test_numbers_with_an_exponent_and_no_dot_are_numbers(tmp_path):
    """YAML 1.1 reads 1e-6 as a string; a world file means the number."""
    path = tmp_path / "exponents.yaml"
    path.write_text("cell_size: 4e-1\nboundary: [[0, 0], [2E0, 0], [2, 2], [-1e-6, 2]]\n"
                    "starts: {a: [1, +1e0, 1e-6], b: [1.5e0, 1.5, -2.5E-1]}\n")
    world = World.load(path)
    assert world.cell_size == 0.4 and world.boundary[3].tolist() == [-1e-6, 2.0]
    assert world.starts == {"a": (1.0, 1.0, 1e-6), "b": (1.5, 1.5, -0.25)}
    path.write_text(GOOD + "description: 1e-6 is a number, and 'e5' stays a string\n"
                    "starts: {a: [1, 1, 'pi/2']}\n")
    assert World.load(path).starts["a"][2] == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("text, problem", [
    ("boundary: [[0, 0], [2, 0]\n", "invalid YAML"),
    ("- 1\n- 2\n", "expected a mapping"),
    ("starts: {a: [1, 1, 0]}\n", "missing key 'boundary'"),
    ("boundary: [[0, 0], [2, 0], [2, x], [0, 2]]\n", "must be a number"),
    ("boundary: [[0, 0], [2, 0], [2, .nan], [0, 2]]\n", "not finite"),
    ("boundary: [[0, 0], [2, 0], [2, .inf], [0, 2]]\n", "not finite"),
    ("boundary: [[0, 0], [2, 0, 1], [2, 2], [0, 2]]\n", r"must be \[x, y\]"),
    ("boundary: [[0, 0], [2, 0]]\n", "at least 3"),
    (GOOD + "walls: [[[1, 1]]]\n", "at least 2"),
    (GOOD + "walls: [[[1, 1], [1, 1], [1, 1.5]]]\n", "zero-length wall"),
    (GOOD + "holes: 3\n", "must be a list"),
    (GOOD + "starts: {a: [5, 5, 0]}\n", "outside the boundary"),
    (GOOD + "starts: {a: [0.05, 1, 0]}\n", "touches a wall"),
    (GOOD + "starts: {a: [0.1, 1, 0]}\n", "touches a wall"),
    (GOOD + "holes: [[[0.5, 0.5], [1.5, 0.5], [1.5, 1.5], [0.5, 1.5]]]\nstarts: {a: [1, 1, 0]}\n",
     "inside obstacle"),
    (GOOD + "starts: {a: [1, 1]}\n", r"must be \[x, y, theta\]"),
    (GOOD + "starts: {a: [1, 1, north]}\n", "theta must be a number"),
    (GOOD + "cell_size: -1\n", "must be > 0"),
    (GOOD + "goal: [9, 9]\n", "goal .* outside"),
    (GOOD + "colour: red\n", "unknown key"),
    # polygons that cannot be a map: a bowtie boundary, a self-crossing hole, holes outside
    # or across the boundary
    ("boundary: [[0, 0], [2, 2], [2, 0], [0, 2]]\n", "'boundary' crosses itself at"),
    ("boundary: [[0, 0], [2, 0], [2, 2], [0, 2]]\nholes: [[[0.5, 0.5], [1, 1], [1, 0.5], "
     "[0.5, 1]]]\n", r"'holes\[0\]' crosses itself"),
    ("boundary: [[0, 0], [2, 0], [2, 2], [0, 2]]\nholes: [[[3, 3], [4, 3], [4, 4]]]\n",
     r"'holes\[0\]' lies outside the boundary"),
    ("boundary: [[0, 0], [2, 0], [2, 2], [0, 2]]\nholes: [[[1.5, 0.5], [2.5, 0.5], "
     "[2.5, 1], [1.5, 1]]]\n", r"'holes\[0\]' crosses the boundary at"),
])
def test_malformed_yaml_gives_clear_error(tmp_path, text, problem):
    path = tmp_path / "bad_world.yaml"
    path.write_text(text)
    with pytest.raises(WorldError, match=problem) as info:
        World.load(str(path))
    assert "bad_world.yaml" in str(info.value)


@pytest.mark.parametrize("text, problem", [
    ("{not json", "invalid JSON"),
    ('{"map": {}}', "missing key 'metric'"),
    ('{"metric": {"holes": []}}', "missing key 'metric.boundary'"),
    ('{"metric": {"boundary": [[0, 0], [1, 0], [1, "a"]]}}', "must be a number"),
    ('{"metric": {"boundary": [[0, 0], [1, 0], [1, 1]], "holes": [[[0.2, 0.2]]]}}', "at least 3"),
])
def test_malformed_course_json_gives_clear_error(tmp_path, text, problem):
    path = tmp_path / "bad_map.json"
    path.write_text(text)
    with pytest.raises(WorldError, match=problem) as info:
        World.load(path)
    assert "bad_map.json" in str(info.value)


def test_missing_file_and_unknown_name(tmp_path):
    with pytest.raises(WorldError, match="not found") as info:
        World.load(str(tmp_path / "nowhere.yaml"))
    assert "nowhere.yaml" in str(info.value)
    with pytest.raises(WorldError, match="unknown world 'lab99'.*lab02"):
        World.load("lab99")


def test_resolve_start_rejects_bad_poses():
    world = World.load("lab02")
    with pytest.raises(WorldError, match="unknown start 'middle'.*outer"):
        world.resolve_start("middle")
    with pytest.raises(WorldError, match="touches a wall"):
        world.resolve_start((1.15, -1.0, 0.0))
    with pytest.raises(WorldError, match="not finite"):
        world.resolve_start((math.nan, 0.0, 0.0))
    assert world.resolve_start(None) == world.starts["outer"]


# --- named goals --------------------------------------------------------------------------

SQUARE = "boundary: [[0, 0], [2, 0], [2, 2], [0, 2]]\n"


def load_with_goals(tmp_path, text):
    path = tmp_path / "goals_world.yaml"
    path.write_text(SQUARE + text)
    return World.load(str(path))


@pytest.mark.parametrize("name", bundled_worlds())
def test_every_bundled_world_names_goals_the_robot_fits_at(name):
    world = World.load(name)
    assert len(world.goals) >= 2
    assert world.goal in world.goals.values()
    for goal_name, (x, y) in world.goals.items():
        assert world.contains(x, y) and world.clearance(x, y) >= GOAL_CLEARANCE, goal_name
        assert world.resolve_goal(goal_name) == (x, y)


def test_goal_key_names_the_default_and_the_first_named_goal_is_the_fallback(tmp_path):
    named = "goals: {a: [0.5, 0.5], b: [1.5, 1.5]}\n"
    assert load_with_goals(tmp_path, named).goal == (0.5, 0.5)
    assert load_with_goals(tmp_path, named + "goal: b\n").goal == (1.5, 1.5)
    assert load_with_goals(tmp_path, named + "goal: [1.0, 1.2]\n").goal == (1.0, 1.2)
    plain = load_with_goals(tmp_path, "goal: [1.0, 1.0]\n")
    assert plain.goal == (1.0, 1.0) and plain.goals == {}
    assert load_with_goals(tmp_path, "").goal is None


@pytest.mark.parametrize("text, problem", [
    ("goals: {a: [0.5, 0.5]}\ngoal: c\n", "goal 'c' is not a name of 'goals'"),
    ("goals: [[0.5, 0.5]]\n", "'goals' must be a mapping"),
    ("goals: {a: [0.5]}\n", r"goals.a must be \[x, y\]"),
    ("goals: {a: [5, 5]}\n", "goal 'a' .* outside the boundary"),
    ("goals: {a: [0.05, 1]}\n", "goal 'a' .* touches a wall"),
    ("goal: [1.95, 1]\n", "goal .* touches a wall"),
])
def test_malformed_goals_give_clear_errors(tmp_path, text, problem):
    with pytest.raises(WorldError, match=problem) as info:
        load_with_goals(tmp_path, text)
    assert "goals_world.yaml" in str(info.value)


def test_resolve_goal_takes_names_text_and_pairs():
    world = World.load("lab02")
    assert world.resolve_goal(None) == world.goal == world.goals["inner_far"]
    assert world.resolve_goal("north_west") == (-1.0, 1.0)
    assert world.resolve_goal("-1.0,0.6") == (-1.0, 0.6)  # negative numbers typed as is
    assert world.resolve_goal((1.0, 0.2)) == (1.0, 0.2)
    with pytest.raises(WorldError, match="neither a named goal .*inner_far"):
        world.resolve_goal("kitchen")
    with pytest.raises(WorldError, match="touches a wall"):
        world.resolve_goal("0.8,0.2")  # on a wall
    with pytest.raises(WorldError, match="outside the boundary"):
        world.resolve_goal((3.0, 0.0))


def test_contains_points_agrees_with_contains():
    world = World.load("room_obstacles")
    rng = np.random.default_rng(1)
    points = rng.uniform((-0.2, -0.2), (4.2, 3.2), size=(400, 2))
    expected = [world.contains(x, y) for x, y in points]
    assert world.contains_points(points).tolist() == expected


# --- one clearance rule for goals (the planner's inflated walls) ---------------------------

def test_a_goal_inside_the_planners_inflation_is_refused_with_the_rule():
    # 10.6 cm from lab02's east wall: the robot fits (10.5 cm) but no path reaches it without
    # leaving the planner's free space (13.5 cm); the CLI once accepted it and the run collided.
    world = World.load("lab02")
    with pytest.raises(WorldError, match=r"goal \(1.094, -0.2\) is too close to a wall: "
                                         r"clearance 0.106 m < 0.135 m"):
        world.resolve_goal("1.094,-0.2")
    assert GOAL_CLEARANCE == pytest.approx(ROBOT_RADIUS + SAFETY_MARGIN) == 0.135
    assert world.resolve_goal("1.065,-0.2") == (1.065, -0.2)  # 13.5 cm: on the edge, fine
    # A start may be anywhere the robot fits: the robot is there.
    assert world.resolve_start((1.094, -0.2, 0.0)) == (1.094, -0.2, 0.0)


def test_a_named_goal_inside_the_inflation_is_refused_when_the_world_loads(tmp_path):
    with pytest.raises(WorldError, match=r"goal 'a' \(0.12, 1\) is too close to a wall"):
        load_with_goals(tmp_path, "goals: {a: [0.12, 1]}\n")


@pytest.mark.parametrize("what", ["goal", "start"])
def test_huge_coordinates_are_outside_without_a_numpy_warning(what):
    world = World.load("lab02")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an overflow warning would fail here
        with pytest.raises(WorldError, match="outside the boundary"):
            if what == "goal":
                world.resolve_goal("1e308,1e308")
            else:
                world.resolve_start((1e308, -1e308, 0.0))


def test_a_pose_checked_for_another_purpose_is_named_so():
    with pytest.raises(WorldError, match=r"kidnap pose \(0, 0\) touches a wall"):
        World.load("lab02").resolve_start((0.0, 0.0, 0.0), what="kidnap pose")


# --- polygons: touching is fine -----------------------------------------------------------

def test_holes_may_touch_the_boundary_and_walls_may_cross_anything(tmp_path):
    path = tmp_path / "touching.yaml"
    path.write_text("boundary: [[0, 0], [2, 0], [2, 2], [0, 2]]\n"
                    "holes: [[[0, 0.5], [0.5, 0.5], [0.5, 1], [0, 1]]]\n"  # flush, west wall
                    "walls: [[[1, 1], [1.5, 1.5]], [[1, 1.5], [1.5, 1]]]\n")  # an X of walls
    world = World.load(str(path))
    assert not world.contains(0.25, 0.75) and world.contains(1.5, 0.5)
