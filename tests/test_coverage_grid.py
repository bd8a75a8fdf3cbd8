"""The coverage grid behind "explored" and "laps".

Aligned with the map, rasterized (big and fine worlds report in seconds), bounded with a clear
error, and a metric that cannot be computed is reported as such while the rest of the report
is kept.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.robot import ROBOT_RADIUS
from amr_common.world.coverage_grid import MAX_GRID_CELLS, GridTooLargeError
from amr_common.world.world import World
from amr_evaluation.episode import count_laps, explored_fraction, run_episode

REPO = Path(__file__).resolve().parent.parent

# A course-style 2 x 2 m map: boundary at +-1.0 m, a 0.4 m corridor ring around a 1.2 m block.
# Its corridors are centred on multiples of 0.4 m: a grid of centres (k + 0.5) * 0.4 would put
# every centre on a wall.
COURSE_STYLE = """\
cell_size: 0.4
boundary: [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
holes:
  - [[-0.6, -0.6], [0.6, -0.6], [0.6, 0.6], [-0.6, 0.6]]
starts:
  east: [0.8, 0.0, pi/2]
"""

# +-1e6 m: a 0.4 m grid would have 2.5e13 cells (182 TiB of booleans and centres).
HUGE_WORLD = ("boundary: [[-1.0e+6, -1.0e+6], [1.0e+6, -1.0e+6], [1.0e+6, 1.0e+6], "
              "[-1.0e+6, 1.0e+6]]\nstarts: {a: [0, 0, 0]}\n")


def course_style_world(tmp_path, extra: str = "") -> World:
    path = tmp_path / "course_style.yaml"
    path.write_text(COURSE_STYLE + extra)
    return World.load(path)


def ring_positions(samples: int = 400) -> np.ndarray:
    """One lap along the middle of the corridor ring (the square of half-side 0.8 m)."""
    s = np.linspace(0.0, 4.0, samples, endpoint=False)
    side, t = np.floor(s).astype(int), s % 1.0
    corners = np.array([[0.8, -0.8], [0.8, 0.8], [-0.8, 0.8], [-0.8, -0.8], [0.8, -0.8]])
    return corners[side] + (corners[side + 1] - corners[side]) * t[:, None]


def inside(polygon: np.ndarray, x: float, y: float) -> bool:
    """Even-odd ray crossing test of one point, edge by edge."""
    count = 0
    for (px, py), (qx, qy) in zip(polygon, np.roll(polygon, -1, axis=0)):
        if (py > y) != (qy > y) and x < px + (y - py) * (qx - px) / (qy - py):
            count += 1
    return count % 2 == 1


def reference_free_cells(world: World, origin: tuple[float, float]) -> np.ndarray:
    """The definition, cell by cell.

    Centre inside the boundary, outside every hole, clearance above the robot radius.
    """
    (xmin, ymin), (xmax, ymax) = world.boundary.min(axis=0), world.boundary.max(axis=0)
    cs = world.cell_size
    xs = origin[0] + (np.arange(math.floor((xmin - origin[0]) / cs + 1e-9),
                                math.ceil((xmax - origin[0]) / cs - 1e-9)) + 0.5) * cs
    ys = origin[1] + (np.arange(math.floor((ymin - origin[1]) / cs + 1e-9),
                                math.ceil((ymax - origin[1]) / cs - 1e-9)) + 0.5) * cs
    cells = [(x, y) for y in ys for x in xs
             if inside(world.boundary, x, y) and not any(inside(h, x, y) for h in world.holes)
             and world.clearance(x, y) > ROBOT_RADIUS]
    return np.array(cells).reshape(-1, 2)


# ---- B12: the grid follows the map -------------------------------------------------------------
def test_course_style_corridors_count_as_free_cells(tmp_path):
    world = course_style_world(tmp_path)
    cells = world.free_cells()
    assert len(cells) == 16   # the whole ring, one cell per 0.4 m of corridor
    assert np.all(np.isclose(np.abs(cells).max(axis=1), 0.8))
    assert explored_fraction(world, ring_positions()) == pytest.approx(1.0)
    assert explored_fraction(world, ring_positions()[:100]) == pytest.approx(5 / 16)
    assert count_laps(world, ring_positions()) == 0   # 399 of 400 samples: not quite a lap
    assert count_laps(world, np.vstack([ring_positions()] * 2)) == 1


def test_a_run_on_a_course_style_map_reports_what_it_explored(tmp_path):
    world = course_style_world(tmp_path)
    result = run_episode(world, "east", duration=40.0, record_trajectory=False)
    assert result.collisions == 0 and result.distance_m > 4.0
    assert result.explored_fraction == pytest.approx(1.0)
    assert result.laps >= 1


def test_grid_origin_in_the_world_file_moves_the_grid(tmp_path):
    # Centres at (k + 0.5) * 0.4 again: all on walls or inside the block, as the file asks.
    assert len(course_style_world(tmp_path, "grid_origin: [0, 0]\n").free_cells()) == 0
    assert len(course_style_world(tmp_path, "grid_origin: [-3.0, 5.0]\n").free_cells()) == 16


@pytest.mark.parametrize("name", ["lab02", "corridor_loop", "maze_deadends", "room_obstacles",
                                  "wide_maze"])
def test_bundled_worlds_keep_their_grid_and_match_the_cell_by_cell_definition(name):
    world = World.load(name)
    # Their boundaries start on multiples of cell_size: the same cells as before.
    expected = reference_free_cells(world, (0.0, 0.0))
    np.testing.assert_allclose(world.free_cells(), expected, atol=1e-9)


def test_rasterized_cells_match_the_definition_on_a_cluttered_world(tmp_path):
    rng = np.random.default_rng(7)
    boundary = [[0, 0], [10, 0], [10, 4], [6, 10], [0, 10]]
    holes = []
    for cx, cy in rng.uniform(0.5, 9.5, (150, 2)):
        r = rng.uniform(0.05, 0.3)
        k = int(rng.integers(3, 7))   # triangles to hexagons, some of them overlapping
        angles = rng.uniform(0, 2 * math.pi) + 2 * math.pi * np.arange(k) / k
        hole = [[float(cx + r * math.cos(a)), float(cy + r * math.sin(a))] for a in angles]
        if all(inside(np.array(boundary, float), x, y) for x, y in hole):  # inside (it is convex)
            holes.append(hole)
    path = tmp_path / "cluttered.yaml"
    path.write_text(json.dumps({"cell_size": 0.13, "grid_origin": [0.01, -0.02],
                                "boundary": boundary, "holes": holes}))
    world = World.load(path)
    expected = reference_free_cells(world, (0.01, -0.02))
    assert len(expected) > 1000
    np.testing.assert_allclose(world.free_cells(), expected, atol=1e-9)
    points = rng.uniform(-1.0, 11.0, (2000, 2))
    expected_inside = [inside(world.boundary, x, y) and not any(inside(h, x, y)
                                                                for h in world.holes)
                       for x, y in points]
    assert list(world.contains_points(points)) == expected_inside
    assert [world.contains(x, y) for x, y in points[:200]] == expected_inside[:200]


# ---- B7: big and fine worlds -------------------------------------------------------------------
def test_a_grid_beyond_the_limit_is_a_clear_error_not_a_huge_allocation(tmp_path):
    path = tmp_path / "huge.yaml"
    path.write_text(HUGE_WORLD)
    world = World.load(path)
    with pytest.raises(GridTooLargeError, match=r"cell_size") as info:
        world.free_cells()
    assert "huge.yaml" in str(info.value) and f"{MAX_GRID_CELLS:,}" in str(info.value)
    # The episode still reports everything else, and says why two metrics are missing.
    result = run_episode(world, "a", duration=2.0)
    assert result.steps == 40 and result.collisions == 0
    assert result.explored_fraction is None and result.laps is None
    assert "cell_size" in result.metric_errors["explored_fraction"]
    assert "cell_size" in result.metric_errors["laps"]
    assert "n/a" in result.summary()
    json.dumps(result.to_dict(), allow_nan=False)


@pytest.mark.slow
def test_run_sim_report_of_a_huge_world_is_written_with_the_metric_marked(tmp_path):
    world = tmp_path / "huge.yaml"
    world.write_text(HUGE_WORLD)
    report_path = tmp_path / "report.json"
    process = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "run_sim.py"), "--world", str(world),
         "--duration", "2", "--report", str(report_path)],
        cwd=REPO, capture_output=True, text=True, timeout=300)
    assert process.returncode == 0, process.stdout + process.stderr
    report = json.loads(report_path.read_text())
    assert report["steps"] == 40 and report["explored_fraction"] is None
    assert "cell_size" in report["metric_errors"]["explored_fraction"]
    assert "explored n/a" in process.stdout
    assert "no /map" in process.stdout + process.stderr   # the map is skipped, the run is not


@pytest.mark.slow
def test_metrics_of_a_2500_obstacle_world_do_not_hang(tmp_path):
    """Metrics and the /map raster of 2,500 obstacles come back (a hang guard).

    Before: simulation 1 s, metrics over 5 minutes (a polygon test per cell and obstacle),
    the /map raster 40 s. A generous guard, not a speed target (scripts/bench*.py measure speed).
    """
    holes = [[[x, y], [x + 0.2, y], [x + 0.2, y + 0.2], [x, y + 0.2]]
             for x in range(1, 51) for y in range(1, 51)]
    path = tmp_path / "forest.yaml"
    path.write_text(json.dumps({"boundary": [[0, 0], [52, 0], [52, 52], [0, 52]],
                                "holes": holes, "starts": {"a": [0.5, 0.5, 0.0]}}))
    code = ("import sys, numpy as np; from amr_common.world.world import World; "
            "from amr_evaluation.episode import trajectory_metrics; "
            "from amr_common.ros.map_messages import grid_values, world_map_messages; "
            "w = World.load(sys.argv[1]); "
            "m = trajectory_metrics(w, np.array([[0.5, 0.5], [0.5, 51.5], [51.5, 51.5]])); "
            "r = grid_values(world_map_messages(w, 0.05)[0]); "   # the simulator's /map
            "print(len(w.free_cells()), m['explored_fraction'], m['laps'], "
            "int((r == 100).sum()))")
    process = subprocess.run([sys.executable, "-c", code, str(path)], cwd=REPO,
                             capture_output=True, text=True, timeout=120)
    assert process.returncode == 0, process.stderr
    cells, explored, laps, occupied = process.stdout.split()
    assert int(cells) > 10_000 and 0.0 < float(explored) < 0.01 and laps == "0"
    assert int(occupied) >= 2500 * 16   # each 0.2 m box covers at least 4 x 4 cells of 5 cm


def test_clearance_kernels_agree_with_the_pointwise_distance():
    from amr_common.world.raycast import clearances_kernel, clearances_numpy, clearances_python

    world = World.load("room_obstacles")
    points = np.random.default_rng(3).uniform(-0.5, 4.5, (300, 2))
    expected = np.array([world.clearance(x, y) for x, y in points])
    for kernel in (clearances_kernel, clearances_numpy, clearances_python):
        out = np.empty(len(points))
        kernel(world.segments, points, out)
        np.testing.assert_allclose(out, expected, atol=1e-12)
    np.testing.assert_allclose(world.clearances(points), expected, atol=1e-12)
