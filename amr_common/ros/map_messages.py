"""A world as ROS map messages: /map, /map_markers and /world_markers.

nav_msgs/OccupancyGrid (/map) and visualization_msgs/MarkerArray of its walls (/map_markers);
/world_markers: what the simulated world has beyond the map - walls the map lacks and the movers
where they are now (the simulator's truth, as /ground_truth).
Message building only (no node); the cells are the world's occupancy grid
(amr_common.world.occupancy_grid: the planner's and the particle filter's cells; values in the
OccupancyGrid convention, row 0 southmost). A map with more than MAX_MARKER_WALLS walls (a SLAM
map's specks: up to ~2 million, 12 million points that took ~30 s and GBs to build, more than a
viewer draws) gets no wall markers: its /map shows the same walls.
"""
from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from nav_msgs.msg import OccupancyGrid
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

MAP_TOPIC = "/map"
MAP_MARKERS_TOPIC = "/map_markers"
WORLD_MARKERS_TOPIC = "/world_markers"
WALL_HEIGHT_M = 0.2  # drawn height of the walls: the LDS scans at 0.18 m
MOVER_HEIGHT_M = 0.5  # drawn height of a mover: tall enough to tell from a wall
WALL_COLOR = ColorRGBA(r=0.45, g=0.45, b=0.5, a=1.0)
GOAL_COLOR = ColorRGBA(r=0.1, g=0.7, b=0.2, a=0.8)
UNMAPPED_COLOR = ColorRGBA(r=1.0, g=0.55, b=0.0, a=0.9)  # walls the map lacks
MOVER_COLOR = ColorRGBA(r=0.6, g=0.2, b=0.8, a=0.85)
MAX_MARKER_WALLS = 20_000  # a map world with more walls: /map_markers without them


def occupancy_grid(values: np.ndarray, resolution: float, origin: tuple[float, float],
                   frame_id: str = "map", stamp: Time | None = None) -> OccupancyGrid:
    """OccupancyGrid of an int8 (rows, cols) array.

    Cell (0, 0) has its lower-left corner at `origin` (x, y); rows run along +y, columns along +x.
    """
    grid = np.ascontiguousarray(values, dtype=np.int8)
    if grid.ndim != 2 or grid.size == 0:
        raise ValueError(f"an occupancy grid needs a non-empty 2D array, got shape {grid.shape}")
    message = OccupancyGrid()
    if stamp is not None:
        message.header.stamp = stamp
        message.info.map_load_time = stamp
    message.header.frame_id = frame_id
    message.info.resolution = float(resolution)
    message.info.height, message.info.width = (int(n) for n in grid.shape)
    message.info.origin.position.x = float(origin[0])
    message.info.origin.position.y = float(origin[1])
    message.info.origin.orientation.w = 1.0
    message.data = array.array("b", grid.tobytes())  # skips rclpy's per-element checks
    return message


def grid_values(message: OccupancyGrid) -> np.ndarray:
    """The (rows, cols) int8 array of an OccupancyGrid (the inverse of occupancy_grid)."""
    return np.asarray(message.data, dtype=np.int8).reshape(message.info.height,
                                                           message.info.width)


def _upright_quads(segments: np.ndarray, ns: str, color: ColorRGBA, frame_id: str,
                   stamp: Time | None) -> Marker:
    """A TRIANGLE_LIST of the segments (N, 4) as upright quads WALL_HEIGHT_M high."""
    walls = Marker(ns=ns, id=0, type=Marker.TRIANGLE_LIST, action=Marker.ADD)
    walls.header.frame_id = frame_id
    if stamp is not None:
        walls.header.stamp = stamp
    walls.pose.orientation.w = 1.0
    walls.scale.x = walls.scale.y = walls.scale.z = 1.0
    walls.color = color
    points = []
    for x1, y1, x2, y2 in np.asarray(segments, dtype=float).reshape(-1, 4):
        a0, b0 = Point(x=x1, y=y1, z=0.0), Point(x=x2, y=y2, z=0.0)
        a1, b1 = Point(x=x1, y=y1, z=WALL_HEIGHT_M), Point(x=x2, y=y2, z=WALL_HEIGHT_M)
        points += [a0, b0, b1, a0, b1, a1]
    walls.points = points
    return walls


def wall_markers(segments: np.ndarray, frame_id: str = "map", stamp: Time | None = None,
                 goal: tuple[float, float] | None = None) -> MarkerArray:
    """MarkerArray of the walls (upright quads) and of the goal.

    The walls are a TRIANGLE_LIST (ns "walls"), the goal a sphere (ns "goal") when given.
    `segments`: (N, 4) rows x1, y1, x2, y2 in metres.
    """
    walls = _upright_quads(segments, "walls", WALL_COLOR, frame_id, stamp)
    markers = [walls]
    if goal is not None:
        sphere = Marker(ns="goal", id=0, type=Marker.SPHERE, action=Marker.ADD)
        sphere.header = walls.header
        sphere.pose.position.x, sphere.pose.position.y = float(goal[0]), float(goal[1])
        sphere.pose.orientation.w = 1.0
        sphere.scale.x = sphere.scale.y = sphere.scale.z = 0.15
        sphere.color = GOAL_COLOR
        markers.append(sphere)
    return MarkerArray(markers=markers)


def world_markers(unmapped: np.ndarray, circles: np.ndarray, frame_id: str = "map",
                  stamp: Time | None = None, message: MarkerArray | None = None) -> MarkerArray:
    """/world_markers: the walls the map lacks and the movers where they are.

    `unmapped`: (N, 4) segments (amr_common.world.map_vs_world.unmapped_walls), a TRIANGLE_LIST
    (ns "unmapped", orange) when there are any; `circles`: rows [x, y, radius], one CYLINDER
    each (ns "movers", id = the mover's index). `message`: a MarkerArray this function built
    before, updated in place (the movers' positions and the stamps) instead of rebuilt.
    """
    if message is None:
        markers = []
        if len(unmapped):
            markers.append(_upright_quads(unmapped, "unmapped", UNMAPPED_COLOR, frame_id, stamp))
        for i, (x, y, radius) in enumerate(np.asarray(circles, dtype=float).reshape(-1, 3)):
            mover = Marker(ns="movers", id=i, type=Marker.CYLINDER, action=Marker.ADD)
            mover.header.frame_id = frame_id
            mover.pose.position.z = 0.5 * MOVER_HEIGHT_M
            mover.pose.orientation.w = 1.0
            mover.scale.x = mover.scale.y = 2.0 * float(radius)
            mover.scale.z = MOVER_HEIGHT_M
            mover.color = MOVER_COLOR
            markers.append(mover)
        message = MarkerArray(markers=markers)
    movers = [m for m in message.markers if m.ns == "movers"]
    for mover, (x, y, _) in zip(movers, np.asarray(circles, dtype=float).reshape(-1, 3)):
        mover.pose.position.x, mover.pose.position.y = float(x), float(y)
    if stamp is not None:
        for marker in message.markers:
            marker.header.stamp = stamp
    return message


def world_map_messages(world, resolution: float, frame_id: str = "map",
                       stamp: Time | None = None) -> tuple[OccupancyGrid, MarkerArray]:
    """/map and /map_markers of an amr_common.world.world.World.

    /map: OccupancyGrid.from_world(world, resolution), the cells the planner and the filter use
    at that resolution. A map world's /map is its map's cells and values exactly (`resolution`
    does not apply); with more than MAX_MARKER_WALLS walls, /map_markers holds no walls.
    """
    from amr_common.world.occupancy_grid import OccupancyGrid
    raster = world.raster if world.raster is not None else \
        OccupancyGrid.from_world(world, resolution).raster()
    walls = world.segments
    if world.raster is not None and len(walls) > MAX_MARKER_WALLS:
        walls = walls[:0]  # its /map draws them (module docstring)
    return (occupancy_grid(raster.values, raster.resolution, raster.origin, frame_id, stamp),
            wall_markers(walls, frame_id, stamp, world.goal))


__all__ = ["MAP_TOPIC", "MAP_MARKERS_TOPIC", "MAX_MARKER_WALLS", "WORLD_MARKERS_TOPIC",
           "occupancy_grid", "grid_values", "wall_markers", "world_map_messages", "world_markers"]
