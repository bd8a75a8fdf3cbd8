"""Named goals in world files: loading, the default goal, resolving names and coordinates."""
from __future__ import annotations

import numpy as np
import pytest

from amr_common.robot import ROBOT_RADIUS
from amr_common.world import World, WorldError, bundled_worlds

SQUARE = "boundary: [[0, 0], [2, 0], [2, 2], [0, 2]]\n"


def load(tmp_path, text):
    path = tmp_path / "goals_world.yaml"
    path.write_text(SQUARE + text)
    return World.load(str(path))


@pytest.mark.parametrize("name", bundled_worlds())
def test_every_bundled_world_names_goals_the_robot_fits_at(name):
    world = World.load(name)
    assert len(world.goals) >= 2
    assert world.goal in world.goals.values()
    for goal_name, (x, y) in world.goals.items():
        assert world.contains(x, y) and world.clearance(x, y) >= ROBOT_RADIUS, goal_name
        assert world.resolve_goal(goal_name) == (x, y)


def test_goal_key_names_the_default_and_the_first_named_goal_is_the_fallback(tmp_path):
    named = "goals: {a: [0.5, 0.5], b: [1.5, 1.5]}\n"
    assert load(tmp_path, named).goal == (0.5, 0.5)
    assert load(tmp_path, named + "goal: b\n").goal == (1.5, 1.5)
    assert load(tmp_path, named + "goal: [1.0, 1.2]\n").goal == (1.0, 1.2)
    plain = load(tmp_path, "goal: [1.0, 1.0]\n")
    assert plain.goal == (1.0, 1.0) and plain.goals == {}
    assert load(tmp_path, "").goal is None


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
        load(tmp_path, text)
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
