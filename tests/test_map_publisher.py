"""The world as /map and /map_markers: the raster, the simulator's map and amr_map_publisher.

The map must match the world: free cells free, wall cells occupied, obstacles solid, outside
unknown; late subscribers still get it (latched).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from nav_msgs.msg import OccupancyGrid
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from visualization_msgs.msg import Marker

from amr_common.ros.map_messages import grid_values, world_map_messages
from amr_common.ros.qos import LATCHED
from amr_common.world import occupancy_grid
from amr_common.world.map_file import world_as_map, write_map
from amr_common.world.map_raster import OCCUPIED, Raster
from amr_common.world.world import World
from amr_localization.expected_ranges import expected_range_table
from amr_planning.planner import Planner
from amr_tools.map_publisher import MapPublisherNode
from tests.tf_map_helpers import FrameProbe, check_raster_matches_world, start_with_frames


def test_map_matches_the_world_and_markers_draw_its_walls(ros):
    node, probe, frames = start_with_frames(ros, world="lab02", map_resolution=0.04)
    ros.spin_until(lambda: frames.maps and frames.markers, message="/map and /map_markers")
    grid = frames.maps[0]
    assert grid.header.frame_id == "map" and grid.info.resolution == pytest.approx(0.04)
    world = World.load("lab02")
    raster = Raster(grid_values(grid), grid.info.resolution,
                    (grid.info.origin.position.x, grid.info.origin.position.y))
    check_raster_matches_world(raster, world)
    (walls,) = [m for m in frames.markers[0].markers if m.ns == "walls"]
    assert walls.type == Marker.TRIANGLE_LIST and len(walls.points) == 6 * len(world.segments)
    # A late subscriber still gets the latched map.
    late = ros.node("late_map_reader")
    got = []
    late.create_subscription(OccupancyGrid, "/map", got.append, LATCHED)
    ros.spin_until(lambda: got, message="the latched /map for a late subscriber")
    assert grid_values(got[0]).tolist() == grid_values(grid).tolist()


@pytest.mark.parametrize("world", ["lab02", "room_obstacles"])
def test_map_is_the_grid_the_planner_and_the_filter_use(world):
    # One raster of a world: /map once had cell edges (not centres) on multiples of the
    # resolution and 0.1 m of padding, so it showed other cells than the planner searched.
    loaded = World.load(world)
    planner = Planner(loaded, resolution_m=0.02)
    table = expected_range_table(loaded, 0.02, 8)
    message, _ = world_map_messages(loaded, 0.02)
    origin = (message.info.origin.position.x, message.info.origin.position.y)
    assert origin == planner.grid.origin == table.grid.origin
    assert grid_values(message).tolist() == planner.grid.occupancy_values().tolist()


@pytest.mark.parametrize("world", ["room_obstacles", "maze_deadends"])
def test_raster_of_bundled_worlds(world):
    loaded = World.load(world)
    raster = occupancy_grid.OccupancyGrid.from_world(loaded, 0.05).raster()
    check_raster_matches_world(raster, loaded)
    # Obstacles (holes) are solid: their inside is occupied too.
    if loaded.holes:
        hole = loaded.holes[0]
        row, col = raster.cell_of(*hole.mean(axis=0))
        assert raster.values[row, col] == OCCUPIED


def test_raster_rejects_a_bad_resolution():
    for bad in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError):
            occupancy_grid.OccupancyGrid.from_world(World.load("lab02"), bad)


def test_map_publisher_serves_a_course_map_json(ros, tmp_path):
    path = tmp_path / "course_map.json"
    path.write_text(json.dumps({"metric": {
        "boundary": [[0, 0], [2, 0], [2, 1], [0, 1]],
        "holes": [[[0.8, 0.4], [1.2, 0.4], [1.2, 0.6], [0.8, 0.6]]]}}))
    node = ros.add(MapPublisherNode(context=ros.context, parameter_overrides=[
        Parameter("world", value=str(path)), Parameter("resolution", value=0.1)]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    frames = FrameProbe(ros)
    ros.spin_until(lambda: frames.maps and frames.markers, message="the latched map")
    grid = frames.maps[0]
    assert grid.info.resolution == pytest.approx(0.1)
    raster = Raster(grid_values(grid), 0.1,
                    (grid.info.origin.position.x, grid.info.origin.position.y))
    check_raster_matches_world(raster, World.load(path))


def test_a_nav2_map_is_published_cell_for_cell_by_both_nodes(ros, tmp_path):
    """As map_server does: the file's cells, resolution and origin, whatever `resolution` says."""
    raster, extras = world_as_map(World.load("lab02"), 0.02)
    values = raster.values.copy()
    values.flat[np.flatnonzero(values == 0)[:40]] = -1  # some unknown inside too
    yaml_path, _ = write_map(Raster(values, 0.02, raster.origin), tmp_path / "lab02",
                             extras=extras)
    publisher = ros.add(MapPublisherNode(context=ros.context, parameter_overrides=[
        Parameter("world", value=str(yaml_path)), Parameter("resolution", value=0.1)]))
    assert publisher.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert publisher.trigger_activate() == TransitionCallbackReturn.SUCCESS
    frames = FrameProbe(ros)
    ros.spin_until(lambda: frames.maps, message="the latched map")
    published = [frames.maps[0]]
    publisher.trigger_deactivate()
    publisher.trigger_cleanup()
    frames.maps.clear()
    start_with_frames(ros, world=str(yaml_path), start="outer", map_resolution=0.05)
    ros.spin_until(lambda: frames.maps, message="the simulator's map")
    published.append(frames.maps[0])
    for grid in published:
        assert grid.info.resolution == pytest.approx(0.02)
        assert (grid.info.origin.position.x, grid.info.origin.position.y) == raster.origin
        assert grid_values(grid).tolist() == values.tolist()


@pytest.mark.parametrize("parameters, reason", [
    ({"world": "/no/such/map.json"}, "missing file"),
    ({"resolution": 0.0}, "zero resolution"),
    ({"resolution": "fine"}, "not a number"),
])


def test_map_publisher_refuses_bad_input(ros, parameters, reason):
    overrides = [Parameter(name, value=value) for name, value in parameters.items()]
    try:
        node = MapPublisherNode(context=ros.context, parameter_overrides=overrides)
    except Exception:  # a string for a double parameter is refused at declaration
        assert reason == "not a number"
        return
    ros.add(node)
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE, reason
