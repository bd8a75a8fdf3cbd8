"""Map worlds: a Nav2 map as a World, the world -> map converter, bad map files in the scripts.

The World side: walls, free space, clearances, ray casting and /map of a map; the converter's
round trip; a bad map file is a one-line error in every script.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.robot import ROBOT_RADIUS
from amr_common.ros.map_messages import grid_values, world_map_messages
from amr_common.world.distance_transform import squared_edt, squared_edt_python
from amr_common.world.map_file import read_map, world_as_map, write_map
from amr_common.world.map_raster import Raster, boundary_segments
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.raster_raycast import MarchGrid, march, march_python, scan_grid_kernel
from amr_common.world.raycast import scan_kernel
from amr_common.world.world import World, bundled_worlds

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import bench_map_world  # noqa: E402
import evaluate  # noqa: E402
import run_robot  # noqa: E402
import run_sim  # noqa: E402
import world_to_map  # noqa: E402


def unit_edges(segments: np.ndarray, resolution: float, origin) -> set:
    """Each segment cut into cell edges, as ((x, y) grid corner, direction) keys."""
    edges = []
    for x1, y1, x2, y2 in segments:
        a = np.rint((np.array([x1, y1]) - origin) / resolution).astype(int)
        b = np.rint((np.array([x2, y2]) - origin) / resolution).astype(int)
        step = np.sign(b - a)
        for k in range(int(abs(b - a).sum())):
            low = np.minimum(a + k * step, a + (k + 1) * step)
            edges.append((tuple(low), tuple(abs(step))))
    assert len(edges) == len(set(edges)), "segments overlap"
    return set(edges)


def brute_force_edges(free: np.ndarray) -> set:
    """Every cell edge between a free cell and a non-free one (beyond the raster: non-free)."""
    padded = np.pad(free, 1)
    edges = set()
    for r in range(padded.shape[0] - 1):
        for c in range(padded.shape[1] - 1):
            if padded[r, c] != padded[r, c + 1]:  # vertical edge at x = c, cells row r - 1
                edges.add(((c, r - 1), (0, 1)))
            if padded[r, c] != padded[r + 1, c]:  # horizontal edge at y = r
                edges.add(((c - 1, r), (1, 0)))
    return {e for e in edges if min(e[0]) >= -1}


def test_walls_of_a_map_are_its_free_cell_edges_merged():
    values = np.full((4, 5), 100, dtype=np.int8)
    values[1:3, 1:4] = 0  # a free 3 x 2 room in a wall
    raster = Raster(values, 0.1, (1.0, -2.0))
    segments = boundary_segments(raster)
    assert len(segments) == 4  # the room's four sides, each one segment
    np.testing.assert_allclose(sorted(map(tuple, segments.round(9))), sorted([
        (1.1, -1.9, 1.4, -1.9), (1.1, -1.7, 1.4, -1.7), (1.1, -1.9, 1.1, -1.7),
        (1.4, -1.9, 1.4, -1.7)]))
    values[0, 0] = 0  # a free cell in the corner: walls on the raster's border too
    # Its two inner sides continue the room's sides (the cells touch at a corner): 4 + 2.
    assert len(boundary_segments(raster)) == 6
    rng = np.random.default_rng(2)
    free = rng.random((30, 40)) < 0.7
    raster = Raster(np.where(free, 0, rng.choice([-1, 100, 50], free.shape)).astype(np.int8),
                    0.05, (-0.3, 0.45))
    segments = boundary_segments(raster)
    assert unit_edges(segments, 0.05, np.array([-0.3, 0.45])) == brute_force_edges(free)
    assert len(segments) < len(brute_force_edges(free))  # merged


def box_distance(points: np.ndarray, raster: Raster) -> np.ndarray:
    """Distance from each point to the nearest non-free cell (a ring beyond the raster too)."""
    padded = np.pad(raster.values != 0, 1, constant_values=True)
    rows, cols = np.nonzero(padded)
    lo_x = raster.origin[0] + (cols - 1) * raster.resolution
    lo_y = raster.origin[1] + (rows - 1) * raster.resolution
    px, py = points[:, 0:1], points[:, 1:2]
    dx = np.maximum(np.maximum(lo_x - px, px - lo_x - raster.resolution), 0.0)
    dy = np.maximum(np.maximum(lo_y - py, py - lo_y - raster.resolution), 0.0)
    return np.hypot(dx, dy).min(axis=1)


def test_free_space_and_clearances_of_a_map_world_are_its_cells():
    raster = bench_map_world.slam_like(world_as_map(World.load("lab02"))[0], seed=3)
    world = World.from_raster(raster, name="noisy", source="noisy.yaml")
    rng = np.random.default_rng(5)
    xmin, ymin, xmax, ymax = world.bounds
    points = rng.uniform((xmin - 0.1, ymin - 0.1), (xmax + 0.1, ymax + 0.1), (4000, 2))
    rows = np.floor((points[:, 1] - raster.origin[1]) / raster.resolution).astype(int)
    cols = np.floor((points[:, 0] - raster.origin[0]) / raster.resolution).astype(int)
    on_map = (rows >= 0) & (rows < raster.values.shape[0]) & (cols >= 0) & \
        (cols < raster.values.shape[1])
    expected = np.zeros(len(points), dtype=bool)
    expected[on_map] = raster.values[rows[on_map], cols[on_map]] == 0
    np.testing.assert_array_equal(world.contains_points(points), expected)
    assert world.contains(*points[expected][0]) and not world.contains(*points[~expected][0])
    free = points[expected]
    np.testing.assert_allclose(world.clearances(free), box_distance(free, raster), atol=1e-12)
    assert world.clearance(*free[0]) == pytest.approx(box_distance(free[:1], raster)[0])
    # The grid of the planner and the filter: the same clearances at the cell centres (by a
    # distance transform, not the segments).
    grid = OccupancyGrid.from_world(world)
    xs, ys = raster.centres()
    centres = np.column_stack([xs[raster.free], ys[raster.free]])
    np.testing.assert_allclose(grid.clearance[raster.free], world.clearances(centres),
                               rtol=0, atol=1e-12)
    assert (grid.clearance[~raster.free] == 0).all()
    # The coverage metrics count only free cells.
    assert world.contains_points(world.free_cells()).all() and len(world.free_cells()) > 0


def scan_both_ways(world: World, grid: MarchGrid, pose, angles, noise, limits):
    """(by segments, by marching) ranges of one scan."""
    out = np.empty((2, len(angles)))
    base = (np.cos(angles), np.sin(angles))
    scan_kernel(world.segments, *pose, *base, *limits, noise, out[0])
    scan_grid_kernel(grid.cells, grid.width, grid.x0, grid.y0, grid.resolution, *pose, *base,
                     *limits, noise, out[1])
    return out


def test_the_distance_transform_is_exact_and_its_twin_agrees():
    rng = np.random.default_rng(7)
    sites = rng.random((23, 31)) < 0.05
    sites[0, 3] = sites[-1, 0] = sites[5, 0] = sites[9, -1] = True
    sites[0], sites[-1], sites[:, 0], sites[:, -1] = True, True, True, True
    rows, cols = np.nonzero(sites)
    r, c = np.mgrid[:23, :31]
    brute = ((r[..., None] - rows) ** 2 + (c[..., None] - cols) ** 2).min(axis=2)
    np.testing.assert_array_equal(squared_edt(sites), brute)
    np.testing.assert_array_equal(squared_edt_python(sites), brute)


def test_ray_marching_returns_the_segment_kernels_ranges():
    raster = bench_map_world.slam_like(world_as_map(World.load("room_obstacles"))[0], seed=1)
    world = World.from_raster(raster)
    grid = MarchGrid.from_raster(raster)
    assert world.march_grid is not None  # thousands of segments: marched
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    rng = np.random.default_rng(0)
    xmin, ymin, xmax, ymax = world.bounds
    points = rng.uniform((xmin, ymin), (xmax, ymax), (400, 2))
    points = points[world.contains_points(points)][:60]
    poses = [(x, y, rng.uniform(-3, 3)) for x, y in points]
    poses.append((raster.origin[0] - 0.3, raster.origin[1] + 0.7, 0.1))  # off the map
    for noise, limits in ((np.zeros(360), (0.0, np.inf, np.inf)),
                          (rng.normal(0, 0.02, 360), (0.12, 3.5, 0.0))):
        for pose in poses:
            by_segments, by_cells = scan_both_ways(world, grid, pose, angles, noise, limits)
            np.testing.assert_allclose(by_cells, by_segments, rtol=0, atol=1e-9)
    # A ray through a cell corner hits there if an edge ends at it (the segment kernel's
    # inclusive segment ends; there rounding decides, so this is checked on its own).
    values = np.zeros((3, 3), dtype=np.int8)
    for blocked, expected in (((0, 1), 0.5), ((1, 0), 0.5), ((2, 2), 1.5), (None, 2.5)):
        cells = values.copy()
        if blocked:
            cells[blocked] = 100
        grid = MarchGrid.from_raster(Raster(cells, 1.0, (0.0, 0.0)))
        ranges = np.empty(1)
        scan_grid_kernel(grid.cells, grid.width, grid.x0, grid.y0, 1.0, 0.5, 0.5, math.pi / 4,
                         np.ones(1), np.zeros(1), 0.0, np.inf, np.inf, np.zeros(1), ranges)
        assert ranges[0] == pytest.approx(expected * math.sqrt(2)), blocked
    for x, y, theta in poses[:20]:  # the plain-Python twin
        gx, gy = (x - grid.x0) / grid.resolution, (y - grid.y0) / grid.resolution
        for a in angles[::15] + theta:
            args = (grid.cells, grid.width, gx, gy, math.cos(a), math.sin(a), 1e9)
            assert march_python(*args) == march(*args)


def test_a_converted_world_keeps_its_free_space_walls_starts_and_goals(tmp_path, course_map):
    resolution = 0.02
    for name in [*bundled_worlds(), str(course_map)]:
        polygon = World.load(name)
        prefix = tmp_path / Path(name).stem
        assert world_to_map.main([name, "-o", str(prefix)]) == 0
        world = World.load(f"{prefix}.yaml")
        assert (world.name, world.starts, world.goals, world.goal, world.cell_size) == \
            (polygon.name, polygon.starts, polygon.goals, polygon.goal, polygon.cell_size)
        # The cells are the polygon world's grid at 2 cm, as the planner and the filter use it.
        np.testing.assert_array_equal(OccupancyGrid.from_world(world).free,
                                      OccupancyGrid.from_world(polygon, resolution).free)
        # Same free space, within a cell of the walls.
        xmin, ymin, xmax, ymax = polygon.bounds
        points = np.random.default_rng(1).uniform((xmin, ymin), (xmax, ymax), (20000, 2))
        clear = polygon.clearances(points) > resolution
        np.testing.assert_array_equal(world.contains_points(points[clear]),
                                      polygon.contains_points(points[clear]), err_msg=name)
        along = np.linspace(0, 1, 11)[:, None, None]
        samples = (world.segments[:, :2] + along * (world.segments[:, 2:] -
                                                    world.segments[:, :2])).reshape(-1, 2)
        # A wall's cells reach at most a cell diagonal from it (half a cell along a straight
        # wall on a grid line; a slanted wall in room_obstacles needs more).
        assert polygon.clearances(samples).max() <= resolution * math.sqrt(2) + 1e-9, name
        # Coverage metrics on the same cells but those the moved walls bring within the
        # robot radius (0.4 m corridors keep their centre cells; room_obstacles loses one).
        ours, theirs = ({tuple(c) for c in w.free_cells().round(9)} for w in (world, polygon))
        changed = np.array(sorted(ours ^ theirs)).reshape(-1, 2)
        assert len(changed) <= 0.05 * len(theirs), name
        assert (abs(polygon.clearances(changed) - ROBOT_RADIUS) <= resolution * math.sqrt(2)).all()


def test_the_map_of_a_map_world_is_the_files_cells(tmp_path):
    values = np.zeros((30, 40), dtype=np.int8)
    values[:, 0] = values[0, :] = 100
    values[10:14, 20:25] = -1
    values[5, 5] = 37  # an in-between value (scale mode) stays on /map as it is
    yaml_path, _ = write_map(Raster(values, 0.05, (-1.0, -0.5)), tmp_path / "m")
    yaml_path.write_text(yaml_path.read_text().replace("mode: trinary", "mode: scale"))
    from PIL import Image
    pixels = np.array(Image.open(tmp_path / "m.pgm"))
    pixels[-6, 5] = 160  # p 0.3725 -> 39 in scale mode
    Image.fromarray(pixels).save(tmp_path / "m.pgm")
    world = World.load(yaml_path)
    expected = read_map(yaml_path).raster.values
    assert expected[5, 5] == 39
    message = world_map_messages(world, resolution=0.02)[0]  # a map world ignores 0.02
    np.testing.assert_array_equal(grid_values(message), expected)
    assert message.info.resolution == pytest.approx(0.05)
    assert (message.info.origin.position.x, message.info.origin.position.y) == (-1.0, -0.5)
    grid = OccupancyGrid.from_world(world, 0.02)
    assert grid.resolution == 0.05 and grid.origin == (-1.0, -0.5)
    np.testing.assert_array_equal(grid.free, expected == 0)


# --- bad map files in the scripts ------------------------------------------------------------

def bad_map(tmp_path) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text("image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return path


def test_a_bad_map_is_a_one_line_error_before_anything_runs(tmp_path, capsys):
    path = bad_map(tmp_path)
    message = f"{path}: image {tmp_path / 'missing.pgm'} not found"
    assert run_sim.main(["--world", str(path), "--start", "0.5,0.5,0"]) == 2
    assert capsys.readouterr().err.strip() == f"run_sim: {message}"
    with pytest.raises(SystemExit) as exit_info:
        run_robot.parse_args(["--map", str(path), "--localize"])
    err = capsys.readouterr().err.strip()
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1 and message in err
    assert evaluate.main(["--worlds", str(path), "--starts", "0.5,0.5,0", "--out",
                          str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.strip() == f"evaluate: {message}"
    assert world_to_map.main([str(path), "-o", str(tmp_path / "x")]) == 2
    assert capsys.readouterr().err.strip() == f"world_to_map: {message}"
    assert world_to_map.main(["lab02", "--resolution", "0", "-o", str(tmp_path / "x")]) == 2
    assert "--resolution must be in [0.005, 1] m" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:  # one line, not the whole usage
        world_to_map.main(["lab02", "--format", "jpg", "-o", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.splitlines() == [
        "world_to_map.py: error: argument --format: invalid choice: 'jpg' (choose from 'pgm', "
        "'png') (--help lists the options)"]
    assert not list(tmp_path.glob("x*"))


def test_world_to_map_writes_into_an_existing_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "maps").mkdir()
    assert world_to_map.main(["lab02", "-o", "maps"]) == 0
    assert world_to_map.main(["twin_maze", "-o", "new/"]) == 0  # a folder to be
    assert world_to_map.main(["corridor_loop", "-o", "maps/loop"]) == 0  # a prefix, as before
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*.*")) == [
        "maps/lab02.pgm", "maps/lab02.yaml", "maps/loop.pgm", "maps/loop.yaml",
        "new/twin_maze.pgm", "new/twin_maze.yaml"]
    assert World.load("maps/lab02.yaml").name == "lab02"
