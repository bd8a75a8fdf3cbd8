"""The shared occupancy grid: cell layout, exact clearances, free/occupied cells."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.world import occupancy_grid
from amr_common.world.map_raster import points_in_polygon
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world import World, bundled_worlds


def test_cell_centres_lie_on_multiples_of_the_resolution_and_cover_the_world():
    world = World.load("lab02")
    grid = OccupancyGrid.from_world(world, 0.02)
    assert (grid.width, grid.height) == (123, 123)  # -1.22 .. 1.22: one cell beyond the walls
    assert grid.origin == pytest.approx((-1.23, -1.23))
    assert grid.cell_centre(0, 0) == pytest.approx((-1.22, -1.22))
    row, col = grid.cell_of(1.0, -1.0)
    assert grid.cell_centre(row, col) == pytest.approx((1.0, -1.0))
    # The corridor centre line is a row of cells 0.2 m from both walls.
    assert grid.clearance[row, col] == pytest.approx(0.2)
    assert grid.clearance_at(1.0, -1.0) == pytest.approx(0.2)
    assert not grid.contains_cell(-1, 0) and grid.clearance_at(5.0, 5.0) == 0.0


@pytest.mark.parametrize("name", bundled_worlds())
def test_clearance_is_the_exact_distance_to_the_walls_inside_and_zero_outside(name):
    world = World.load(name)
    grid = OccupancyGrid.from_world(world, 0.05)
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    centres = grid.cell_centres(rows.ravel(), cols.ravel())
    inside = world.contains_points(centres)
    exact = world.clearances(centres)
    assert np.allclose(grid.clearance.ravel()[inside], exact[inside], atol=1e-12)
    assert np.all(grid.clearance.ravel()[~inside] == 0.0)
    # Free: inside and no wall through the cell (no wall within half a cell of the centre,
    # some wall within half a diagonal of every occupied cell inside).
    assert np.all(grid.free.ravel()[inside & (exact >= 0.025 * math.sqrt(2))])
    assert not np.any(grid.free.ravel()[inside & (exact < 0.025)])
    assert not np.any(grid.free.ravel()[~inside])
    off_walls = exact > 1e-9  # a centre on the boundary wall may count as in or out
    assert np.array_equal(grid.in_boundary.ravel()[off_walls], points_in_polygon(
        world.boundary, centres[off_walls, 0], centres[off_walls, 1]))


def test_walls_are_occupied_lines_and_values_follow_the_nav_msgs_layout():
    world = World.load("lab02")
    grid = OccupancyGrid.from_world(world, 0.02, padding_m=0.1)
    assert grid.origin == pytest.approx((-1.31, -1.31))  # 5 cells of padding
    row, col = grid.cell_of(0.0, -0.8)  # on the wall from (-0.8, -0.8) to (0.8, -0.8)
    assert not grid.free[row, col] and grid.free[row + 1, col] and grid.free[row - 1, col]
    values = grid.occupancy_values()
    assert values.dtype == np.int8 and values.shape == (grid.height, grid.width)
    assert values[row, col] == occupancy_grid.OCCUPIED
    assert values[row + 2, col] == occupancy_grid.FREE
    assert values[0, 0] == occupancy_grid.UNKNOWN  # the lower-left cell lies outside
    assert values[grid.cell_of(-1.2, 0.0)] == occupancy_grid.OCCUPIED  # the boundary wall


@pytest.mark.parametrize("resolution", [0.0, -0.02, float("nan"), "2cm"])
def test_bad_resolution_is_a_clear_error(resolution):
    with pytest.raises(ValueError, match="resolution must be a positive number"):
        OccupancyGrid.from_world(World.load("lab02"), resolution)


def test_every_grid_indexes_its_cells_alike():
    # One cell_of (amr_common.world.cell_grid) behind the occupancy grid, a raster and the coverage
    # grid: the vector form agrees with it point for point, cell borders included.
    world = World.load("room_obstacles")
    grid = OccupancyGrid.from_world(world, 0.05)
    raster = grid.raster()
    coverage = world.coverage_grid()
    rng = np.random.default_rng(7)
    points = np.vstack([rng.uniform(-0.5, 4.5, (400, 2)), np.arange(-0.5, 4.5, 0.05)[:, None]
                        * np.ones((1, 2))])   # multiples of the resolution: cell borders
    for cells in (grid, raster, coverage):
        rows, cols = cells.cells_of(points[:, 0], points[:, 1])
        assert [cells.cell_of(x, y) for x, y in points] == list(zip(rows.astype(int).tolist(),
                                                                    cols.astype(int).tolist()))
    free = [grid.contains_cell(*grid.cell_of(x, y)) and bool(grid.free[grid.cell_of(x, y)])
            for x, y in points]
    assert raster.free_at(points).tolist() == free
