"""The particle filter on big maps: the table it can afford, or a refusal.

The expected-range table grows with the free area: a 40 x 40 m office floor gets 4 cm cells and
180 directions within max_memory_mb (the old 2 cm x 360 table would need ~2.9 GB; the old code
refused the map only when configuring, its grid having more than 4 M cells); a map too big even
then is refused before anything is built, saying what it would need. Peak memory is measured by
scripts/bench_localization.py (--memory), not here.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter

from amr_common.world.raycast import scan_kernel
from amr_common.world.world import World
from amr_localization.expected_ranges import NO_RANGE_MM, build_expected_range_table
from amr_localization.particle_filter import ParticleFilter
from amr_localization.particle_filter_node import ParticleFilterNode
from amr_localization.particle_filter_params import check_parameters, check_world
from amr_localization.table_memory import MapTooBigError, candidate_plans, choose_table
from tools.make_building_world import building, to_yaml

BUILDING_40M = Path(__file__).resolve().parent / "worlds" / "building_40m.yaml"


def _building(tmp_path, size: float) -> World:
    path = tmp_path / f"building_{size:g}m.yaml"
    path.write_text(to_yaml(building(size, 18)))
    return World.load(path)


def test_a_40_m_floor_gets_a_4_cm_180_direction_table_within_the_budget():
    world = World.load(BUILDING_40M)
    values = check_parameters({})
    plan = check_world(world, values)
    assert (plan.resolution, plan.angles) == (0.04, 180)
    assert plan.total_bytes <= values["max_memory_mb"] * 1e6
    assert 300e6 < plan.table_bytes < 400e6
    # The old 2 cm x 360 table: ~2.9 GB, on a grid over the cell limit (refused at configure).
    finest = candidate_plans(world, values)[0]
    assert (finest.resolution, finest.angles) == (0.02, 360)
    assert finest.table_bytes > 2.8e9 and finest.cells > 4_000_000
    # More memory allowed: the finest table that fits it and the grid's cell limit.
    assert choose_table(world, dict(values, max_memory_mb=1e5)).angles == 360
    # The course's mazes keep their table.
    for name in ("lab02", "room_obstacles", "twin_maze"):
        small = check_world(World.load(name), values)
        assert (small.resolution, small.angles) == (0.02, 360)


def test_a_map_too_big_is_refused_before_anything_is_built_saying_what_it_needs(tmp_path):
    world = _building(tmp_path, 60)
    values = check_parameters({})
    with pytest.raises(MapTooBigError, match=r"60\.0 x 60\.0 m .* would need 1,0\d\d MB .*"
                       r"4 cm x 180 directions.*max_memory_mb is 600"):
        check_world(world, values)
    assert check_world(world, dict(values, max_memory_mb=1200)).resolution == 0.04
    with pytest.raises(ValueError, match="too big"):
        ParticleFilter(world)
    huge = tmp_path / "huge.yaml"
    huge.write_text("boundary: [[0, 0], [100, 0], [100, 100], [0, 100]]\n")
    with pytest.raises(MapTooBigError, match=r"2,\d\d\d MB.*grid has 6,\d{3},\d{3} cells"):
        check_world(World.load(huge), values)


def test_the_initial_pose_is_checked_against_the_map_up_front():
    values = check_parameters({"initial_pose": [0.0, -0.8, 0.0]})  # on a wall of lab02
    with pytest.raises(ValueError, match="initial_pose .* wall"):
        check_world(World.load("lab02"), values)


def test_a_coarse_table_stores_rows_only_for_the_free_space_with_exact_ranges(tmp_path):
    """The byte size is the free cells' rows; every range is the simulator's kernel's, exactly.

    A 12 m floor forced onto the big-map table (4 cm x 180): its rays reach past the first two
    wall sets the build casts against (1.5 m, 5 m around each block), so all three are checked.
    """
    world = _building(tmp_path, 12)
    plan = check_world(world, check_parameters({"max_memory_mb": 50}))
    assert (plan.resolution, plan.angles) == (0.04, 180)
    table = build_expected_range_table(world, plan.resolution, plan.angles)
    stored = np.count_nonzero(table.grid.clearance >= 0.01)
    assert table.ranges.shape == (stored + 1, 180) and not table.ranges[0].any()
    assert table.nbytes == (stored + 1) * 180 * 2 + table.cells * 4 <= plan.table_bytes
    assert stored < 0.99 * table.cells, "cells on or beside walls (and outside) get no row"
    directions = np.arange(180) * (2 * math.pi / 180)
    ranges, zeros = np.empty(180), np.zeros(180)
    rng = np.random.default_rng(9)
    cells = rng.choice(np.flatnonzero(table.rows), 300, replace=False)
    far = 0
    for cell in cells:
        x, y = table.cell_centres([cell])[0]
        scan_kernel(world.segments, x, y, 0.0, np.cos(directions), np.sin(directions), 0.0,
                    np.inf, np.inf, zeros, ranges)
        mm = np.where(ranges * 1000.0 < NO_RANGE_MM, np.round(ranges * 1000.0), NO_RANGE_MM)
        assert np.array_equal(table.cell_ranges(cell), mm.astype(np.uint16))
        far += np.count_nonzero(ranges > 5.0)
    assert far > 0, "some rays reach beyond the 5 m wall set"


def test_a_filter_on_the_coarse_table_tracks_a_standing_robot_within_a_cell(tmp_path):
    from amr_sim.lidar import Lidar
    world = _building(tmp_path, 12)
    pose = world.starts["corridor_crossing"]
    pf = ParticleFilter(world, initial_pose=list(pose), max_memory_mb=50,
                        initial_pose_sigma=[0.05, 0.05, 0.05], lidar_model="exact")
    assert (pf.table.resolution, pf.table.angles) == (0.04, 180) and pf.model.sub_cell
    pf.set_scan_geometry(0.0, 2 * math.pi / 360, 360, 0.12, 3.5)
    scan = Lidar(world.segments, 360, 0.0, 2 * math.pi / 360, 0.12, 3.5, 0.0).scan(*pose)
    for _ in range(12):
        pf.correct(scan, force=True)
    assert math.hypot(pf.estimate[0] - pose[0], pf.estimate[1] - pose[1]) < 0.015


def test_the_node_refuses_a_map_too_big_when_configuring(ros, tmp_path):
    path = tmp_path / "huge.yaml"
    path.write_text("boundary: [[0, 0], [100, 0], [100, 100], [0, 100]]\n")
    messages = []
    node = ros.add(ParticleFilterNode(context=ros.context, parameter_overrides=[
        Parameter("world", value=str(path))]))
    node.get_logger().error = lambda text, **kw: messages.append(text)
    assert node.trigger_configure().name == "FAILURE"
    assert "too big" in messages[-1] and "would need" in messages[-1]


def test_the_pose_search_of_a_coarse_table_finds_the_exact_twin_in_corridor_loop():
    """On 4 cm cells the search grid stays 4 cm, holding the corridors' centre lines.

    With every second 4 cm cell (an 8 cm grid, off the 0.2 m centre lines) the half-turn twin
    of this pose scored 19 of 30 beams, was never checked, and the filter declared the wrong
    copy (2 of 200 episodes of evaluate.py --localize on the big-map table).
    """
    from amr_sim.lidar import Lidar
    world = World.load("corridor_loop")
    pose = (0.456, 2.201, -math.pi)
    pf = ParticleFilter(world, initial_pose=list(pose), table_resolution_m=0.04,
                        table_angles=180, lidar_model="exact")
    pf.set_scan_geometry(0.0, 2 * math.pi / 240, 240, 0.016, 8.0)
    scan = Lidar(world.segments, 240, 0.0, 2 * math.pi / 240, 0.016, 8.0, math.nan).scan(*pose)
    xmin, ymin, xmax, ymax = world.bounds
    twin = (xmin + xmax - pose[0], ymin + ymax - pose[1])
    scan = pf._take_scan(scan, 0.0)  # this scan's beams and tolerances, as correct() takes it
    rivals = [a for a in pf._alternatives(scan) if a.match_fraction >= 0.9]
    assert any(math.hypot(a.pose[0] - twin[0], a.pose[1] - twin[1]) < 0.05 for a in rivals), \
        [(a.pose, a.match_fraction) for a in pf.last_alternatives]


def _map_world(tmp_path, name: str, resolution: float) -> World:
    """A bundled world as a Nav2 map (what scripts/world_to_map.py writes), loaded."""
    from amr_common.world.map_file import world_as_map, write_map
    raster, extras = world_as_map(World.load(name), resolution)
    yaml_path, _ = write_map(raster, tmp_path / f"{name}_{100 * resolution:g}cm", "pgm", extras)
    return World.load(yaml_path)


@pytest.mark.parametrize("name, resolution", [("lab02", 0.02), ("lab02", 0.05),
                                              ("room_obstacles", 0.02)])
def test_a_map_worlds_plan_is_its_own_grid_and_predicts_the_tables_bytes(tmp_path, caplog, name,
                                                                          resolution):
    """A map world's table is on the map's cells (OccupancyGrid of a raster): so is its plan.

    The plan took the world's outline at table_resolution_m (2 cm, then 4 cm for a big map)
    and estimated the free cells: its figures were another grid's.
    """
    world = _map_world(tmp_path, name, resolution)
    plan = check_world(world, check_parameters({}))
    assert (plan.resolution, plan.angles) == (world.raster.resolution, 360)
    table = build_expected_range_table(world, plan.resolution, plan.angles)
    assert (table.ny, table.nx) == world.raster.values.shape and plan.cells == table.cells
    assert plan.free_cells == len(table.ranges) - 1
    assert plan.table_bytes == table.nbytes
    caplog.set_level("INFO", logger="amr_localization.particle_filter")
    ParticleFilter(world)
    assert "big map" not in caplog.text, "a map's own cell size is not a reduced table"


@pytest.mark.parametrize("resolution", [0.02, 0.05])
def test_a_map_world_too_big_is_refused_with_its_own_grids_figure(tmp_path, resolution):
    """Only the directions of a map's table can shrink: the refusal names its cells' table."""
    world = _map_world(tmp_path, "lab02", resolution)
    values = check_parameters({"max_memory_mb": 1})
    plans = candidate_plans(world, values)
    assert [(p.resolution, p.angles) for p in plans] == [(resolution, 360), (resolution, 180)]
    table = build_expected_range_table(world, resolution, 180)
    with pytest.raises(MapTooBigError) as error:
        check_world(world, values)
    assert f"({100 * resolution:g} cm x 180 directions, table {table.nbytes / 1e6:,.0f} MB)" \
        in str(error.value)
    assert f"would need {plans[-1].total_bytes / 1e6:,.0f} MB" in str(error.value)
    assert plans[-1].table_bytes == table.nbytes


# --- the exhaustive pose search of a big map, a slice per scan ---------------------------------
# On the 40 x 40 m floor the search (885,000 positions, ~3 s of CPU) ran in one correct() call:
# at the first scan of a global search and before each declaration the node answered nothing
# for seconds while the robot drove on its last command. Now each call scores at most
# SLICE_CELLS positions; a course maze (at most ~5,400) still searches in one call.

def test_a_sliced_search_finds_what_a_search_in_one_go_finds(tmp_path):
    from amr_localization.pose_search import SLICE_CELLS
    from amr_sim.lidar import Lidar
    world = _building(tmp_path, 12)
    pf = ParticleFilter(world, max_memory_mb=50)
    pf.set_scan_geometry(0.0, 2 * math.pi / 360, 360, 0.12, 3.5)
    pose = world.starts["corridor_crossing"]
    scan = Lidar(world.segments, 360, 0.0, 2 * math.pi / 360, 0.12, 3.5, math.nan).scan(*pose)
    z_mm = pf.beams.readings_mm(scan)
    positions = len(pf.search.cells)
    assert positions > 2 * SLICE_CELLS
    whole = pf.search.start(500, pf.beams, z_mm).finish()
    sliced, slices = pf.search.start(500, pf.beams, z_mm), 1
    while not sliced.advance():
        slices += 1
    assert slices == -(-positions // SLICE_CELLS)
    assert np.array_equal(sliced.scores, whole.scores) and np.array_equal(sliced.flat, whole.flat)
    for name in ("lab02", "room_obstacles", "wide_maze"):  # the roomiest course mazes
        assert len(ParticleFilter(World.load(name)).search.cells) <= SLICE_CELLS


def test_searches_carry_their_poses_by_the_odometry_since_their_scan():
    """A pose found for an earlier scan, moved as the robot moved since (its own frame)."""
    from amr_localization.filter_searches import PendingSearch
    pending = PendingSearch("seed", None, np.zeros(1), (0.0, 0.0, 0.0))
    poses = np.array([[1.0, 2.0, 0.3], [-0.5, 0.7, -2.9]])
    twists = [(0.2, 0.5, 0.05)] * 20 + [(0.15, -1.0, 0.05)] * 15
    for v, w, dt in twists:
        pending.predict(v, w, dt)
    for pose, carried in zip(poses, pending.carry(poses)):
        x, y, theta = pose
        for v, w, dt in twists:  # the filter's own mid-point integration, from that pose
            mid = theta + 0.5 * w * dt
            x, y, theta = x + v * dt * math.cos(mid), y + v * dt * math.sin(mid), theta + w * dt
        assert np.allclose(carried, (x, y, math.remainder(theta, 2 * math.pi)), atol=1e-9)


@pytest.mark.parametrize("profile, must_localize", [("turtlebot3_clean", True),
                                                     ("turtlebot3", False)])
def test_no_filter_call_searches_more_than_a_slice_and_the_floor_still_localizes(tmp_path,
                                                                               monkeypatch,
                                                                               profile,
                                                                               must_localize):
    """Each call scores at most a slice, also with a real LiDAR (LDS-01 tolerances, de-skew).

    Its searches finish calls after their scan and judge it with that scan's rays, ranges and
    tolerances. There the floor's repeated offices may stay rivals (in 30 s several explain
    99-100 % of the rays within the datasheet's tolerances, as before the searches were sliced):
    undecided is allowed, wrong never.
    """
    from amr_evaluation.localization_episode import run_localization_episode
    from amr_localization.pose_search import SLICE_CELLS, PoseSearch
    world = _building(tmp_path, 12)
    scored: list[int] = []
    score_into, correct = PoseSearch._score_into, ParticleFilter.correct

    def counting_score_into(search, centres, *args):
        scored[-1] += len(centres)
        return score_into(search, centres, *args)

    def counting_correct(pf, *args, **kwargs):
        scored.append(0)
        return correct(pf, *args, **kwargs)

    monkeypatch.setattr(PoseSearch, "_score_into", counting_score_into)
    monkeypatch.setattr(ParticleFilter, "correct", counting_correct)
    result = run_localization_episode(world, "corridor_west", profile=profile, seed=0,
                                      duration=30.0, record=False,
                                      filter_params={"max_memory_mb": 50})
    assert max(scored) <= SLICE_CELLS, f"a call scored {max(scored)} positions"
    assert sum(scored) > 3 * SLICE_CELLS  # the seed's and the check's searches, sliced
    assert result.false_localizations == 0, result.summary()
    if must_localize:
        assert result.time_to_localized_s is not None, result.summary()
