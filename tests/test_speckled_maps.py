"""Maps as noisy as SLAM leaves them, at the sizes allowed: the filter's table, the simulator.

A 20 x 20 m map at 2 cm with 1 % specks as the filter's map once configured for
minutes (the expected-range table cast every ray against every one of its ~39,000 walls) and
ignored Ctrl-C and SIGTERM until done. Now the table is built exactly the same (the segment
kernel's arithmetic, tested here against it) from the walls each ray can reach, in slices that
a stop ends, and a map whose table would still take too long is refused before anything runs.
The simulator once put every wall of such a map in its pymunk space (2,000 x 2,000
cells with 50 % specks: 189 s, 3.4 GB); now only those near the robot, with the same contacts.
Speed is measured by scripts/bench_map_world.py --big-maps; here small maps, behaviour only.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.parameter import Parameter

from amr_common.stop_flag import StopFlag
from amr_common.world.map_raster import OCCUPIED, Raster
from amr_common.world.raycast import scan_kernel
from amr_common.world.world import World
from amr_localization.particle_filter import ParticleFilter
from tools.make_speckled_map import speckled_raster, start_pose, write_speckled_map


def speckled_world(cells: int = 100, share: float = 0.2, seed: int = 0) -> World:
    raster = speckled_raster(cells, share, seed=seed)
    return World.from_raster(raster, name=f"specks_{cells}_{share:g}",
                             source=f"specks_{cells}_{share:g}_{seed}",
                             starts={"centre": start_pose(raster)})


def every_wall_mm(walls: np.ndarray, x: float, y: float, angles: int) -> np.ndarray:
    """The ranges (mm) the old build stored: every ray against every wall (scan_kernel)."""
    directions = np.arange(angles) * (2 * math.pi / angles)
    out = np.empty(angles)
    scan_kernel(walls, x, y, 0.0, np.cos(directions), np.sin(directions), 0.0, np.inf, np.inf,
                np.zeros(angles), out)
    return np.where(out * 1000.0 < 65535, np.round(out * 1000.0), 65535).astype(np.uint16)


@pytest.mark.parametrize("share, angles", [(0.01, 90), (0.2, 72), (0.5, 36)])
def test_the_table_of_a_speckled_map_is_the_segment_kernels_to_the_millimetre(share, angles):
    """Sparse (rays cast in rings and wedges) and dense (through the buckets): the same mm."""
    from amr_common.world.map_raster import likely_wall_segments
    from amr_localization.expected_ranges import build_expected_range_table
    world = speckled_world(80, share)
    walls = likely_wall_segments(world.raster)
    table = build_expected_range_table(world, 0.02, angles, segments=walls)
    cells = np.flatnonzero(table.rows)
    assert len(cells) > 1000
    for cell in cells[::7]:
        x, y = table.cell_centres([cell])[0]
        assert np.array_equal(table.cell_ranges(cell), every_wall_mm(walls, x, y, angles)), cell


@pytest.mark.parametrize("march", [False, True])
def test_the_tables_kernel_and_its_plain_twin_agree(march):
    from amr_localization import table_kernels
    from amr_localization.expected_ranges import start_build
    world = speckled_world(40, 0.1)
    outs = []
    for kernel in (table_kernels.fill_blocks, table_kernels.fill_blocks_python):
        build = start_build(world, 0.02, 24)
        blocks = np.arange(len(build.block_starts) - 1)
        scratch, stamp = table_kernels.scratch_arrays(
            build.walls_count, int(np.max(np.diff(build.block_starts))), build.sector)
        kernel(*build._arguments, build.rows, march, blocks, scratch, stamp, 1, build.ranges)
        outs.append(build.ranges)
    assert outs[0].any() and np.array_equal(outs[0], outs[1])


def test_the_walls_in_buckets_answer_as_every_wall_and_their_twins_agree():
    from amr_common.world.raster_raycast import (
        SegmentGrid,
        cast_through_buckets_python,
        clearances_through_buckets,
        clearances_through_buckets_python,
    )
    from amr_common.world.raycast import clearances_python
    world = speckled_world(60, 0.2)
    grid = SegmentGrid.build(world.segments)
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.3, 1.5, (200, 2))  # some off the map
    exact = np.empty(len(points))
    clearances_python(world.segments, points, exact)
    for kernel in (clearances_through_buckets, clearances_through_buckets_python):
        out = np.empty(len(points))
        kernel(*grid.arrays, points, out)
        assert np.array_equal(out, exact)
    assert np.array_equal(world.clearances(points), exact)  # World uses the buckets here
    for x, y in points[:20]:
        a = rng.uniform(-math.pi, math.pi)
        expected = np.empty(1)
        scan_kernel(world.segments, x, y, a, np.ones(1), np.zeros(1), 0.0, np.inf, np.inf,
                    np.zeros(1), expected)
        dx, dy = math.cos(a), math.sin(a)
        assert grid.cast(x, y, dx, dy)[0] == cast_through_buckets_python(
            *grid.arrays, x, y, dx, dy)[0]
        assert grid.cast(x, y, dx, dy)[0] == pytest.approx(expected[0], abs=1e-12)


def test_a_stop_ends_the_tables_build_between_slices():
    from amr_localization.expected_ranges import (
        TableBuildInterrupted,
        build_expected_range_table,
    )
    world = speckled_world(150, 0.01)
    checks = []

    def stop():
        checks.append(1)
        return len(checks) >= 3

    with pytest.raises(TableBuildInterrupted, match="stopped"):
        build_expected_range_table(world, 0.02, 360, stop=stop)
    assert len(checks) == 3  # checked again and again while it builds, not only at the start


def test_ctrl_c_caught_by_a_scripts_stop_flag_stops_the_filters_construction():
    """A table bigger than its sample (~0.3 s of CPU; a smaller one is built by then)."""
    flag = StopFlag().install()
    try:
        flag.requested = True  # Ctrl-C (or SIGTERM) came while the node configured
        with pytest.raises(RuntimeError, match="table was stopped"):  # TableBuildInterrupted
            ParticleFilter(speckled_world(300, 0.01, seed=7))
    finally:
        flag.uninstall()


def test_the_node_stops_configuring_when_stopped_and_can_configure_again(ros, tmp_path):
    from amr_localization.particle_filter_node import ParticleFilterNode
    path = write_speckled_map(tmp_path / "specks", 300, 0.01, seed=8)  # more than its sample
    warnings = []
    node = ros.add(ParticleFilterNode(context=ros.context, parameter_overrides=[
        Parameter("world", value=str(path))]))
    node.get_logger().warning = lambda text, **kw: warnings.append(text)
    flag = StopFlag().install()
    try:
        flag.requested = True
        assert node.trigger_configure().name == "FAILURE"
    finally:
        flag.uninstall()
    assert warnings and "configure stopped" in warnings[-1] and "Ctrl-C" in warnings[-1]
    assert node.current_state_label() == "unconfigured"
    assert node.trigger_configure().name == "SUCCESS"


def test_a_map_whose_table_would_take_too_long_is_refused_saying_how_long():
    from amr_localization.particle_filter_params import check_parameters, check_world
    world = speckled_world(120, 0.02, seed=4)
    with pytest.raises(ValueError, match="would take about") as refused:  # TableTooSlowError
        check_world(world, check_parameters({"max_table_build_s": 1e-4}))
    text = str(refused.value)
    assert "\n" not in text and "would take about" in text and " s to build" in text
    assert "max_table_build_s is 0.0001" in text and "MB" in text and "cells" in text
    plan = check_world(world, check_parameters({}))  # the default: seconds are fine
    assert ParticleFilter(world).table.nbytes == plan.table_bytes


def test_a_big_maps_simulator_holds_only_the_walls_near_the_robot_with_the_same_contacts(
        monkeypatch):
    """Driving into specks: the same poses, contacts and clearances as with every wall."""
    from amr_sim.simulator import Simulator

    def drive(sim):
        shapes = []
        for i in range(400):
            sim.step(0.22, 1.2 if (i // 50) % 2 else -0.4)
            shapes.append(len(sim.space.shapes))
        return sim, max(shapes)

    world = speckled_world(200, 0.02, seed=2)
    assert len(world.segments) > 2500
    window, most = drive(Simulator(world, start="centre", profile="ideal"))
    assert most < len(world.segments) / 4, "the walls near the robot, not all"
    monkeypatch.setattr(World, "wall_grid", property(lambda self: None), raising=False)
    reference, every = drive(Simulator(world, start="centre", profile="ideal"))
    assert every > len(world.segments)  # every wall, and the robot
    assert window.collisions == reference.collisions > 2
    # At a speck's corner the robot touches two walls at once: which one pymunk reports first
    # follows the order it holds them in (the point moved by 0.16 mm along the speck's side).
    assert np.allclose(window.collision_points, reference.collision_points, rtol=0, atol=1e-3)
    assert window.pose == pytest.approx(reference.pose, abs=1e-9)
    assert window.min_clearance == pytest.approx(reference.min_clearance, abs=1e-12)
    assert window.clearance == pytest.approx(reference.clearance, abs=1e-12)
    assert np.array_equal(window.last_scan, reference.last_scan)


@pytest.mark.parametrize("profile", ["turtlebot3", "turtlebot3_lds02"])
def test_the_real_scanner_on_a_big_map_reads_what_every_wall_gives(monkeypatch, profile):
    """Its rays walk the walls' buckets: the same readings (ranges to the last bits)."""
    from amr_sim.simulator import Simulator
    world = speckled_world(150, 0.02, seed=5)
    scans = []
    for every_wall in (False, True):
        if every_wall:
            monkeypatch.setattr(World, "wall_grid", property(lambda self: None), raising=False)
        sim = Simulator(world, start="centre", profile=profile, seed=3)
        for i in range(30):
            sim.step(0.1, 0.5)
        scans.append(sim.last_scan)
        assert (len(sim.lidar.walls[1]) > 0) != every_wall  # buckets, then none
    returns = [np.isfinite(scan) & (scan > 0.0) for scan in scans]  # no return: NaN or 0.0
    assert np.array_equal(returns[0], returns[1]) and 0 < returns[0].sum() < len(scans[0])
    np.testing.assert_allclose(scans[0], scans[1], rtol=0, atol=1e-9)


def test_the_real_scanners_kernel_through_buckets_and_its_twins_agree():
    from amr_common.world.raster_raycast import (
        SegmentGrid,
        cast_rays_through_buckets,
        cast_rays_through_buckets_python,
    )
    from amr_common.world.raycast import cast_rays_kernel
    from amr_sim.lidar_effects import scan_rays_kernel, scan_rays_numpy
    from amr_sim.simulator import Simulator
    world = speckled_world(120, 0.03, seed=9)
    grid = SegmentGrid.build(world.segments)
    rng = np.random.default_rng(2)
    ox, oy = rng.uniform(0.1, 2.3, (2, 300))
    headings = rng.uniform(-math.pi, math.pi, 300)
    out = [(np.empty(300), np.empty(300)) for _ in range(3)]
    cast_rays_kernel(world.segments, ox, oy, np.cos(headings), np.sin(headings), *out[0])
    for kernel, (ranges, cos) in zip((cast_rays_through_buckets,
                                      cast_rays_through_buckets_python), out[1:]):
        kernel(*grid.arrays, ox, oy, np.cos(headings), np.sin(headings), ranges, cos)
        np.testing.assert_allclose(ranges, out[0][0], rtol=1e-12)
        np.testing.assert_allclose(cos, out[0][1], rtol=0, atol=1e-9)
    sim = Simulator(world, start="centre", profile="turtlebot3", seed=4)
    for k in range(13):
        sim.step(0.2, 2.0 * math.sin(k))
    lidar = sim.lidar
    gauss, uniform = rng.standard_normal(360), rng.random(360, dtype=np.float32)
    args = (lidar.walls, lidar.circles, lidar.history, lidar._head, lidar.angles, lidar._cos,
            lidar._sin, lidar.bands, lidar.params, gauss, uniform)
    fast, slow = np.empty(360), np.empty(360)
    scan_rays_kernel(*args, fast)
    scan_rays_numpy(*args, slow)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
    assert (fast > 0.0).sum() > 100


def test_a_map_of_millions_of_walls_gets_no_wall_markers_its_map_shows_them():
    from amr_common.ros.map_messages import grid_values, world_map_messages
    world = speckled_world(300, 0.3, seed=1)
    assert len(world.segments) > 20_000  # map_messages.MAX_MARKER_WALLS
    grid, markers = world_map_messages(world, 0.02)
    walls = [m for m in markers.markers if m.ns == "walls"]
    assert walls and not walls[0].points
    assert np.array_equal(grid_values(grid), world.raster.values)
    small = speckled_world(60, 0.05)
    assert world_map_messages(small, 0.02)[1].markers[0].points  # a few walls: drawn


def test_a_big_maps_coverage_grid_is_the_same_from_its_walls_in_buckets():
    from amr_common.world.coverage_grid import build_coverage_grid
    from amr_common.world.raster_raycast import SegmentGrid
    world = speckled_world(200, 0.004, seed=6)
    args = (world.segments, world.boundary, world.holes, 0.1, None, 0.105)
    fast = build_coverage_grid(*args, clearances=SegmentGrid.build(world.segments).clearances)
    every = build_coverage_grid(*args)
    assert every.free.any() and np.array_equal(fast.free, every.free)


def test_a_start_inside_a_maps_border_wall_is_said_to_be_inside_a_wall():
    values = np.zeros((20, 20), dtype=np.int8)
    values[0, :] = values[-1, :] = values[:, 0] = values[:, -1] = OCCUPIED
    values[5, 5] = -1
    world = World.from_raster(Raster(values, 0.05, (0.0, 0.0)))
    assert "is inside a wall of the map (an occupied cell" in world.pose_problem(0.025, 0.5)
    assert "is inside a wall of the map (an unknown cell" in world.pose_problem(0.275, 0.275)
    assert world.pose_problem(5.0, 5.0).endswith("is outside the map")
    assert world.pose_problem(math.nan, 0.5).endswith("is outside the map")


def test_a_map_just_over_the_cell_limit_says_its_cells_as_integers(tmp_path):
    from amr_common.world.map_file import write_map
    from amr_common.world.world import WorldError
    yaml_path, _ = write_map(Raster(np.zeros((2001, 2000), dtype=np.int8), 0.05, (0.0, 0.0)),
                             tmp_path / "big")
    with pytest.raises(WorldError) as refused:
        World.load(yaml_path)
    assert "would need 2,000 x 2,001 = 4,002,000 cells" in str(refused.value)
    assert "limit 4,000,000" in str(refused.value)
