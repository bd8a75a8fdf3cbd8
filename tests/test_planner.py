"""The planner: clearance, optimality, compiled = Python, clear errors.

Clearance-keeping paths on every bundled world, optimality against Dijkstra on the same grid,
compiled and Python searches agreeing, and clear errors for impossible goals.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from amr_common.world.world import GOAL_CLEARANCE, World, bundled_worlds
from amr_planning import search
from amr_planning.planner import Planner, PlanningError

COURSE_STYLE = ["lab02", "maze_deadends"]  # 0.4 m corridors on a 0.4 m grid
LENGTH_FACTOR = 1.15  # planned length <= this x the shortest path of a Dijkstra on the same grid


def densify(points: np.ndarray, step: float = 0.005) -> np.ndarray:
    pieces = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, math.ceil(np.hypot(*(b - a)) / step))
        pieces.append(a + (b - a) * np.arange(1, n + 1)[:, None] / n)
    return np.vstack(pieces)


def pairs(world: World):
    return [(s[:2], g) for s, g in itertools.product(world.starts.values(), world.goals.values())
            if math.dist(s[:2], g) > 0.05]


@pytest.fixture(scope="module")
def planners():
    return {name: Planner(World.load(name)) for name in bundled_worlds()}


@pytest.mark.parametrize("name", bundled_worlds())
def test_paths_avoid_the_inflated_walls_on_every_bundled_world(planners, name):
    planner = planners[name]
    world = planner.world
    for start, goal in pairs(world):
        plan = planner.plan(start, goal)
        assert plan.points[0] == pytest.approx(start) and plan.points[-1] == pytest.approx(goal)
        cells = [planner.cell_index(x, y) for x, y in plan.grid_path]
        assert np.isfinite(planner.cost[cells]).all(), "the grid path uses inflated cells"
        clearance = world.clearances(densify(plan.points))
        assert clearance.min() >= planner.inflation_radius - 1e-9, (start, goal)
        assert plan.min_clearance_m == pytest.approx(
            world.clearances(plan.points).min())
        steps = np.hypot(*np.diff(plan.points, axis=0).T)
        assert steps.max() <= planner.params["path_spacing_m"] + 1e-9


@pytest.mark.parametrize("name", COURSE_STYLE)
def test_paths_keep_15_cm_from_the_walls_of_0_4_m_corridors(planners, name):
    planner = planners[name]
    for start, goal in pairs(planner.world):
        clearance = planner.world.clearances(densify(planner.plan(start, goal).points))
        assert clearance.min() >= 0.15, (start, goal, clearance.min())


@pytest.mark.parametrize("name", bundled_worlds())
def test_astar_is_optimal_against_dijkstra_on_the_same_grid(planners, name):
    planner = planners[name]
    shortest = Planner(planner.world, clearance_weight=0.0)
    for start, goal in pairs(planner.world):
        cells = planner.cell_index(*start), planner.cell_index(*goal)
        _, cost, expanded = planner.search(*cells)
        _, dijkstra_cost, dijkstra_expanded = planner.search(*cells, heuristic_weight=0.0)
        assert cost == pytest.approx(dijkstra_cost, rel=1e-12)
        assert expanded <= dijkstra_expanded
        _, weighted_cost, _ = planner.search(*cells, heuristic_weight=1.5)
        assert dijkstra_cost - 1e-9 <= weighted_cost <= 1.5 * dijkstra_cost
        # Length: the centred, smoothed path against Dijkstra's shortest grid path.
        path, _, _ = shortest.search(*cells, heuristic_weight=0.0)
        centres = shortest.grid.cell_centres(*np.divmod(path, shortest.grid.width))
        dijkstra_length = np.hypot(*np.diff(centres, axis=0).T).sum()
        assert planner.plan(start, goal).length_m <= LENGTH_FACTOR * dijkstra_length + 0.05


@pytest.mark.parametrize("algorithm", ["astar", "wavefront"])
def test_compiled_and_python_searches_give_the_same_path(planners, algorithm):
    planner = planners["lab02"]
    world = planner.world
    cells = planner.cell_index(*world.starts["outer"][:2]), planner.cell_index(*world.goal)
    compiled = planner.search(*cells, algorithm=algorithm)
    python = planner.search(*cells, algorithm=algorithm, compiled=False)
    assert np.array_equal(compiled[0], python[0])
    assert compiled[1:] == python[1:]


def test_the_clearance_cost_keeps_paths_away_from_walls_that_the_wavefront_brushes(planners):
    world = World.load("lab02")
    wavefront = Planner(world, algorithm="wavefront")
    start, goal = world.starts["outer"][:2], world.goal
    astar_path = planners["lab02"].plan(start, goal)
    wave_path = wavefront.plan(start, goal)
    assert wave_path.points[-1] == pytest.approx(goal)
    # The wave's grid path hugs the inflation (13.5 cm); the cost keeps A* on the centre line.
    assert world.clearances(wave_path.grid_path).min() < 0.145
    assert world.clearances(astar_path.grid_path).min() >= 0.199


def test_a_start_inside_the_inflation_is_connected_to_the_nearest_free_cell(planners):
    planner = planners["lab02"]
    start = (1.0, -1.08)  # 12 cm from the south wall: inside the 13.5 cm inflation
    plan = planner.plan(start, (1.0, 1.0))
    assert plan.points[0] == pytest.approx(start)
    assert planner.world.clearances(densify(plan.points)).min() >= 0.12 - 1e-9
    touching = (1.0, -1.11)  # the robot overlaps the wall by 1.5 cm (a bad estimate): still out
    assert planner.plan(touching, (1.0, 1.0)).points[0] == pytest.approx(touching)


@pytest.mark.parametrize("world, goal, problem", [
    ("room_obstacles", (1.1, 1.0), r"goal \(1.100, 1.000\) is inside a wall or outside the map"),
    ("lab02", (5.0, 5.0), "goal .* inside a wall or outside the map"),
    ("lab02", (0.0, -0.8), r"goal \(0.000, -0.800\) is on a wall"),  # a free-standing wall
    ("lab02", (1.0, -1.1), "goal .* touches a wall: clearance 0.100 m < robot radius"),
    ("lab02", (float("nan"), 0.0), "goal .* not finite"),
    ("lab02", (1.0,), r"goal must be \(x, y\)"),
])
def test_impossible_goals_give_clear_errors(planners, world, goal, problem):
    start = planners[world].world.resolve_start(None)[:2]
    with pytest.raises(PlanningError, match=problem):
        planners[world].plan(start, goal)


def test_a_goal_inside_the_inflation_is_an_error_not_a_straight_line_through_it(planners):
    # The robot fits there (10.6 cm > 10.5 cm) but the walls are inflated by 13.5 cm: the path
    # once ended with a straight piece through the inflation, and the run collided.
    planner = planners["lab02"]
    with pytest.raises(PlanningError, match=r"goal \(1.094, -0.2\) is too close to a wall: "
                                            r"clearance 0.106 m < 0.135 m"):
        planner.plan((1.0, -1.0), (1.094, -0.2))
    margin = Planner(planner.world, safety_margin_m=0.05)  # the planner's own inflation counts
    with pytest.raises(PlanningError, match="clearance 0.140 m < 0.155 m"):
        margin.plan((1.0, -1.0), (1.06, -0.2))


@pytest.mark.parametrize("world", ["lab02", "room_obstacles"])
def test_paths_to_goals_on_the_inflation_edge_never_leave_the_free_space(planners, world):
    planner = planners[world]
    rng = np.random.default_rng(3)
    xmin, ymin, xmax, ymax = planner.world.bounds
    points = rng.uniform((xmin, ymin), (xmax, ymax), size=(20000, 2))
    clearance = planner.world.clearances(points)
    edge = points[(clearance >= GOAL_CLEARANCE) & (clearance < GOAL_CLEARANCE + 0.01)
                  & planner.world.contains_points(points)][:25]
    start = planner.world.resolve_start(None)[:2]
    for goal in edge:
        try:
            plan = planner.plan(start, goal)
        except PlanningError as exc:  # unreachable pockets are fine; leaving the space is not
            assert "unreachable" in str(exc)
            continue
        assert planner.world.clearances(densify(plan.points)).min() >= GOAL_CLEARANCE - 1e-3


def test_a_goal_behind_a_gap_narrower_than_the_robot_is_unreachable(tmp_path):
    path = tmp_path / "two_rooms.yaml"
    path.write_text("boundary: [[0, 0], [2, 0], [2, 1], [0, 1]]\n"
                    "walls: [[[1, 0], [1, 0.4]], [[1, 0.62], [1, 1]]]\n")  # a 22 cm gap
    planner = Planner(World.load(str(path)))
    with pytest.raises(PlanningError, match=r"goal \(1.500, 0.500\) is unreachable from start "
                                            r"\(0.500, 0.500\)"):
        planner.plan((0.5, 0.5), (1.5, 0.5))
    assert planner.plan((0.5, 0.5), (0.5, 0.8)).length_m == pytest.approx(0.3, abs=0.02)


def test_start_equal_to_goal_is_a_single_point_path(planners):
    plan = planners["lab02"].plan((1.0, -1.0), (1.0, -1.0))
    assert len(plan.points) == 1 and plan.length_m == 0.0


@pytest.mark.parametrize("params, problem", [
    ({"algorithm": "dfs"}, "algorithm must be one of"),
    ({"resolution_m": 0.0}, "resolution_m must be > 0"),
    ({"safety_margin_m": float("inf")}, "safety_margin_m must be a finite number"),
    ({"preferred_clearance_m": 0.1}, "must exceed robot_radius_m"),
    ({"heuristic_weight": 0.5}, "heuristic_weight must be 0"),
    ({"turbo": True}, "unknown parameter"),
])
def test_bad_parameters_are_clear_errors(params, problem):
    with pytest.raises(ValueError, match=problem):
        Planner(World.load("lab02"), **params)


def test_trace_back_refuses_a_broken_chain():
    came_from = np.array([-1, -1, 1], dtype=np.int64)
    assert search.trace_back(came_from, 1, 2).tolist() == [1, 2]
    with pytest.raises(RuntimeError):
        search.trace_back(came_from, 0, 2)
