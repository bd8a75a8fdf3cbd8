"""The log-odds occupancy grid: exact values on an analytic room, growth, its cap, the raster."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.world.map_raster import FREE, OCCUPIED, UNKNOWN
from amr_mapping.log_odds_grid import GROWTH_CELLS, LogOddsGrid
from amr_mapping.loop_closure import draw

RES = 0.02


def _grid(**kw) -> LogOddsGrid:
    return LogOddsGrid(RES, kw.pop("max_cells", 10_000_000), 0.9, 0.4, **kw)


def test_one_ray_along_a_row_clears_the_cells_before_its_end_and_hits_the_end():
    grid = _grid()
    grid.add_scan((0.011, 0.011), np.array([[0.991, 0.011]]))
    row = -grid.row0
    values = grid.counts[row, -grid.col0:-grid.col0 + 51]
    assert np.all(values[:49] == -40)  # cells 0..48: crossed, 0.4 each
    assert values[49] == 90  # the end cell: 0.9
    assert values[50] == 0
    assert grid.counts.sum() == 49 * -40 + 90
    assert grid.hits.sum() == 1


def test_miss_stop_spares_the_cells_just_before_the_end():
    grid = _grid(miss_stop=0.05)
    grid.add_scan((0.011, 0.011), np.array([[0.991, 0.011]]))
    values = grid.counts[-grid.row0, -grid.col0:-grid.col0 + 50]
    # misses only for cells left before 0.991 - 0.05 = 0.941: cells 0..46 (their far side
    # x = 0.94 at the most)
    assert np.all(values[:47] == -40) and np.all(values[47:49] == 0) and values[49] == 90


def _room_scan(pose, half=1.0, rays=720):
    """Noise-free ranges from pose inside the square room |x|, |y| <= half (LiDAR at pose)."""
    angles = pose[2] + np.arange(rays) * 2 * math.pi / rays
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (half - pose[0]) / c, np.where(c < 0, (-half - pose[0]) / c, np.inf))
        ty = np.where(s > 0, (half - pose[1]) / s, np.where(s < 0, (-half - pose[1]) / s, np.inf))
    r = np.minimum(tx, ty)
    local = angles - pose[2]
    return np.column_stack([r * np.cos(local), r * np.sin(local)])


def test_analytic_room_gives_free_inside_occupied_walls_unknown_outside():
    grid = _grid(miss_stop=0.02, hit_moments=True)
    for pose in [(0.0, 0.0, 0.0), (0.3, -0.2, 1.0), (-0.4, 0.35, 2.0), (0.1, 0.5, -1.0)]:
        draw(grid, pose, _room_scan(pose), 0.0)
    raster = grid.raster(0.6, -0.4, 0.2)
    assert set(np.unique(raster.values)) <= {FREE, OCCUPIED, UNKNOWN}

    def value(x, y):
        row, col = raster.cell_of(x, y)
        inside = 0 <= row < raster.values.shape[0] and 0 <= col < raster.values.shape[1]
        return raster.values[row, col] if inside else UNKNOWN

    # Inside: free well away from the walls; the walls occupied along their whole length (a
    # wall on a cell boundary: the cell on one side or the other); outside: unknown (no ray
    # went there); the raster is cropped to what was observed.
    for x, y in [(0.0, 0.0), (0.5, 0.5), (-0.7, -0.7), (0.9, 0.0)]:
        assert value(x, y) == FREE
    e = 1e-3
    for t in np.linspace(-0.97, 0.97, 50):
        for (x1, y1), (x2, y2) in [(((1.0 - e, t), (1.0 + e, t))), ((-1.0 - e, t), (-1.0 + e, t)),
                                   ((t, 1.0 - e), (t, 1.0 + e)), ((t, -1.0 - e), (t, -1.0 + e))]:
            assert OCCUPIED in (value(x1, y1), value(x2, y2)), (x1, y1)
    assert value(1.04 + e, 0.0) == UNKNOWN
    xs, ys = raster.centres()
    occupied = raster.values == OCCUPIED
    wall_distance = np.abs(np.maximum(np.abs(xs), np.abs(ys)) - 1.0)
    assert wall_distance[occupied].max() <= 1.5 * RES
    assert raster.origin[0] <= -1.0 and raster.values.shape[1] * RES < 2.2


def test_scans_removed_again_leave_the_grid_unknown():
    grid = _grid(hit_moments=True)
    poses = [(0.0, 0.0, 0.0), (0.2, 0.1, 0.5)]
    for pose in poses:
        draw(grid, pose, _room_scan(pose, rays=360), 0.0)
    for pose in poses:
        draw(grid, pose, _room_scan(pose, rays=360), 0.0, sign=-1)
    assert not grid.counts.any() and not grid.hits.any()
    assert np.all(grid.raster(0.6, -0.4).values == UNKNOWN)


def test_grid_grows_in_blocks_and_refuses_to_grow_past_its_cap():
    grid = _grid()
    assert grid.add_scan((0.0, 0.0), np.array([[1.0, 0.0]]))
    rows, cols = grid.shape
    assert grid.add_scan((0.0, 0.0), np.array([[0.0, 0.5]]))  # still inside: no growth
    assert grid.shape == (rows, cols)
    assert grid.add_scan((0.0, 0.0), np.array([[-3.0, 2.0]]))  # crosses nothing drawn before
    assert grid.shape[1] >= cols + GROWTH_CELLS
    # The old cells kept their place in the world.
    assert grid.counts[-grid.row0, round(1.0 / RES) - grid.col0] == 90

    small = _grid(max_cells=200 * 200)
    assert small.add_scan((0.0, 0.0), np.array([[1.0, 0.0]]))
    shape = small.shape
    assert not small.add_scan((0.0, 0.0), np.array([[30.0, 0.0]]))  # would need 1,600 columns
    assert small.shape == shape and small.counts.size <= 200 * 200
    # The part of the ray inside the grid was still traced; nothing beyond it.
    assert small.counts[-small.row0, -small.col0 + 10] < 0


@pytest.mark.parametrize("share", [0.0, 0.2])
def test_raster_hit_share_drops_lone_noise_hits_beside_a_wall(share):
    grid = _grid()
    sensor = (0.011, 0.011)
    ends = np.array([[0.991, 0.011]] * 20 + [[1.011, 0.011]])  # 20 hits, one noise hit behind
    grid.add_scan(sensor, ends)
    raster = grid.raster(0.6, -0.4, share)
    behind = raster.values[raster.cell_of(1.011, 0.011)]
    assert raster.values[raster.cell_of(0.991, 0.011)] == OCCUPIED
    assert behind == (OCCUPIED if share == 0.0 else UNKNOWN)


def test_a_scan_drawn_before_the_grid_grew_is_taken_out_exactly():
    """Rays traced at one array offset and removed at another cross the same cells.

    45-degree rays whose start and end share their position within a cell meet cell corners
    exactly: computed from the array's corner, rounding broke those ties one way when drawn
    and another once the grid had grown (the Intel log's local map, keyframes drawn and taken
    out for minutes: a cell left with +0.4 log-odds and one hit, whose field weight was
    infinite and the matcher's score with it).
    """
    rng = np.random.default_rng(0)
    res = 0.05
    sensors = np.floor(rng.uniform(-3, 3, (400, 2)) / res) * res + rng.uniform(0, res, (400, 1))
    ends = sensors + rng.integers(5, 80, (400, 1)) * res * np.sign(rng.uniform(-1, 1, (400, 2)))
    grid = LogOddsGrid(res, 10_000_000, 0.9, 0.4, hit_moments=True)
    for sensor, end in zip(sensors, ends):
        grid.add_scan(tuple(sensor), end[None, :])
    far = ((0.0, 0.0), np.array([[-40.0, -37.0]]))
    grid.add_scan(*far)  # the grid grows: its array starts elsewhere
    for sensor, end in zip(sensors, ends):
        grid.add_scan(tuple(sensor), end[None, :], -1)
    alone = LogOddsGrid(res, 10_000_000, 0.9, 0.4, hit_moments=True)
    alone.add_scan(*far)
    rows, cols = alone.counts.shape
    box = (alone.row0, alone.col0, alone.row0 + rows, alone.col0 + cols)
    assert np.array_equal(grid.window(*box), alone.counts)
    assert grid.counts.sum() == alone.counts.sum() and grid.hits.sum() == 1
